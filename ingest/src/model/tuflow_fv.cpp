// TUFLOW FV results (NetCDF: cells of 3 or 4 nodes, water level per cell over time) -> ModelMesh.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <ogr_spatialref.h>

#include "../gdal_util.h"
#include "heightcast/core/error.h"
#include "md_util.h"
#include "readers.h"

namespace hc::ingest::detail {
namespace {

// The cells (cell_node: 1-based node numbers, cell_Nvert of them each) and the nodes (node_X, node_Y).
void readCells(const MdFile& f, ModelMesh& m) {
    readNodes(f, "node_X", "node_Y", m);
    ArrayPtr nv = f.open("cell_Nvert", "the cells' node counts"), cn = f.open("cell_node", "the cells' nodes");
    const std::vector<size_t> shape = shapeOf(cn);
    const std::vector<double> counts = f.read(nv), nodes = f.read(cn);
    if (shape.size() != 2 || counts.size() != shape[0])
        f.fail("cell_node is not (cells, nodes) for the " + std::to_string(counts.size()) + " cells of cell_Nvert");
    size_t per[2] = {0, 0};  // triangles, quadrilaterals
    m.faceStart.assign(1, 0);
    for (size_t c = 0; c < counts.size(); ++c) {
        if (!(counts[c] >= 3 && counts[c] <= double(shape[1])) || counts[c] != std::floor(counts[c]))
            f.fail("cell " + std::to_string(c + 1) + " has " + fmt(counts[c]) +
                   " nodes (cell_Nvert): a cell has 3 to " + std::to_string(shape[1]));
        for (size_t k = 0; k < size_t(counts[c]); ++k) {
            const double n = nodes[c * shape[1] + k];
            if (!(n >= 1 && n <= double(m.nodeX.size())) || n != std::floor(n))
                f.fail("cell " + std::to_string(c + 1) + " (cell_node) names node " + fmt(n, 9) + ", not one of the " +
                       std::to_string(m.nodeX.size()) + " nodes (numbered from 1)");
            m.faceNodes.push_back(uint32_t(n - 1));
        }
        m.faceStart.push_back(m.faceNodes.size());
        ++per[counts[c] == 3 ? 0 : 1];
    }
    m.kind = "mixed faces of 3-" + std::to_string(shape[1]) + " nodes";
    if (!per[0] || !per[1]) m.kind = per[0] ? "triangles" : "quadrilaterals";
    m.faceName = [](size_t face) { return "cell " + std::to_string(face + 1); };
}

struct Sizes {
    size_t cells = 0, nodes = 0;
};

// Where `a` lives by its last dimension: per cell or per node, as a (where) or (time, where) variable.
MeshAt placeOf(const MdFile& f, Sizes n, const ArrayPtr& a) {
    const std::vector<size_t> shape = shapeOf(a);
    const size_t where = shape.empty() ? 0 : shape.back();
    if (shape.empty() || shape.size() > 2 || (where != n.cells && where != n.nodes))
        f.fail(a->GetName() + " is not a cell (" + std::to_string(n.cells) + ") or node (" + std::to_string(n.nodes) +
               ") variable, nor one of those over time");
    return where == n.cells ? MeshAt::Face : MeshAt::Node;
}

// The values of `a` at step `k` of a (time, where) variable, or all of a (where) one; fill values become NaN.
MeshField fieldOf(const MdFile& f, Sizes n, const ArrayPtr& a, size_t k) {
    MeshField out{placeOf(f, n, a), shapeOf(a).size() == 2 ? f.readSlice(a, k) : f.read(a)};
    fillToNaN(out.values, fillOf(a));
    return out;
}

// The bed: cell_Zb (the initial bed; a morphological run also writes ZB over time), or --terrain-var.
void readBed(const MdFile& f, const MeshReadOptions& opt, ModelMesh& m) {
    ArrayPtr bed = opt.terrainVar.empty() ? f.find("cell_Zb") : f.open(opt.terrainVar, "the bed level, --terrain-var");
    if (!bed) {
        m.warnings.push_back(f.path + ": no bed level (cell_Zb; --terrain-var names one): a DEM must give the terrain");
        return;
    }
    m.bed = fieldOf(f, {m.faceCount(), m.nodeX.size()}, bed, 0);
    const size_t holes =
        size_t(std::count_if(m.bed.values.begin(), m.bed.values.end(), [](double v) { return std::isnan(v); }));
    if (holes)
        m.warnings.push_back(f.path + ": " + std::to_string(holes) + " values of " + bed->GetName() +
                             " are fill values: holes");
    if (shapeOf(bed).size() == 2)
        m.warnings.push_back(f.path + ": the bed " + bed->GetName() +
                             " varies over time: its first step taken (--terrain-var names another)");
    else if (f.find("ZB") && bed->GetName() == "cell_Zb")
        m.notes.push_back("the bed over time (ZB, of morphological runs) not read: the initial bed cell_Zb drawn");
}

// Output times: ResTime in hours (TUFLOW FV's own units, "hours"; CF "... since ..." units too) -> seconds.
std::vector<double> resTimesS(const MdFile& f, ModelMesh& m) {
    ArrayPtr time = f.open("ResTime", "the output times");
    const std::string units = lower(textAttr(time, "units"));
    double unit = cfSecondsPerUnit(units);
    if (unit == 0 && (units.empty() || units.rfind("hour", 0) == 0)) unit = 3600;
    if (unit == 0 && units.rfind("sec", 0) == 0) unit = 1;
    if (unit == 0) f.fail("ResTime has units '" + units + "', not hours or seconds");
    if (units.empty()) m.warnings.push_back(f.path + ": ResTime has no units: hours taken (TUFLOW FV's own)");
    std::vector<double> t = f.read(time);
    for (double& v : t) v *= unit;
    checkIncreasing(f, t, "ResTime");
    return t;
}

// A 3-D (layered) file's note: the variables per layer cell, which are not read.
void noteLayers(const MdFile& f, ModelMesh& m, size_t cells2d, size_t cells3d) {
    if (cells3d <= cells2d) return;
    std::string names;
    size_t n = 0;
    for (const std::string& name : f.names()) {
        ArrayPtr a = f.find(name);
        if (!a || name == "idx2" || a->GetDimensions().empty() || a->GetDimensions().back()->GetName() != "NumCells3D")
            continue;
        if (n++ < 6) names += (names.empty() ? "" : ", ") + name;
    }
    m.notes.push_back("3-D results (" + std::to_string(cells3d) + " layer cells over " + std::to_string(cells2d) +
                      " columns): " + std::to_string(n) + " layered variables (" + names + (n > 6 ? ", ..." : "") +
                      ") not read; the water level H is per 2-D cell");
}

// A step layer: a (time, cells or nodes) variable, or a (time, 3-D cells) one of a file of one layer (through idx3).
MeshLayer layerOf(const MdFile& f, const ModelMesh& m, const std::string& name, size_t steps, size_t cells3d) {
    ArrayPtr a = f.open(name, "--face-layers");
    const std::vector<size_t> shape = shapeOf(a);
    const std::string units = a->GetUnit().empty() ? textAttr(a, "units") : a->GetUnit();
    if (shape.size() != 2 || shape[0] != steps)
        f.fail(name + " is not a (time, cells) variable of " + std::to_string(steps) + " steps");
    const bool per3d = a->GetDimensions()[1]->GetName() == "NumCells3D" && shape[1] == cells3d;
    const Sizes n{m.faceCount(), m.nodeX.size()};
    if (!per3d) {
        placeOf(f, n, a);  // per cell or node, checked before any step is asked for
        return {name, units, [f, n, a](size_t k) { return fieldOf(f, n, a, k); }};
    }
    if (cells3d != m.faceCount())
        f.fail(name + " is per 3-D layer cell (NumCells3D): layered variables are not read; name a 2-D one");
    std::vector<double> top = f.read(f.open("idx3", "the 2-D to 3-D cell index"));
    if (top.size() != m.faceCount())
        f.fail("idx3 has " + std::to_string(top.size()) + " values for " + std::to_string(m.faceCount()) + " cells");
    for (double& i : top)
        if (!(i >= 1 && i <= double(cells3d)))
            f.fail("idx3 names 3-D cell " + fmt(i) + ", not one of the " + std::to_string(cells3d));
    return {name, units, [f, a, top](size_t k) {
                std::vector<double> all = f.readSlice(a, k);
                fillToNaN(all, fillOf(a));
                MeshField out{MeshAt::Face, {}};
                for (double i : top) out.values.push_back(all[size_t(i) - 1]);
                return out;
            }};
}

// The CRS: degrees (spherical, or the node units) are WGS 84; else a grid mapping the file names (crs_wkt,
// spatial_ref, an EPSG code); else a .prj of the same name beside the file.
std::string fvCrs(const MdFile& f, ModelMesh& m) {
    const std::string units = lower(textAttr(f.find("node_X"), "units"));
    const bool spherical = lower(rootText(f, "spherical")) == "true";
    if (spherical || units.find("degree") != std::string::npos) {
        m.warnings.push_back(f.path + ": coordinates in degrees (" +
                             (spherical ? "spherical: true" : "node_X units " + units) +
                             "): EPSG:4326 taken (--s_srs names another CRS)");
        return "EPSG:4326";
    }
    const std::string mapping = textAttr(f.find("H"), "grid_mapping");
    if (ArrayPtr g = f.find(mapping.empty() ? "crs" : mapping))
        for (const char* key : {"crs_wkt", "spatial_ref", "EPSG_code", "epsg_code", "epsg"})
            if (std::string v = textAttr(g, key); !v.empty() && v != "0" && v != "EPSG:0")
                return v.find_first_not_of("0123456789") == std::string::npos ? "EPSG:" + v : v;
    const std::string local = ": coordinates taken as metres in a local frame (name the CRS with --s_srs)";
    const std::filesystem::path prj = std::filesystem::path(f.path).replace_extension(".prj");
    std::ifstream in(prj);
    if (!in) {
        m.warnings.push_back(f.path + ": no CRS (none in the file, no " + prj.filename().string() + " beside it)" +
                             local);
        return "";
    }
    std::ostringstream text;
    text << in.rdbuf();
    OGRSpatialReference srs;
    CPLErrorStateBackuper quiet;
    if (srs.SetFromUserInput(text.str().c_str()) == OGRERR_NONE) return toWkt(srs);
    m.warnings.push_back(f.path + ": " + prj.string() + " holds no CRS GDAL reads" + local);
    return "";
}

// The warning for the cells the model marks dry (stat 0), whose residual film of water is not drawn.
void noteDry(const MdFile& f, ModelMesh& m) {
    const std::optional<double> dry = rootNum(f, "Dry depth");
    m.warnings.push_back(f.path + ": cells the model marks dry (stat 0" +
                         (dry ? ": depth under its dry depth " + fmt(*dry, 4) + " m" : "") +
                         ") have no water level (NaN) (--water-surface-var H reads H as written)");
}

size_t dimensionSize(const MdFile& f, const std::string& name) {
    for (const auto& d : f.root->GetDimensions())
        if (d->GetName() == name) return size_t(d->GetSize());
    return 0;
}

// The output times, the water level per cell over them (NaN where the model marks a cell dry), and the step layers.
void readSteps(const MdFile& f, const MeshReadOptions& opt, size_t cells3d, ModelMesh& m) {
    if (opt.waterSurfaceVar == "-") return;
    ArrayPtr level =
        f.open(opt.waterSurfaceVar.empty() ? "H" : opt.waterSurfaceVar, "the water level, --water-surface-var");
    m.timesS = resTimesS(f, m);
    const std::vector<size_t> shape = shapeOf(level);
    if (shape.size() != 2 || shape[0] != m.timesS.size())
        f.fail(level->GetName() + " is not a (time, cells) variable of the " + std::to_string(m.timesS.size()) +
               " steps of ResTime");
    const Sizes n{m.faceCount(), m.nodeX.size()};
    const bool perCell = placeOf(f, n, level) == MeshAt::Face;  // checked before any step is asked for
    // The model's own wet/dry flag (stat: 0 dry) for its own water level H.
    ArrayPtr stat = opt.waterSurfaceVar.empty() && perCell ? f.find("stat") : nullptr;
    if (stat && shapeOf(stat) != shape) stat = nullptr;
    if (stat) noteDry(f, m);
    m.level = [f, n, level, stat](size_t k) {
        MeshField out = fieldOf(f, n, level, k);
        if (!stat) return out;
        const std::vector<double> wet = f.readSlice(stat, k);
        for (size_t i = 0; i < wet.size(); ++i)
            if (wet[i] == 0) out.values[i] = NAN;
        return out;
    };
    for (const std::string& name : opt.layerVars) m.layers.push_back(layerOf(f, m, name, m.timesS.size(), cells3d));
}

}  // namespace

std::string tuflowFvFormat(const std::shared_ptr<GDALGroup>& root) {
    return holds(root, {"cell_Nvert", "cell_node", "node_X", "node_Y"}, {"H", "cell_Zb"}) ? "TUFLOW FV results (NetCDF)"
                                                                                          : "";
}

ModelMesh readTuflowFv(const std::string& path, std::shared_ptr<GDALDataset> keep, const MeshReadOptions& opt) {
    MdFile f{path, keep, keep->GetRootGroup()};
    if (!f.root) f.fail("no NetCDF root group");
    ModelMesh m;
    m.source = path;
    m.format = "TUFLOW FV results (NetCDF)";
    readCells(f, m);
    readBed(f, opt, m);
    m.crs = fvCrs(f, m);
    const size_t cells3d = dimensionSize(f, "NumCells3D");
    noteLayers(f, m, m.faceCount(), cells3d);
    readSteps(f, opt, cells3d, m);
    checkModelMesh(m);
    return m;
}

}  // namespace hc::ingest::detail
