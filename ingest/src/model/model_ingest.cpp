// Flood model results -> grids: a quadtree's faces as cells, any other mesh sampled, or the water of a mesh on a DEM
// (model.h, model_ingest.h).
#include "heightcast/ingest/model.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <numeric>

#include <fmt/format.h>

#include "heightcast/core/error.h"
#include "heightcast/core/progress.h"
#include "heightcast/core/timer.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/ingest/mesh.h"
#include "lattice.h"
#include "mesh_frame.h"
#include "model_ingest.h"
#include "sample_mesh.h"

namespace hc::ingest {
namespace {

MeshReadOptions readOptions(const Options& o) {
    MeshReadOptions r;
    r.terrainVar = o.terrainVar;
    r.waterSurfaceVar = o.waterSurfaceVar;
    r.layerVars = o.faceLayerVars;
    return r;
}

// What a reader said, each naming the file.
void passOn(const ModelMesh& m, LoadReport& report) {
    auto named = [&](const std::string& w) { return w.rfind(m.source, 0) == 0 ? w : m.source + ": " + w; };
    for (const std::string& w : m.warnings) report.warnings.push_back(named(w));
    for (const std::string& n : m.notes) report.warnings.push_back(named(n));
}

void describe(const ModelMesh& m, LoadReport& report) {
    size_t lo = SIZE_MAX, hi = 0;
    for (size_t f = 0; f < m.faceCount(); ++f) lo = std::min(lo, m.nodesOf(f)), hi = std::max(hi, m.nodesOf(f));
    const std::string kind = !m.kind.empty() ? m.kind
                             : lo == hi      ? (lo == 3   ? "triangles"
                                                : lo == 4 ? "quadrilaterals"
                                                          : fmt::format("faces of {} nodes", lo))
                                             : fmt::format("mixed faces of {}-{} nodes", lo, hi);
    report.sourceDescription = fmt::format("{}: {} faces ({}), {} nodes, {} step{}", m.format, m.faceCount(), kind,
                                           m.nodeX.size(), m.timesS.size(), m.timesS.size() == 1 ? "" : "s");
    if (!m.timesS.empty())
        report.sourceDescription += fmt::format(" at {:.9g}..{:.9g} s", m.timesS.front(), m.timesS.back());
    passOn(m, report);
    report.sourceWidth = m.faceCount(), report.sourceHeight = 1;
}

// ---- a quadtree's faces as cells ----

// The faces with a bed value (the others are holes), as a mesh of their own, which takes over m's nodes (m keeps its
// faces, bed and steps, and must outlive it); ids[k] is face k's index in `m`.
ModelMesh facesWithBed(ModelMesh& m, std::vector<size_t>& ids) {
    ModelMesh out;
    out.source = m.source, out.coordsFloat32 = m.coordsFloat32, out.nodeX = std::move(m.nodeX),
    out.nodeY = std::move(m.nodeY);
    for (size_t f = 0; f < m.faceCount(); ++f) {
        if (std::isnan(m.bed.values[f])) continue;
        out.faceNodes.insert(out.faceNodes.end(), m.faceNodes.begin() + long(m.faceStart[f]),
                             m.faceNodes.begin() + long(m.faceStart[f + 1]));
        out.faceStart.push_back(out.faceNodes.size());
        ids.push_back(f);
    }
    const ModelMesh* whole = &m;
    out.faceName = [whole, &ids](size_t k) { return whole->nameOf(ids[k]); };
    return out;
}

Grid cellsShape(const detail::QuadtreeFit& q, const detail::MeshFrame& frame, const ModelMesh& m) {
    Grid shape;
    shape.originWorldX = q.originX, shape.originWorldY = q.originY;
    shape.finestCellM = q.finest, shape.rotationDeg = std::abs(q.rotationDeg) < 1e-12 ? 0.0 : q.rotationDeg;
    shape.rootLevel = q.rootLevel, shape.minLevel = 0, shape.maxLevel = q.maxLevel;
    shape.crsWkt = frame.crsWkt, shape.crsName = frame.crsName;
    if (!m.timesS.empty()) shape.layers.push_back({"water_depth", "m"});
    for (const MeshLayer& l : m.layers) shape.layers.push_back({l.name, l.units});
    shape.values.resize(shape.layers.size());
    return shape;
}

// The faces' cells in Morton order: codes, their faces (as indexes into the mesh) and elevations.
struct Cells {
    std::vector<uint64_t> codes;
    std::vector<size_t> face;
    std::vector<float> elevation;
};

Cells cellsOf(const ModelMesh& m, const std::vector<size_t>& ids, const detail::QuadtreeFit& q) {
    std::vector<uint64_t> codeOf(ids.size());
    for (size_t k = 0; k < ids.size(); ++k) codeOf[k] = makeCellCode(mortonEncode(q.ix[k], q.iy[k]), q.level[k]);
    std::vector<size_t> order(ids.size());
    std::iota(order.begin(), order.end(), size_t{0});
    std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return codeOf[a] < codeOf[b]; });
    Cells c;
    for (size_t k : order)
        c.codes.push_back(codeOf[k]), c.face.push_back(ids[k]), c.elevation.push_back(float(m.bed.values[ids[k]]));
    for (size_t i = 1; i < c.codes.size(); ++i)
        if (c.codes[i] == c.codes[i - 1])
            throw Error(m.source + ": " + m.nameOf(c.face[i - 1]) + " and " + m.nameOf(c.face[i]) +
                        " are the same square");
    return c;
}

