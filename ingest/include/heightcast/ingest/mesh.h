// heightcast/ingest/mesh.h: flood model results as the models write them, read into one plain form (docs/models.md).
//
// Every reader (UGRID-1.0 map files of D-Flow FM and SFINCS, SFINCS regular maps, HEC-RAS 2D plan results, ANUGA
// .sww, TELEMAC Selafin, 3Di, TUFLOW FV) fills a ModelMesh: the 2-D faces as polygons of nodes, the bed level and the
// water level per step where the model defines them (per face, or per node and linear over triangles), the times, the
// CRS, and what the reader assumed. What happens next does not depend on the format (model_ingest.cpp): a quadtree of
// square faces is taken as it is (one cell per face, its lattice fitted to the nodes), any other mesh is sampled onto
// the adaptive grid, terrain from the mesh's bed or from a DEM given with it.
//
// NetCDF and HDF5 are read through GDAL's multidimensional API; Selafin by a small binary reader of our own.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace hc::ingest {

// Where a field's values live: one per face (constant over it, as finite-volume models define them), or one per node
// (linear over triangles, as finite-element models define them; a face of more nodes is split into a fan of triangles
// from its first node).
enum class MeshAt { Face, Node };

// Values of one field at one time: NaN where the model has none (fill values, -9999 on inactive faces: the reader turns
// them into NaN and counts them in a warning).
struct MeshField {
    MeshAt at = MeshAt::Face;
    std::vector<double> values;  // faceCount() or nodeX.size() values [m]
};

// A further field per step (velocity magnitude, ...), stored as a step layer of that name on the wet cells.
struct MeshLayer {
    std::string name, units;
    std::function<MeshField(size_t step)> read;
};

struct ModelMesh {
    std::string source;  // the file, for messages
    std::string format;  // "D-Flow FM map (UGRID-1.0)", "HEC-RAS 2D plan results (HDF5, version 6)", ...
    // Nodes in the mesh's CRS (projected: its linear unit; geographic: degrees east/north), and the 2-D faces as
    // polygons of 3 or more nodes in order around them (compressed rows: face f's nodes are
    // faceNodes[faceStart[f] .. faceStart[f + 1]), 0-based). faceStart has faceCount() + 1 entries.
    std::vector<double> nodeX, nodeY;
    std::vector<uint64_t> faceStart{0};
    std::vector<uint32_t> faceNodes;
    // Per face, the name messages use for it ("face 12", "cell 40 of 2-D area 'Perimeter 1'"); empty: "face F".
    std::function<std::string(size_t face)> faceName;
    // The bed (terrain) [m]; values empty where the file has none (a DEM must then be given).
    MeshField bed;
    // The water surface elevation [m] per step, read one step at a time (meshes of 10 M faces and 100 steps need not
    // fit in memory together); times [s], strictly increasing (a reader checks and says which step goes back). No
    // steps: a terrain mesh only.
    std::vector<double> timesS;
    std::function<MeshField(size_t step)> level;
    std::vector<MeshLayer> layers;
    // The CRS as WKT or any text GDAL's SetFromUserInput reads ("EPSG:28992"); "" where the file names none.
    std::string crs;
    // The coordinates as the file stores them were float32 (their rounding, a few ulps at their magnitude, is then
    // allowed for when a quadtree's lattice is fitted to them).
    bool coordsFloat32 = false;
    // The model computes on the squares of a quadtree (SFINCS, 3Di, TUFLOW quadtree): its faces are taken as they are,
    // one cell each, and a mesh whose nodes do not fit one lattice is refused rather than sampled.
    bool quadtreeModel = false;
    std::vector<std::string> warnings;  // what the reader assumed or turned into NaN, each with its override
    std::vector<std::string> notes;     // what it skipped: "a 1-D network of 40 nodes (not drawn)", 3-D layers, ...
    std::string kind;  // "triangles", "quadrilaterals", "mixed faces of 3-6 nodes", "quadtree" (filled by
                       // describe() when left empty)

    size_t faceCount() const { return faceStart.size() - 1; }
    size_t nodesOf(size_t f) const { return size_t(faceStart[f + 1] - faceStart[f]); }
    std::string nameOf(size_t f) const { return faceName ? faceName(f) : "face " + std::to_string(f); }
};

struct MeshReadOptions {
    std::string terrainVar;              // UGRID: the bed variable; "" = the format's own (zb, mesh2d_flowelem_bl, ...)
    std::string waterSurfaceVar;         // UGRID: the water level variable; "" = the format's own (zs, mesh2d_s1, ...)
    std::vector<std::string> layerVars;  // further variables over time, each a step layer
};

// The model format of `path` ("" when it is none of those read here: a raster, most likely). Opens the file, reads no
// values, never throws.
std::string modelFormatOf(const std::string& path);

// For a file of a model whose results are not read here (MIKE .dfsu, XMDF, a bare .2dm), what it is and what to
// convert it to; "" otherwise. By the name alone.
std::string unreadModelFormat(const std::string& path);

// Reads the model results of `path` (the format modelFormatOf names). Throws hc::Error naming the file and the face,
// step or variable that is wrong; an unknown model format is refused naming the format and what to convert it to.
ModelMesh readModelMesh(const std::string& path, const MeshReadOptions& options);

// An SMS/TUFLOW .2dm mesh alone (xmdf.cpp): its nodes, 2-D faces and bed (the nodes' z); throws hc::Error.
ModelMesh readTwoDmMesh(const std::string& path);

// Checks a mesh as read (node indexes in range, faces of >= 3 nodes, step field sizes, times increasing): throws
// hc::Error naming the face or step. Every reader calls it last.
void checkModelMesh(const ModelMesh& mesh);

}  // namespace hc::ingest
