// CF UGRID-1.0 map files (D-Flow FM, SFINCS quadtree, any 2-D mesh of faces of 3 or more nodes) -> ModelMesh.
#include <algorithm>
#include <cmath>
#include <sstream>

#include "../gdal_util.h"
#include "heightcast/core/error.h"
#include "md_util.h"
#include "readers.h"

namespace hc::ingest::detail {
namespace {

// The mesh topology variables of dimension `dim` (2: faces, 1: networks).
std::vector<ArrayPtr> topologies(const std::shared_ptr<GDALGroup>& root, int dim) {
    std::vector<ArrayPtr> out;
    const char* const show[] = {"SHOW_ZERO_DIM=YES", "SHOW_ALL=YES", nullptr};
    for (const std::string& name : root->GetMDArrayNames(show)) {
        ArrayPtr a = root->OpenMDArray(name);
        if (!a || textAttr(a, "cf_role") != "mesh_topology") continue;
        auto d = a->GetAttribute("topology_dimension");
        if (d && d->ReadAsInt() == dim) out.push_back(a);
    }
    return out;
}

std::pair<std::string, std::string> twoNames(const std::string& text) {
    std::istringstream in(text);
    std::string a, b;
    in >> a >> b;
    return {a, b};
}

// The first of `names` the file has (the option's name alone when given).
ArrayPtr firstOf(const MdFile& f, const std::string& given, std::initializer_list<std::string> names,
                 const std::string& role) {
    if (!given.empty()) return f.open(given, role);
    for (const std::string& n : names)
        if (ArrayPtr a = f.find(n)) return a;
    return nullptr;
}

struct Topology {
    ArrayPtr topo;
    std::string mesh;  // its name: D-Flow FM's variables are "<mesh>_s1", ...
    size_t faces = 0, nodes = 0;
    std::string faceDim, nodeDim;  // the dimensions of the connectivity's faces and of the node coordinates
};

// Where a variable lives on the mesh: by its `location` attribute, else by its last dimension (its name, else its
// size).
std::optional<MeshAt> locationOf(const ArrayPtr& a, const Topology& t) {
    const std::string loc = textAttr(a, "location");
    if (loc == "face") return MeshAt::Face;
    if (loc == "node") return MeshAt::Node;
    const auto dims = a->GetDimensions();
    if (dims.empty()) return std::nullopt;
    const std::string last = dims.back()->GetName();
    if (last == t.faceDim) return MeshAt::Face;
    if (last == t.nodeDim) return MeshAt::Node;
    if (dims.back()->GetSize() == t.faces) return MeshAt::Face;
    if (dims.back()->GetSize() == t.nodes) return MeshAt::Node;
    return std::nullopt;
}

void readNodesAndFaces(const MdFile& f, Topology& t, ModelMesh& m) {
    const auto [xName, yName] = twoNames(textAttr(t.topo, "node_coordinates"));
    if (yName.empty()) f.fail(t.mesh + ":node_coordinates does not name two variables (x y)");
    const ArrayPtr xv = readNodes(f, xName, yName, m);
    if (xv->GetDimensionCount() == 1) t.nodeDim = xv->GetDimensions()[0]->GetName();
    const std::string connName = textAttr(t.topo, "face_node_connectivity");
    if (connName.empty()) f.fail(t.mesh + " has no face_node_connectivity: not a mesh of faces");
    ArrayPtr conn = f.open(connName, "face_node_connectivity");
    const auto dims = conn->GetDimensions();
    if (dims.size() != 2) f.fail(connName + " is not two-dimensional (faces x nodes)");
    // (faces, nodes) as UGRID writes it, or (nodes, faces) where face_dimension says the faces come second.
    const std::string faceDim = textAttr(t.topo, "face_dimension");
    const bool transposed = !faceDim.empty() && dims[1]->GetName() == faceDim;
    const size_t faces = size_t(dims[transposed ? 1 : 0]->GetSize()), per = size_t(dims[transposed ? 0 : 1]->GetSize());
    t.faceDim = dims[transposed ? 1 : 0]->GetName();
    const std::vector<double> c = f.read(conn);
    const double start = numAttr(conn, "start_index").value_or(0);
    const std::optional<double> fill = fillOf(conn);
    m.faceNodes.reserve(faces * per);
    m.faceStart.assign(1, 0);
    for (size_t face = 0; face < faces; ++face) {
        for (size_t k = 0; k < per; ++k) {
            const double v = c[transposed ? k * faces + face : face * per + k];
            if (std::isnan(v) || (fill && v == *fill) || v < start) continue;  // padding of a face with fewer nodes
            const double node = v - start;
            if (node >= double(m.nodeX.size()) || node != std::floor(node))
                f.fail("face " + std::to_string(face) + " names node " + fmt(v, 9) + ", not one of the " +
                       std::to_string(m.nodeX.size()) + " nodes (start_index " + fmt(start) + ")");
            m.faceNodes.push_back(uint32_t(node));
        }
        m.faceStart.push_back(m.faceNodes.size());
    }
}

// A field on the mesh: one value per face or node; `steps` > 0: (time, where) read a step at a time.
MeshField readField(const MdFile& f, const ArrayPtr& a, const Topology& t, MeshAt at, std::optional<size_t> step,
                    size_t& fills) {
    MeshField out;
    out.at = at;
    out.values = step ? f.readSlice(a, *step) : f.read(a);
    const size_t need = at == MeshAt::Face ? t.faces : t.nodes;
    if (out.values.size() != need)
        f.fail(a->GetName() + (step ? " at step " + std::to_string(*step) : std::string()) + " has " +
               std::to_string(out.values.size()) + " values for " + std::to_string(need) +
               (at == MeshAt::Face ? " faces" : " nodes"));
    fills += fillToNaN(out.values, fillOf(a));
    return out;
}

std::string crsText(const MdFile& f, const ArrayPtr& var, ModelMesh& m) {
    // GDAL guesses a geographic CRS for variables without a grid_mapping: only a named mapping counts.
    std::string mapping = textAttr(var, "grid_mapping");
    if (auto srs = var->GetSpatialRef(); !mapping.empty() && srs && !srs->IsEmpty()) return toWkt(*srs);
    ArrayPtr g = mapping.empty() ? nullptr : f.find(mapping);
    for (const char* name : {"projected_coordinate_system", "wgs84", "crs"})
        if (!g) g = f.find(name), mapping = name;
    if (!g) return "";
    for (const char* key : {"crs_wkt", "spatial_ref", "epsg_code", "EPSG_code", "epsg"}) {
        std::string v = textAttr(g, key);
        if (v.empty()) continue;
        if (std::string(key) == "epsg" && v.find(':') == std::string::npos) v = "EPSG:" + v;
        if (v == "EPSG:0" || v == "0") {
            m.warnings.push_back(f.path + ": " + mapping + ":" + key + " is 0 (no CRS)");
            return "";
        }
        return v;
    }
    return "";
}

}  // namespace

// Which model wrote the file: SFINCS says so in its global attributes, heightcast in its mesh's long_name, D-Flow FM by
// its variables' names.
std::string ugridFormat(const std::shared_ptr<GDALGroup>& root) {
    const std::vector<ArrayPtr> topos = topologies(root, 2);
    if (topos.empty()) return "";
    bool sfincs = false;
    for (const auto& a : root->GetAttributes()) {
        const char* v = a->GetDataType().GetClass() == GEDTC_STRING ? a->ReadAsString() : nullptr;
        sfincs = sfincs || (v && std::string(v).find("SFINCS") != std::string::npos);
    }
    if (sfincs) return "SFINCS quadtree map (UGRID-1.0)";
    if (textAttr(topos[0], "long_name").find("heightcast") != std::string::npos)
        return "heightcast quadtree mesh (UGRID-1.0)";
    const std::vector<std::string> names = root->GetMDArrayNames();
    const bool dflow = std::find(names.begin(), names.end(), "mesh2d_s1") != names.end() ||
                       std::find(names.begin(), names.end(), "mesh2d_flowelem_bl") != names.end();
    return dflow ? "D-Flow FM map (UGRID-1.0)" : "UGRID-1.0 mesh";
}

ModelMesh readUgrid(const std::string& path, std::shared_ptr<GDALDataset> keep, const MeshReadOptions& opt) {
    MdFile f{path, keep, keep->GetRootGroup()};
    const std::vector<ArrayPtr> topos = topologies(f.root, 2);
    if (topos.empty()) f.fail("no UGRID 2-D mesh (no variable with cf_role mesh_topology and topology_dimension 2)");
    ModelMesh m;
    m.source = path;
    m.format = ugridFormat(f.root);
    Topology t{topos[0], topos[0]->GetName(), 0, 0, "", ""};
    if (topos.size() > 1)
        m.notes.push_back(std::to_string(topos.size() - 1) + " further 2-D mesh(es) beside '" + t.mesh + "' not read");
    for (const ArrayPtr& net : topologies(f.root, 1))
        m.notes.push_back("the 1-D network '" + net->GetName() + "' (" + textAttr(net, "long_name") +
                          ") is not drawn: 2-D faces only");
    readNodesAndFaces(f, t, m);
    t.faces = m.faceCount(), t.nodes = m.nodeX.size();
    const std::string& mesh = t.mesh;
    m.quadtreeModel = m.format.rfind("SFINCS", 0) == 0 || m.format.rfind("heightcast", 0) == 0;
    // The bed: the option's, else the models' own names (face values first: the model's cells).
    size_t bedFills = 0;
    ArrayPtr bed =
        firstOf(f, opt.terrainVar, {"zb", mesh + "_flowelem_bl", mesh + "_face_z", mesh + "_node_z", "mesh2d_node_z"},
                "--terrain-var");
    if (bed) {
        auto at = locationOf(bed, t);
        if (!at) f.fail(bed->GetName() + " is neither a face nor a node variable of " + mesh);
        m.bed = readField(f, bed, t, *at, std::nullopt, bedFills);
        if (bedFills)
            m.warnings.push_back(path + ": " + std::to_string(bedFills) + " values of " + bed->GetName() +
                                 " are fill values: holes");
    } else {
        m.warnings.push_back(path + ": no bed level (zb, " + mesh + "_flowelem_bl, " + mesh +
                             "_node_z; --terrain-var names one): a DEM must give the terrain");
    }
    m.crs = crsText(f, bed ? bed : t.topo, m);
    // The water level over time.
    ArrayPtr level = opt.waterSurfaceVar == "-"
                         ? nullptr
                         : firstOf(f, opt.waterSurfaceVar, {"zs", mesh + "_s1"}, "--water-surface-var");
    if (!level && !opt.layerVars.empty())
        f.fail("--face-layers needs the water level: step layers are stored on wet faces");
    if (!level) return checkModelMesh(m), m;
    const auto at = locationOf(level, t);
    const auto shape = shapeOf(level);
    if (!at || shape.size() != 2)
        f.fail(level->GetName() + " is not a (time, face) or (time, node) variable of " + mesh);
    ArrayPtr time = level->GetDimensions()[0]->GetIndexingVariable();
    if (!time) time = f.find(level->GetDimensions()[0]->GetName());
    if (time) {
        m.timesS = cfTimesS(f, time);
    } else {
        for (size_t k = 0; k < shape[0]; ++k) m.timesS.push_back(double(k));
        m.warnings.push_back(path + ": " + level->GetName() +
                             "'s first dimension has no time variable: the step index is taken as time [s]");
    }
    if (m.timesS.size() != shape[0]) f.fail("the time variable and " + level->GetName() + " differ in steps");
    m.level = [f, level, t, at](size_t k) {
        size_t fills = 0;
        return readField(f, level, t, *at, k, fills);
    };
    for (const std::string& name : opt.layerVars) {
        if (name == level->GetName() || (bed && name == bed->GetName()))
            f.fail("--face-layers " + name + ": that is the " +
                   (bed && name == bed->GetName() ? "bed" : "water level") + "; name further variables");
        ArrayPtr a = f.open(name, "--face-layers");
        const auto la = locationOf(a, t);
        if (!la || shapeOf(a) != shape)
            f.fail(name + " is not shaped as the water level " + level->GetName() + ": a step layer must be");
        m.layers.push_back({name, a->GetUnit().empty() ? textAttr(a, "units") : a->GetUnit(), [f, a, t, la](size_t k) {
                                size_t fills = 0;
                                return readField(f, a, t, *la, k, fills);
                            }});
    }
    checkModelMesh(m);
    return m;
}

}  // namespace hc::ingest::detail