// Step k's wet cells: depth = level - bed where positive (a NaN level, a fill value, is dry), and the further layers
// there (a fill value taken as 0, counted in `unset`).
WaterStepData stepOf(const ModelMesh& m, const Cells& c, size_t k, std::vector<uint64_t>& unset) {
    const MeshField level = m.level(k);
    if (level.at != MeshAt::Face)
        throw Error(m.source +
                    ": the water level is given at nodes: a quadtree's faces need it per face (--mesh sample)");
    std::vector<MeshField> layers;
    for (const MeshLayer& l : m.layers) layers.push_back(l.read(k));
    WaterStepData step;
    step.timeS = m.timesS[k];
    step.values.resize(1 + layers.size());
    for (size_t i = 0; i < c.face.size(); ++i) {
        const size_t f = c.face[i];
        const float depth = float(level.values[f] - m.bed.values[f]);
        if (!(depth > 0)) continue;
        step.wet.push_back(uint32_t(i));
        step.values[0].push_back(depth);
        for (size_t l = 0; l < layers.size(); ++l) {
            const double v = layers[l].values.at(f);
            unset[l] += !std::isfinite(v);
            step.values[1 + l].push_back(std::isfinite(v) ? float(v) : 0.0f);
        }
    }
    return step;
}

BuildSummary ingestCells(const Options& opt, ModelMesh& m, const detail::MeshFrame& frame, const std::string& path,
                         LoadReport& report, const Stopwatch& clock) {
    if (m.bed.at != MeshAt::Face)
        throw Error(m.source +
                    ": the bed is given at nodes: a quadtree's faces need it per face (--mesh sample samples it)");
    if (opt.samplingGiven)
        throw Error("--tolerance / --min-cell / --max-cell: " + m.source +
                    "'s faces are taken as cells, as they are (a quadtree): nothing is "
                    "sampled or merged; --mesh sample samples them onto the grid");
    std::vector<size_t> ids;
    detail::QuadtreeFit q;
    {
        const ModelMesh kept = facesWithBed(m, ids);
        if (ids.empty()) throw Error(m.source + ": every face's bed level is a fill value: nothing to ingest");
        q = detail::fitQuadtree(kept, opt.meshToleranceM.value_or(-1));
    }
    const Cells c = cellsOf(m, ids, q);
    const Grid shape = cellsShape(q, frame, m);
    IngestStats stats;
    stats.sourcePath = opt.input, stats.sourceKind = "UGRID mesh", stats.sourceFormat = report.sourceDescription;
    stats.sourceCrsName = frame.sourceCrsName, stats.validPixels = ids.size(), stats.latticeResidualM = q.maxResidual;
    BuildSummary out;
    out.shape = shape;
    out.cellCount = ids.size();
    out.cellsPerLevel.assign(size_t(q.maxLevel) + 1, 0);
    for (int l : q.level) ++out.cellsPerLevel[size_t(l)];
    std::vector<uint64_t> unset(m.layers.size(), 0);
    try {
        GridFileWriter writer(path, shape, ids.size(), m.timesS.size());
        writer.append(c.codes, {std::span<const float>(c.elevation)});
        Progress progress("writing " + std::to_string(m.timesS.size()) + " steps", m.timesS.size(),
                          opt.progress && !m.timesS.empty());
        for (size_t k = 0; k < m.timesS.size(); ++k) {
            const WaterStepData step = stepOf(m, c, k, unset);
            out.steps.push_back({step.timeS, step.wet.size(), 0, {}, {}});
            out.stepBytes += 8 * step.wet.size();
            writer.appendStep(step);
            progress.advance(1);
        }
        stats.seconds = clock.seconds();
        writer.commit(stats);
    } catch (const Error& e) {
        const std::string msg = e.what();  // the writer checks every cell: overlapping faces are caught there
        if (msg.find("overlap") != std::string::npos)
            throw Error(m.source + ": faces overlap (" + msg + "): not a quadtree mesh");
        throw;
    }
    for (size_t l = 0; l < m.layers.size(); ++l)
        if (unset[l])
            report.warnings.push_back(
                fmt::format("{}: {} is a fill value on {} wet face{} (summed over the steps): taken as 0", m.source,
                            m.layers[l].name, unset[l], unset[l] == 1 ? "" : "s"));
    out.shape.stats = stats;
    out.shape.steps = out.steps;
    out.wetCells = out.steps.empty() ? 0 : out.steps.back().wetCells;
    report.method = fmt::format(
        "taken as it is: one cell per face, no resampling; the lattice fitted to every node (largest residual {:.3g} "
        "m, "
        "RMS {:.3g} m, tolerance {:.3g} m){}",
        q.maxResidual, q.rmsResidual, q.tolerance,
        shape.rotationDeg == 0
            ? std::string()
            : fmt::format("; turned {:.9g} degrees against the CRS's axes (the grid's rotation)", shape.rotationDeg));
    report.sourceValidPixels = ids.size();
    return out;
}

