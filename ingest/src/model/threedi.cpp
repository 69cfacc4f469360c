// 3Di results_3di.nc (NetCDF: the 2-D surface cells of a quadtree, water level per cell over time) -> ModelMesh.
#include <algorithm>
#include <cmath>
#include <memory>
#include <unordered_map>
#include <utility>

#include "../gdal_util.h"
#include "heightcast/core/error.h"
#include "md_util.h"
#include "readers.h"

namespace hc::ingest::detail {
namespace {

// The 2-D cells kept: indexes into the file's nMesh2D_nodes (3Di calls its cells nodes), 2-D open water only.
struct Cells {
    size_t all = 0;
    std::shared_ptr<std::vector<size_t>> keep = std::make_shared<std::vector<size_t>>();  // shared by the step readers
};

struct PairHash {
    size_t operator()(const std::pair<long long, long long>& p) const {
        return std::hash<long long>()(p.first) * 0x9E3779B97F4A7C15ull ^ std::hash<long long>()(p.second);
    }
};

// A cell type's code as Mesh2DNode_type's attributes name it ("surface_water_2d": "1"), else 3Di's own.
int typeCode(const ArrayPtr& type, const std::string& name, int fallback) {
    const std::string v = textAttr(type, name);
    try {
        return v.empty() ? fallback : std::stoi(v);
    } catch (const std::exception&) {
        return fallback;
    }
}

// The surface water cells (Mesh2DNode_type), and notes on the groundwater, boundary and 1-D nodes left out.
Cells surfaceCells(const MdFile& f, size_t all, ModelMesh& m) {
    Cells c{all};
    ArrayPtr type = f.find("Mesh2DNode_type");
    if (!type) type = f.find("Mesh2D_node_type");
    if (!type) {
        for (size_t i = 0; i < all; ++i) c.keep->push_back(i);
        m.warnings.push_back(f.path + ": no cell types (Mesh2DNode_type): all " + std::to_string(all) +
                             " 2-D cells taken as surface water");
        return c;
    }
    const std::vector<double> t = f.read(type);
    if (t.size() != all)
        f.fail(type->GetName() + " has " + std::to_string(t.size()) + " values for " + std::to_string(all) +
               " 2-D cells");
    const int surface = typeCode(type, "surface_water_2d", 1), ground = typeCode(type, "groundwater_2d", 2);
    const int openBound = typeCode(type, "open_water_boundary_2d", 5),
              groundBound = typeCode(type, "groundwater_boundary_2d", 6);
    size_t groundwater = 0, boundary = 0, other = 0;
    for (size_t i = 0; i < all; ++i) {
        const int code = std::isfinite(t[i]) ? int(t[i]) : -1;
        if (code == surface)
            c.keep->push_back(i);
        else if (code == ground)
            ++groundwater;
        else if (code == openBound || code == groundBound)
            ++boundary;
        else
            ++other;
    }
    if (c.keep->empty()) f.fail("no 2-D surface water cell (" + type->GetName() + " " + std::to_string(surface) + ")");
    if (groundwater)
        m.notes.push_back(std::to_string(groundwater) +
                          " 2-D groundwater cells left out (the surface water cells drawn)");
    if (boundary)
        m.notes.push_back(std::to_string(boundary) + " 2-D boundary cells (outside the model domain) left out");
    if (other)
        m.notes.push_back(std::to_string(other) + " 2-D cells of other types (" + type->GetName() + ") left out");
    return c;
}

// The size of a dimension of the file by name (0 when it has none).
size_t dimensionSize(const MdFile& f, const std::string& name) {
    for (const auto& d : f.root->GetDimensions())
        if (d->GetName() == name) return size_t(d->GetSize());
    return 0;
}

// One square face per kept cell from its corner bounds (Mesh2DContour_x/_y, as Mesh2DFace_xcc's `bounds` names
// them), corners anticlockwise from the south-west; cells share the nodes where their corners coincide.
void buildFaces(const MdFile& f, const Cells& c, ModelMesh& m) {
    ArrayPtr xcc = f.find("Mesh2DFace_xcc"), ycc = f.find("Mesh2DFace_ycc");
    const std::string bx = xcc && !textAttr(xcc, "bounds").empty() ? textAttr(xcc, "bounds") : "Mesh2DContour_x";
    const std::string by = ycc && !textAttr(ycc, "bounds").empty() ? textAttr(ycc, "bounds") : "Mesh2DContour_y";
    ArrayPtr bxv = f.open(bx, "the cells' corner x"), byv = f.open(by, "the cells' corner y");
    const std::vector<size_t> shape = shapeOf(bxv);
    if (shape.size() != 2 || shape[0] != c.all || shapeOf(byv) != shape)
        f.fail(bx + " and " + by + " are not (" + std::to_string(c.all) + " cells, corners)");
    std::vector<double> x = f.read(bxv), y = f.read(byv);
    fillToNaN(x, fillOf(bxv).value_or(-9999)), fillToNaN(y, fillOf(byv).value_or(-9999));
    m.coordsFloat32 = bxv->GetDataType().GetNumericDataType() == GDT_Float32;
    // Each cell's extent; the smallest sets the quantum that tells coinciding corners apart from distinct ones.
    std::vector<double> box;  // x0 y0 x1 y1 per kept cell
    double smallest = INFINITY;
    const auto row = [&](const std::vector<double>& v, size_t cell) {
        return std::minmax_element(v.begin() + std::ptrdiff_t(cell * shape[1]),
                                   v.begin() + std::ptrdiff_t((cell + 1) * shape[1]));
    };
    for (size_t cell : *c.keep) {
        const auto [x0, x1] = row(x, cell);
        const auto [y0, y1] = row(y, cell);
        if (!std::isfinite(*x0 + *x1 + *y0 + *y1) || !(*x1 > *x0) || !(*y1 > *y0))
            f.fail("2-D cell " + std::to_string(cell + 1) + " (of nMesh2D_nodes, from 1) has no corner bounds (" + bx +
                   ", " + by + ": fill values or an empty square)");
        box.insert(box.end(), {*x0, *y0, *x1, *y1});
        smallest = std::min({smallest, *x1 - *x0, *y1 - *y0});
    }
    const double quantum = smallest * 1e-3;
    std::unordered_map<std::pair<long long, long long>, uint32_t, PairHash> nodeAt;
    auto node = [&](double px, double py) {
        const auto key = std::make_pair(std::llround(px / quantum), std::llround(py / quantum));
        auto [it, added] = nodeAt.try_emplace(key, uint32_t(m.nodeX.size()));
        if (added) m.nodeX.push_back(px), m.nodeY.push_back(py);
        return it->second;
    };
    m.faceNodes.reserve(c.keep->size() * 4);
    for (size_t i = 0; i < c.keep->size(); ++i) {
        const double* b = &box[i * 4];
        m.faceNodes.insert(m.faceNodes.end(), {node(b[0], b[1]), node(b[2], b[1]), node(b[2], b[3]), node(b[0], b[3])});
        m.faceStart.push_back(m.faceNodes.size());
    }
}

// The values of the kept cells in one step of a (time, cells) variable (or all of a (cells) one); -9999 and the
// variable's fill value become NaN.
std::vector<double> cellValues(const MdFile& f, const ArrayPtr& a, const std::vector<size_t>& keep,
                               std::optional<size_t> step, size_t& fills) {
    std::vector<double> all = step ? f.readSlice(a, *step) : f.read(a);
    fills += fillToNaN(all, fillOf(a)) + fillToNaN(all, -9999.0);
    std::vector<double> out;
    out.reserve(keep.size());
    for (size_t i : keep) out.push_back(all[i]);
    return out;
}

// The bed per kept cell (Mesh2DFace_zcc, or --terrain-var); cells without one are holes, counted in a warning.
void readBed(const MdFile& f, const Cells& c, const MeshReadOptions& opt, ModelMesh& m) {
    ArrayPtr bed = f.open(opt.terrainVar.empty() ? "Mesh2DFace_zcc" : opt.terrainVar, "the bed level, --terrain-var");
    if (shapeOf(bed) != std::vector<size_t>{c.all})
        f.fail(bed->GetName() + " is not a (" + std::to_string(c.all) + " 2-D cells) variable");
    size_t fills = 0;
    m.bed = {MeshAt::Face, cellValues(f, bed, *c.keep, std::nullopt, fills)};
    const auto holes = std::count_if(m.bed.values.begin(), m.bed.values.end(), [](double v) { return std::isnan(v); });
    if (holes)
        m.warnings.push_back(f.path + ": " + std::to_string(holes) + " of the " + std::to_string(c.keep->size()) +
                             " cells have no bed level (" + bed->GetName() +
                             ": -9999, a fill value or NaN): holes (--terrain-var names another)");
}

// The CRS: projected_coordinate_system's EPSG code, else the water level's grid mapping.
std::string threeDiCrs(const MdFile& f, const ArrayPtr& level) {
    std::vector<ArrayPtr> maps = {f.find("projected_coordinate_system")};
    if (level && !textAttr(level, "grid_mapping").empty()) maps.push_back(f.find(textAttr(level, "grid_mapping")));
    for (const ArrayPtr& g : maps) {
        if (!g) continue;
        for (const char* key : {"crs_wkt", "spatial_ref", "EPSG_code", "epsg_code", "epsg"}) {
            std::string v = textAttr(g, key);
            if (v.empty() || v == "0" || v == "EPSG:0") continue;
            return v.find_first_not_of("0123456789") == std::string::npos ? "EPSG:" + v : v;
        }
    }
    return "";
}

// The times, the water level per kept cell over them, and the step layers.
void readSteps(const MdFile& f, const Cells& c, const MeshReadOptions& opt, const ArrayPtr& level, ModelMesh& m) {
    const std::vector<size_t> shape = shapeOf(level);
    if (shape.size() != 2 || shape[1] != c.all)
        f.fail(level->GetName() + " is not a (time, " + std::to_string(c.all) + " 2-D cells) variable");
    ArrayPtr time = level->GetDimensions()[0]->GetIndexingVariable();
    if (!time) time = f.open("time", "the output times");
    m.timesS = cfTimesS(f, time);
    if (m.timesS.size() != shape[0]) f.fail("the time variable and " + level->GetName() + " differ in steps");
    auto steps = [f, keep = c.keep](const ArrayPtr& a) {
        return [f, keep, a](size_t k) {
            size_t fills = 0;
            return MeshField{MeshAt::Face, cellValues(f, a, *keep, k, fills)};
        };
    };
    m.level = steps(level);
    for (const std::string& name : opt.layerVars) {
        ArrayPtr a = f.open(name, "--face-layers");
        if (shapeOf(a) != shape)
            f.fail(name + " is not shaped as the water level (time, 2-D cells): a step layer must be");
        m.layers.push_back({name, a->GetUnit().empty() ? textAttr(a, "units") : a->GetUnit(), steps(a)});
    }
}

}  // namespace

std::string threeDiFormat(const std::shared_ptr<GDALGroup>& root) {
    return holds(root, {"Mesh2DFace_xcc", "Mesh2DFace_ycc"}, {"Mesh2D_s1", "Mesh2DFace_zcc"}) ? "3Di results (NetCDF)"
                                                                                              : "";
}

ModelMesh readThreeDi(const std::string& path, std::shared_ptr<GDALDataset> keep, const MeshReadOptions& opt) {
    MdFile f{path, keep, keep->GetRootGroup()};
    if (!f.root) f.fail("no NetCDF root group");
    ModelMesh m;
    m.source = path;
    m.format = "3Di results (NetCDF)";
    m.kind = "quadtree";
    m.quadtreeModel = true;
    // The cells: 2-D surface water ones only, each a square face.
    const std::vector<size_t> centres = shapeOf(f.open("Mesh2DFace_xcc", "the 2-D cell centres"));
    if (centres.size() != 1 || centres[0] == 0)
        f.fail("Mesh2DFace_xcc is not a (2-D cells) variable of one or more cells");
    const size_t all = centres[0];
    const Cells c = surfaceCells(f, all, m);
    if (size_t oneD = dimensionSize(f, "nMesh1D_nodes"))
        m.notes.push_back("a 1-D network of " + std::to_string(oneD) + " nodes (not drawn): 2-D cells only");
    buildFaces(f, c, m);
    std::vector<double> ids;
    if (ArrayPtr idv = f.find("Mesh2DNode_id"); idv && shapeOf(idv) == std::vector<size_t>{all}) ids = f.read(idv);
    m.faceName = [ids, keep = c.keep](size_t face) {
        const size_t i = (*keep)[face];
        return "2-D cell " + (ids.empty() ? std::to_string(i + 1) + " (of nMesh2D_nodes, from 1)"
                                          : fmt(ids[i], 12) + " (Mesh2DNode_id)");
    };
    readBed(f, c, opt, m);
    // The water level over time, and the CRS.
    ArrayPtr level;
    if (opt.waterSurfaceVar != "-") {
        level = f.open(opt.waterSurfaceVar.empty() ? "Mesh2D_s1" : opt.waterSurfaceVar,
                       "the water level, --water-surface-var");
        readSteps(f, c, opt, level, m);
    }
    m.crs = threeDiCrs(f, level);
    if (m.crs.empty())
        m.warnings.push_back(path +
                             ": projected_coordinate_system names no CRS: coordinates taken as metres in a local frame "
                             "(name the CRS with --s_srs)");
    checkModelMesh(m);
    return m;
}

}  // namespace hc::ingest::detail
