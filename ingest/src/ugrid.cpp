// UGRID quadtree meshes -> grid with water steps (ugrid.h).
#include "heightcast/ingest/ugrid.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <optional>
#include <sstream>

#include <fmt/format.h>
#include <gdal_priv.h>
#include <ogr_spatialref.h>

#include "gdal_util.h"
#include "heightcast/core/error.h"
#include "heightcast/core/timer.h"
#include "heightcast/grid/grid_file.h"

namespace hc::ingest {
namespace {

using ArrayPtr = std::shared_ptr<GDALMDArray>;

std::unique_ptr<GDALDataset> openMultidim(const std::string& path) {
    detail::ensureGdal();
    return std::unique_ptr<GDALDataset>(
        GDALDataset::Open(path.c_str(), GDAL_OF_MULTIDIM_RASTER | GDAL_OF_READONLY, nullptr, nullptr, nullptr));
}

std::string textAttr(const ArrayPtr& a, const std::string& name) {
    auto at = a->GetAttribute(name);
    if (!at) return "";
    const char* v = at->ReadAsString();
    return v ? v : "";
}

// The mesh topology variable (cf_role mesh_topology, topology_dimension 2), or nullptr.
ArrayPtr findTopology(const std::shared_ptr<GDALGroup>& root) {
    const char* const show[] = {"SHOW_ZERO_DIM=YES", "SHOW_ALL=YES", nullptr};
    for (const std::string& name : root->GetMDArrayNames(show)) {
        ArrayPtr a = root->OpenMDArray(name);
        if (!a || textAttr(a, "cf_role") != "mesh_topology") continue;
        auto dim = a->GetAttribute("topology_dimension");
        if (dim && dim->ReadAsInt() == 2) return a;
    }
    return nullptr;
}

struct Reader {
    std::string path;
    std::shared_ptr<GDALGroup> root;
    [[noreturn]] void fail(const std::string& what) const { throw Error(path + ": " + what); }
    ArrayPtr open(const std::string& name, const std::string& role) const {
        ArrayPtr a = root->OpenMDArray(name);
        if (!a) fail("no variable '" + name + "' (" + role + ")");
        return a;
    }
    // All of `a` as doubles (exact for the integers of a connectivity), in its dimension order.
    std::vector<double> read(const ArrayPtr& a) const {
        const auto dims = a->GetDimensions();
        size_t total = 1;
        std::vector<GUInt64> start(dims.size(), 0);
        std::vector<size_t> count;
        for (const auto& d : dims) count.push_back(size_t(d->GetSize())), total *= size_t(d->GetSize());
        std::vector<double> v(total);
        if (total && !a->Read(start.data(), count.data(), nullptr, nullptr, GDALExtendedDataType::Create(GDT_Float64), v.data()))
            fail("cannot read the variable '" + a->GetName() + "': " + CPLGetLastErrorMsg());
        return v;
    }
    std::optional<double> fill(const ArrayPtr& a) const {
        bool has = false;
        const double f = a->GetNoDataValueAsDouble(&has);
        return has ? std::optional<double>(f) : std::nullopt;
    }
};

std::string fmtNum(double v) { return detail::fmt(v, 9); }

// A face as read: its corners in order around it.
struct Face {
    std::array<std::array<double, 2>, 4> p;
};

// The quadtree the faces make: each face's cell (ix, iy, level on the finest lattice), the grid's origin, finest
// size and rotation. Throws naming the face and the problem when the mesh is not a quadtree.
struct Quadtree {
    double originX = 0, originY = 0, finest = 0, rotationDeg = 0;
    std::vector<uint32_t> ix, iy;
    std::vector<int> level;
    int rootLevel = 0, maxLevel = 0;
};

Quadtree quadtreeOf(const Reader& r, const std::vector<Face>& faces, const std::vector<size_t>& ids) {
    Quadtree q;
    const size_t n = faces.size();
    // Sides and the orientation of each face (its first edge's angle, modulo 90 degrees, in (-45, 45]).
    std::vector<double> side(n), angle(n);
    for (size_t f = 0; f < n; ++f) {
        const auto& p = faces[f].p;
        double len[4], ex[4], ey[4];
        for (int e = 0; e < 4; ++e) {
            ex[e] = p[size_t((e + 1) % 4)][0] - p[size_t(e)][0];
            ey[e] = p[size_t((e + 1) % 4)][1] - p[size_t(e)][1];
            len[e] = std::hypot(ex[e], ey[e]);
        }
        const double s = len[0];
        const std::string name = "face " + std::to_string(ids[f]);
        if (!(s > 0)) r.fail(name + " has two nodes at one place: a quadtree mesh has square faces");
        for (int e = 1; e < 4; ++e)
            if (std::abs(len[e] - s) > 1e-6 * s) r.fail(name + " is not a square (sides " + fmtNum(s) + " and " + fmtNum(len[e]) + " m): not a quadtree mesh");
        for (int e = 0; e < 4; ++e)
            if (std::abs(ex[e] * ex[(e + 1) % 4] + ey[e] * ey[(e + 1) % 4]) > 1e-6 * s * s)
                r.fail(name + " is not a square (its corners are not right angles): not a quadtree mesh");
        side[f] = s;
        double a = std::atan2(ey[0], ex[0]) * 180.0 / M_PI;
        a = std::remainder(a, 90.0);  // (-45, 45]
        if (a <= -45.0) a += 90.0;
        angle[f] = a;
    }
    // One orientation for all: the grid's rotation (within 1e-6 degrees; an axis-aligned mesh is exactly 0).
    q.rotationDeg = std::abs(angle[0]) < 1e-9 ? 0.0 : angle[0];
    for (size_t f = 1; f < n; ++f) {
        double d = std::remainder(angle[f] - angle[0], 90.0);
        if (std::abs(d) > 1e-6)
            r.fail("face " + std::to_string(ids[f]) + " is turned by " + fmtNum(angle[f]) + " degrees, face " + std::to_string(ids[0]) + " by " +
                   fmtNum(angle[0]) + ": a quadtree's faces share one orientation");
    }
    q.finest = *std::min_element(side.begin(), side.end());
    // Each face in the grid's axes, relative to face 0's first node (small numbers, so no UTM magnitude is rotated).
    Grid frame;
    frame.rotationDeg = q.rotationDeg;
    frame.originWorldX = faces[0].p[0][0], frame.originWorldY = faces[0].p[0][1];
    std::vector<double> cx(n), cy(n);
    double minX = HUGE_VAL, minY = HUGE_VAL;
    size_t coarsest = 0;
    q.level.resize(n);
    for (size_t f = 0; f < n; ++f) {
        double x0 = HUGE_VAL, y0 = HUGE_VAL;
        for (const auto& c : faces[f].p) {
            double x = 0, y = 0;
            frame.worldToLocal(c[0], c[1], x, y);
            x0 = std::min(x0, x), y0 = std::min(y0, y);
        }
        cx[f] = x0, cy[f] = y0;
        minX = std::min(minX, x0), minY = std::min(minY, y0);
        const double ratio = side[f] / q.finest;
        const int l = int(std::lround(std::log2(ratio)));
        if (l < 0 || l > kMaxLevel || std::abs(ratio - std::ldexp(1.0, l)) > 1e-6 * ratio)
            r.fail("face " + std::to_string(ids[f]) + " has a side of " + fmtNum(side[f]) + " m, not a power-of-two multiple of the smallest face's " +
                   fmtNum(q.finest) + " m: not a quadtree mesh");
        q.level[f] = l;
        if (l > q.level[coarsest]) coarsest = f;
    }
    // The origin: on the coarsest face's lattice, at or below every face's corner, so every face aligns to its size.
    const double cs = side[coarsest];
    // (A whole number of coarse sides, up to the rounding of coordinates in double: 1e-6 of a side.)
    const double ox = cx[coarsest] - std::ceil((cx[coarsest] - minX) / cs - 1e-6) * cs;
    const double oy = cy[coarsest] - std::ceil((cy[coarsest] - minY) / cs - 1e-6) * cs;
    q.ix.resize(n), q.iy.resize(n);
    uint64_t extent = 1;
    for (size_t f = 0; f < n; ++f) {
        const double fx = (cx[f] - ox) / q.finest, fy = (cy[f] - oy) / q.finest;
        const double rx = std::round(fx), ry = std::round(fy);
        if (std::abs(fx - rx) > 1e-6 * std::max(1.0, std::abs(fx)) || std::abs(fy - ry) > 1e-6 * std::max(1.0, std::abs(fy)) || rx < 0 || ry < 0 ||
            rx > 2147483647.0 || ry > 2147483647.0)
            r.fail("face " + std::to_string(ids[f]) + "'s corner is not on the lattice of the smallest faces: not a quadtree mesh");
        const uint64_t span = uint64_t{1} << q.level[f];
        if (uint64_t(rx) % span != 0 || uint64_t(ry) % span != 0)
            r.fail("face " + std::to_string(ids[f]) + " (side " + fmtNum(side[f]) + " m) is not aligned to its own size: not a quadtree mesh");
        q.ix[f] = uint32_t(rx), q.iy[f] = uint32_t(ry);
        extent = std::max({extent, uint64_t(rx) + span, uint64_t(ry) + span});
        q.maxLevel = std::max(q.maxLevel, q.level[f]);
    }
    while ((uint64_t{1} << q.rootLevel) < extent) ++q.rootLevel;
    if (q.rootLevel > kMaxRootLevel) r.fail("the mesh spans " + std::to_string(extent) + " smallest faces: too large for one grid");
    frame.localToWorld(ox, oy, q.originX, q.originY);
    return q;
}

// The CRS from the variables' grid_mapping (crs_wkt, spatial_ref, or an EPSG code); nullopt when none.
std::optional<OGRSpatialReference> crsOf(const Reader& r, const ArrayPtr& terrain) {
    if (auto srs = terrain->GetSpatialRef(); srs && !srs->IsEmpty()) return *srs;
    const std::string mapping = textAttr(terrain, "grid_mapping");
    ArrayPtr m = mapping.empty() ? nullptr : r.root->OpenMDArray(mapping);
    if (!m) return std::nullopt;
    for (const char* key : {"crs_wkt", "spatial_ref", "epsg_code", "EPSG_code"}) {
        std::string v = textAttr(m, key);
        if (v.empty()) continue;
        OGRSpatialReference srs;
        if (srs.SetFromUserInput(v.c_str()) != OGRERR_NONE) r.fail("the CRS in " + mapping + ":" + key + " is not one GDAL reads: " + v.substr(0, 80));
        return srs;
    }
    return std::nullopt;
}

}  // namespace

bool isUgridMesh(const std::string& path) {
    CPLErrorStateBackuper keep;  // a file that is not a mesh leaves no error behind (ensureGdal keeps GDAL quiet)
    auto ds = openMultidim(path);
    if (!ds) return false;
    auto root = ds->GetRootGroup();
    return root && findTopology(root) != nullptr;
}

BuildSummary ingestUgridToFile(const Options& opt, const std::string& path, LoadReport& report) {
    const Stopwatch clock;
    auto ds = openMultidim(opt.input);
    if (!ds) throw Error(opt.input + ": cannot be opened as a multidimensional (NetCDF) dataset: " + detail::lastGdalError());
    Reader r{opt.input, ds->GetRootGroup()};
    ArrayPtr topo = r.root ? findTopology(r.root) : nullptr;
    if (!topo) r.fail("no UGRID mesh (no variable with cf_role mesh_topology and topology_dimension 2)");
    // Nodes and faces.
    std::istringstream coords(textAttr(topo, "node_coordinates"));
    std::string xName, yName;
    coords >> xName >> yName;
    if (yName.empty()) r.fail(topo->GetName() + ":node_coordinates does not name two variables (x y)");
    const std::vector<double> nodeX = r.read(r.open(xName, "node x")), nodeY = r.read(r.open(yName, "node y"));
    if (nodeX.size() != nodeY.size()) r.fail(xName + " and " + yName + " differ in length");
    const std::string connName = textAttr(topo, "face_node_connectivity");
    if (connName.empty()) r.fail(topo->GetName() + " has no face_node_connectivity: not a mesh of faces");
    ArrayPtr conn = r.open(connName, "face_node_connectivity");
    const auto connDims = conn->GetDimensions();
    if (connDims.size() != 2) r.fail(connName + " is not two-dimensional (faces x nodes)");
    // (faces, nodes) as UGRID writes it, or (nodes, faces) where face_dimension says the faces come second.
    const std::string faceDimName = textAttr(topo, "face_dimension");
    const bool transposed = !faceDimName.empty() && connDims[1]->GetName() == faceDimName;
    const size_t faceCount = size_t(connDims[transposed ? 1 : 0]->GetSize()), perFace = size_t(connDims[transposed ? 0 : 1]->GetSize());
    const std::vector<double> connectivity = r.read(conn);
    int startIndex = 0;
    if (auto s = conn->GetAttribute("start_index")) startIndex = s->ReadAsInt();
    const std::optional<double> nodeFill = r.fill(conn);
    // The terrain per face: a fill value (or NaN) is a hole.
    ArrayPtr terrainVar = r.open(opt.terrainVar, "the terrain, --terrain-var");
    const std::vector<double> zb = r.read(terrainVar);
    if (zb.size() != faceCount) r.fail(opt.terrainVar + " has " + std::to_string(zb.size()) + " values for " + std::to_string(faceCount) + " faces: not a face variable");
    const std::optional<double> zbFill = r.fill(terrainVar);
    std::vector<Face> faces;
    std::vector<size_t> ids;  // the file's face index of each face kept
    for (size_t f = 0; f < faceCount; ++f) {
        if (std::isnan(zb[f]) || (zbFill && zb[f] == *zbFill)) continue;
        Face face;
        size_t valid = 0;
        for (size_t k = 0; k < perFace; ++k) {
            const double v = connectivity[transposed ? k * faceCount + f : f * perFace + k];
            if (std::isnan(v) || (nodeFill && v == *nodeFill) || v < 0) continue;
            const double node = v - startIndex;
            if (node < 0 || node >= double(nodeX.size()) || node != std::floor(node))
                r.fail("face " + std::to_string(f) + " names node " + fmtNum(v) + ", not one of the " + std::to_string(nodeX.size()) +
                       " nodes (start_index " + std::to_string(startIndex) + ")");
            if (valid < 4) face.p[valid] = {nodeX[size_t(node)], nodeY[size_t(node)]};
            ++valid;
        }
        if (valid != 4)
            r.fail("face " + std::to_string(f) + " has " + std::to_string(valid) + " nodes: a quadtree mesh has square faces of 4 nodes");
        faces.push_back(face);
        ids.push_back(f);
    }
    if (faces.empty()) r.fail("every face's terrain (" + opt.terrainVar + ") is a fill value: nothing to ingest");
    const Quadtree q = quadtreeOf(r, faces, ids);

    // Water levels over time.
    ArrayPtr levelVar = opt.waterSurfaceVar.empty() ? nullptr : r.root->OpenMDArray(opt.waterSurfaceVar);
    std::vector<double> zs, times;
    size_t stepCount = 0;
    if (levelVar) {
        const auto dims = levelVar->GetDimensions();
        zs = r.read(levelVar);
        if (dims.size() == 1 && zs.size() == faceCount) {
            stepCount = 1, times = {0.0};
        } else if (dims.size() == 2 && dims[1]->GetSize() == faceCount) {
            stepCount = size_t(dims[0]->GetSize());
            ArrayPtr t = dims[0]->GetIndexingVariable();
            if (!t) t = r.root->OpenMDArray(dims[0]->GetName());
            if (t) {
                const double unit = detail::cfSecondsPerUnit(t->GetUnit().empty() ? textAttr(t, "units") : t->GetUnit());
                times = r.read(t);
                if (unit == 0 || times.size() != stepCount) {
                    report.warnings.push_back(opt.input + ": the time variable " + t->GetName() + " has no CF time units: the step index is taken as time");
                    times.clear();
                } else {
                    for (double& v : times) v *= unit;
                }
            }
            if (times.empty())
                for (size_t k = 0; k < stepCount; ++k) times.push_back(double(k));
            for (size_t k = 1; k < times.size(); ++k)
                if (!(times[k] > times[k - 1]))
                    r.fail("the times of " + opt.waterSurfaceVar + " do not increase: step " + std::to_string(k) + " at " + fmtNum(times[k]) + " s follows " +
                           fmtNum(times[k - 1]) + " s");
        } else {
            r.fail(opt.waterSurfaceVar + " is not a face variable (faces) or (time, faces) of this mesh");
        }
    } else if (!opt.waterSurfaceVar.empty() && opt.waterSurfaceVar != "zs") {
        r.fail("no variable '" + opt.waterSurfaceVar + "' (--water-surface-var)");
    }
    const std::optional<double> zsFill = levelVar ? r.fill(levelVar) : std::nullopt;
    // Further step layers: face variables shaped as the water level, each read whole (8 bytes a face and step).
    struct FaceLayer {
        std::string name, units;
        std::vector<double> values;
        std::optional<double> fill;
        uint64_t unset = 0;  // wet faces where it is a fill value (taken as 0)
    };
    std::vector<FaceLayer> faceLayers;
    if (!opt.faceLayerVars.empty() && !levelVar)
        r.fail("--face-layers needs the water level variable '" + opt.waterSurfaceVar + "': step layers are stored on wet faces");
    for (const std::string& name : opt.faceLayerVars) {
        if (name == "elevation" || name == "water_depth" || name == "water_surface" || name == opt.waterSurfaceVar || name == opt.terrainVar)
            r.fail("--face-layers " + name + ": that name is the terrain or the water; name further variables (velocity, ...)");
        for (const FaceLayer& f : faceLayers)
            if (f.name == name) r.fail("--face-layers names " + name + " twice");
        ArrayPtr a = r.open(name, "--face-layers");
        FaceLayer f{name, a->GetUnit().empty() ? textAttr(a, "units") : a->GetUnit(), r.read(a), r.fill(a), 0};
        if (f.values.size() != zs.size())
            r.fail(name + " has " + std::to_string(f.values.size()) + " values, the water level " + opt.waterSurfaceVar + " " +
                   std::to_string(zs.size()) + ": a step layer must be a face variable over the same times");
        faceLayers.push_back(std::move(f));
    }

    // The grid: cells in Morton order.
    Grid shape;
    shape.originWorldX = q.originX, shape.originWorldY = q.originY;
    shape.finestCellM = q.finest, shape.rotationDeg = q.rotationDeg;
    shape.rootLevel = q.rootLevel, shape.minLevel = 0, shape.maxLevel = q.maxLevel;
    std::optional<OGRSpatialReference> srs;
    if (!opt.sourceSrs.empty() && opt.sourceSrs != "local") {
        srs.emplace();
        if (srs->SetFromUserInput(opt.sourceSrs.c_str()) != OGRERR_NONE) throw Error("--s_srs " + opt.sourceSrs + ": not a CRS GDAL reads");
    } else if (opt.sourceSrs.empty()) {
        srs = crsOf(r, terrainVar);
    }
    if (srs) {
        shape.crsWkt = detail::toWkt(*srs);
        shape.crsName = detail::crsName(&*srs);
    } else if (opt.sourceSrs.empty()) {
        report.warnings.push_back(opt.input + ": the mesh names no CRS: coordinates taken as metres in a local frame (name the CRS with --s_srs)");
    }
    if (stepCount) shape.layers.push_back({"water_depth", "m"});
    for (const FaceLayer& f : faceLayers) shape.layers.push_back({f.name, f.units});
    shape.values.resize(shape.layers.size());
    std::vector<size_t> order(faces.size());
    std::iota(order.begin(), order.end(), size_t{0});
    std::vector<uint64_t> codeOf(faces.size());
    for (size_t f = 0; f < faces.size(); ++f) codeOf[f] = makeCellCode(mortonEncode(q.ix[f], q.iy[f]), q.level[f]);
    std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return codeOf[a] < codeOf[b]; });
    std::vector<uint64_t> codes(faces.size());
    std::vector<float> elevation(faces.size());
    for (size_t i = 0; i < order.size(); ++i) codes[i] = codeOf[order[i]], elevation[i] = float(zb[ids[order[i]]]);
    for (size_t i = 1; i < codes.size(); ++i)
        if (codes[i] == codes[i - 1]) r.fail("faces " + std::to_string(ids[order[i - 1]]) + " and " + std::to_string(ids[order[i]]) + " are the same square");

    IngestStats stats;
    stats.sourcePath = opt.input;
    stats.sourceKind = "UGRID mesh";
    stats.sourceCrsName = shape.crsName;
    stats.validPixels = faces.size();
    BuildSummary out;
    out.shape = shape;
    out.cellCount = faces.size();
    out.cellsPerLevel.assign(size_t(q.maxLevel) + 1, 0);
    for (int l : q.level) ++out.cellsPerLevel[size_t(l)];
    try {
        GridFileWriter writer(path, shape, faces.size(), stepCount);
        writer.append(codes, {std::span<const float>(elevation)});
        for (size_t k = 0; k < stepCount; ++k) {
            WaterStepData step;
            step.timeS = times[k];
            step.values.resize(1 + faceLayers.size());
            for (size_t i = 0; i < order.size(); ++i) {
                const size_t f = ids[order[i]];
                const double level = zs[k * faceCount + f];
                if (std::isnan(level) || (zsFill && level == *zsFill)) continue;
                const float depth = float(level - zb[f]);
                if (!(depth > 0)) continue;
                step.wet.push_back(uint32_t(i));
                step.values[0].push_back(depth);
                for (size_t l = 0; l < faceLayers.size(); ++l) {
                    FaceLayer& fl = faceLayers[l];
                    const double v = fl.values[k * faceCount + f];
                    const bool unset = !std::isfinite(v) || (fl.fill && v == *fl.fill);
                    fl.unset += unset;
                    step.values[1 + l].push_back(unset ? 0.0f : float(v));
                }
            }
            out.steps.push_back({step.timeS, step.wet.size(), 0, {}, {}});
            out.stepBytes += 8 * step.wet.size();
            writer.appendStep(step);
        }
        stats.seconds = clock.seconds();
        writer.commit(stats);
    } catch (const Error& e) {
        // The writer checks every cell: overlapping faces are caught there; say it of the mesh.
        const std::string m = e.what();
        if (m.find("overlap") != std::string::npos) r.fail("faces overlap (" + m + "): not a quadtree mesh");
        throw;
    }
    for (const FaceLayer& f : faceLayers)
        if (f.unset)
            report.warnings.push_back(fmt::format("{}: {} is a fill value on {} wet face{} (summed over the steps): taken as 0", opt.input,
                                                  f.name, f.unset, f.unset == 1 ? "" : "s"));
    out.shape.stats = stats;
    out.shape.steps = out.steps;
    out.wetCells = out.steps.empty() ? 0 : out.steps.back().wetCells;
    report.sourceDescription = fmt::format("UGRID mesh: {} faces ({} with terrain), {} nodes, {} step{}", faceCount, faces.size(), nodeX.size(),
                                           stepCount, stepCount == 1 ? "" : "s");
    report.sourceCrsName = shape.crsName;
    report.gridCrsName = shape.crsName;
    report.method = q.rotationDeg == 0 ? "taken as it is: one cell per face, no resampling"
                                       : fmt::format("taken as it is: one cell per face, no resampling; the quadtree is turned {:.9g} degrees "
                                                     "against the CRS's axes (stored as the grid's rotation)",
                                                     q.rotationDeg);
    report.sourceWidth = faceCount;
    report.sourceHeight = 1;
    report.sourceValidPixels = faces.size();
    return out;
}

}  // namespace hc::ingest