// ---- any other mesh, sampled ----

detail::PixelFrame frameOver(const ModelMesh& m, double cell) {
    double x0 = HUGE_VAL, x1 = -HUGE_VAL, y0 = HUGE_VAL, y1 = -HUGE_VAL;
    for (uint32_t n : m.faceNodes)
        x0 = std::min(x0, m.nodeX[n]), x1 = std::max(x1, m.nodeX[n]), y0 = std::min(y0, m.nodeY[n]),
        y1 = std::max(y1, m.nodeY[n]);
    detail::PixelFrame f;
    f.pixelSizeM = cell;
    f.west = std::floor(x0 / cell) * cell, f.north = std::ceil(y1 / cell) * cell;
    const double w = std::ceil((x1 - f.west) / cell), h = std::ceil((f.north - y0) / cell);
    if (w * h > 4e9 || w > 1e9 || h > 1e9)
        throw Error(fmt::format(
            "{}: sampling {:.6g} x {:.6g} m at {:.6g} m pixels needs {:.3g} pixels: give a coarser --min-cell",
            m.source, x1 - x0, y1 - y0, cell, w * h));
    f.width = size_t(std::max(1.0, w)), f.height = size_t(std::max(1.0, h));
    return f;
}

// Depth [m] on the terrain's pixels from a sampled level: NaN on holes, 0 where dry.
Raster depthOf(const Raster& terrain, const std::vector<float>& level) {
    Raster d = terrain;
    d.roundingM.clear();
    for (size_t i = 0; i < d.values.size(); ++i) {
        if (std::isnan(terrain.values[i])) continue;
        const float depth = level[i] - terrain.values[i];
        d.values[i] = depth > 0 ? depth : 0.0f;  // NaN level: dry
    }
    return d;
}

struct Sampled {
    std::shared_ptr<const ModelMesh> mesh;
    std::shared_ptr<const detail::MeshCover> cover;
};

WaterSteps stepsOf(Sampled s, const Raster& terrain) {
    WaterSteps w;
    w.count = s.mesh->timesS.size();
    w.timesS = s.mesh->timesS;
    w.load = [s, &terrain](size_t k) {
        const MeshField level = s.mesh->level(k);
        return depthOf(terrain, s.cover->sampleLevel(level, level.at == s.mesh->bed.at ? s.mesh->bed : MeshField{}));
    };
    return w;
}

BuildSummary ingestSampled(const Options& opt, std::shared_ptr<ModelMesh> m, const detail::MeshFrame& frame,
                           const std::string& path, LoadReport& report, const Stopwatch& clock) {
    if (m->bed.values.empty())
        throw Error(m->source +
                    ": the results hold no bed level: give the terrain as a DEM (hc-ingest DEM.tif --water-mesh " +
                    m->source + ")");
    if (!m->layers.empty())
        throw Error(m->source + ": --face-layers are read from quadtree meshes only (their faces taken as cells)");
    const double cell = opt.minCellM ? *opt.minCellM : detail::finestFaceSide(*m);
    const detail::PixelFrame pf = frameOver(*m, cell);
    auto cover = std::make_shared<detail::MeshCover>(*m, pf, opt.threads);
    Raster terrain;
    terrain.width = pf.width, terrain.height = pf.height, terrain.westWorld = pf.west, terrain.northWorld = pf.north,
    terrain.pixelSizeM = cell;
    terrain.crsWkt = frame.crsWkt, terrain.crsName = frame.crsName;
    terrain.values = cover->sample(m->bed);
    if (terrain.validCount() == 0)
        throw Error(m->source + ": no pixel centre of " + fmt::format("{:.6g}", cell) +
                    " m lies on a face with a bed level: choose a finer --min-cell");
    const BuildOptions build = buildOptions(opt, cell, report);
    const WaterSteps steps = stepsOf({m, cover}, terrain);
    IngestStats extra;
    extra.sourcePath = opt.input, extra.sourceCrsName = frame.sourceCrsName,
    extra.sourceFormat = report.sourceDescription, extra.seconds = clock.seconds();
    BuildSummary b = buildGridFile(terrain, steps.count ? &steps : nullptr, build, path, extra);
    report.method = fmt::format(
        "sampled at the centres of {} x {} pixels of {:.6g} m ({}; the bed and each step's level as the model defines "
        "them: {}), "
        "then built as a raster",
        pf.width, pf.height, cell, opt.minCellM ? "--min-cell" : "the finest faces' size",
        m->bed.at == MeshAt::Face ? "constant per face" : "linear over triangles");
    report.sourceValidPixels = cover->covered();
    return b;
}

// Fill values the file does not declare: --nodata V makes bed and levels equal to V no value; without it, a classic
// sentinel in the bed is said, with that fix (a level at a sentinel is below any bed: dry either way).
void undeclaredFills(const Options& opt, ModelMesh& m, LoadReport& report) {
    if (opt.nodata) {
        const double v = *opt.nodata;
        for (double& z : m.bed.values)
            if (z == v) z = NAN;
        if (m.level)
            m.level = [inner = m.level, v](size_t k) {
                MeshField f = inner(k);
                for (double& z : f.values)
                    if (z == v) z = NAN;
                return f;
            };
        return;
    }
    for (double sentinel : {-9999.0, -99999.0, -999.0, -32768.0}) {
        const auto n = std::count(m.bed.values.begin(), m.bed.values.end(), sentinel);
        if (n > 0)
            report.warnings.push_back(fmt::format(
                "{}: {} bed values are {:g}, a classic fill value the file does not declare: taken as ground at "
                "that height; --nodata {:g} takes them as holes",
                m.source, n, sentinel, sentinel));
    }
}

}  // namespace

BuildSummary ingestModelToFile(const Options& opt, const std::string& path, LoadReport& report) {
    const Stopwatch clock;
    validateOptions(opt);  // --tolerance, --min-cell, --max-cell, --nodata: as for a raster
    for (const std::string& name : opt.faceLayerVars)
        if (name == "elevation" || name == "water_depth" || name == "water_surface" || name == opt.terrainVar ||
            name == opt.waterSurfaceVar)
            throw Error("--face-layers " + name +
                        ": that name is the terrain or the water; name further variables (velocity, ...)");
    auto m = std::make_shared<ModelMesh>(readModelMesh(opt.input, readOptions(opt)));
    describe(*m, report);
    undeclaredFills(opt, *m, report);
    const detail::MeshFrame frame = detail::meshToMetric(*m, opt.sourceSrs, report);
    report.sourceCrsName = frame.sourceCrsName, report.gridCrsName = frame.crsName;
    std::string why;
    bool cells = opt.meshMode == MeshMode::Cells;
    if (opt.meshMode == MeshMode::Auto && !m->bed.values.empty() && m->bed.at == MeshAt::Face) {
        if (frame.geographic)
            why = "in degrees (projected to UTM, its squares are squares no more)";
        else
            cells = m->quadtreeModel || detail::looksLikeQuadtree(*m, 0.02, why);
    }
    if (cells) return ingestCells(opt, *m, frame, path, report, clock);
    if (opt.meshMode == MeshMode::Auto && m->quadtreeModel && !why.empty())
        report.warnings.push_back(m->source + ": a quadtree model's mesh " + why + ": sampled onto the grid");
    return ingestSampled(opt, m, frame, path, report, clock);
}

namespace detail {

WaterSteps meshWaterSteps(const Options& opt, const Raster& terrain, LoadReport& report) {
    auto m = std::make_shared<ModelMesh>(readModelMesh(opt.waterMesh, readOptions(opt)));
    if (m->timesS.empty())
        throw Error(opt.waterMesh + ": the results hold no water level over time (--water-surface-var names it)");
    passOn(*m, report);
    meshToTarget(*m, opt.meshSrs, terrain.crsWkt, report);
    const PixelFrame pf{terrain.westWorld, terrain.northWorld, terrain.pixelSizeM, terrain.width, terrain.height};
    auto cover = std::make_shared<const MeshCover>(*m, pf, opt.threads);
    if (cover->covered() == 0)
        throw Error(opt.waterMesh +
                    ": no face of the mesh lies on the terrain's pixels: are both in the CRS they say (--mesh-srs "
                    "names the mesh's)?");
    report.method += fmt::format("; water from {} ({} faces, {} steps, on {} of the terrain's pixels)", m->format,
                                 m->faceCount(), m->timesS.size(), cover->covered());
    return stepsOf({m, cover}, terrain);
}

}  // namespace detail
}  // namespace hc::ingest
