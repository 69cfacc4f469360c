#include "heightcast/ingest/ingest.h"

#include <cmath>
#include <cstdio>
#include <memory>
#include <optional>

#include <fmt/format.h>

#include "heightcast/core/error.h"
#include "heightcast/ingest/build.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/ranks.h"
#include "heightcast/core/timer.h"
#include "gdal_util.h"
#include "load_water.h"
#include "model/model_ingest.h"
#include "resample.h"

namespace hc::ingest {

namespace {
std::string fmtM(double v) { return fmt::format("{:.6g}", v); }
}  // namespace

int chooseMaxLevel(const Options& opt, double pixelSizeM, LoadReport&) {
    const double target = opt.maxCellM ? *opt.maxCellM : 96.0;  // the report's coarsest cell
    if (opt.maxCellM && *opt.maxCellM < pixelSizeM * (1 - 1e-9))
        throw Error("--max-cell " + fmtM(*opt.maxCellM) + " m is smaller than the finest cell (" + fmtM(pixelSizeM) +
                    " m)");
    int level = 0;
    while (pixelSizeM * std::ldexp(1.0, level + 1) <= target * (1 + 1e-9) && level < kMaxLevel) ++level;
    return level;
}

BuildOptions buildOptions(const Options& opt, double pixelSizeM, LoadReport& report) {
    BuildOptions b;
    b.toleranceM = opt.toleranceM;
    b.maxLevel = chooseMaxLevel(opt, pixelSizeM, report);
    b.threads = opt.threads;
    b.progress = opt.progress;
    return b;
}

namespace {

// Loads terrain (and water) and chooses the build options: the shared first half of both jobs.
struct Prepared {
    Raster terrain;
    WaterSteps water;                // count 0 without water
    std::vector<Raster> waterCache;  // each step's raster, kept from its first load while they fit (kWaterCacheBytes)
    BuildOptions build;
    detail::SourceTrace trace;          // the source, when the working raster is not the source itself
    std::vector<float> cellElevations;  // filled by the build when trace holds a source
};

Prepared prepare(const Options& opt, LoadReport& report) {
    Prepared p;
    p.terrain = detail::loadTerrainTraced(opt, report, &p.trace);
    if (p.terrain.validCount() == 0) {
        if (report.sourceValidPixels == 0) throw Error(opt.input + ": every pixel is nodata: nothing to ingest");
        const double w = double(p.terrain.width) * p.terrain.pixelSizeM,
                     h = double(p.terrain.height) * p.terrain.pixelSizeM;
        throw Error(opt.input + ": none of the " + std::to_string(p.terrain.width) + " x " +
                    std::to_string(p.terrain.height) + " working pixels of " + fmtM(p.terrain.pixelSizeM) +
                    " m has its centre on valid data (the raster covers about " + fmtM(w) + " x " + fmtM(h) +
                    " m, with " + std::to_string(report.sourceValidPixels) + " valid pixels)" +
                    (opt.minCellM ? ": choose a --min-cell well below the raster's size" : ""));
    }
    p.water.count = waterStepCount(opt);
    for (size_t k = 0; k < p.water.count; ++k) p.water.timesS.push_back(waterStepTimeS(opt, k));
    p.waterCache.resize(p.water.count);
    return p;
}

// The build reads each step twice (structure, then values): steps are kept between the two reads while all of them
// together stay under this, otherwise read (warped) again.
constexpr uint64_t kWaterCacheBytes = uint64_t{1} << 30;

// Sets p.water.load (p must not move afterwards).
void bindWater(Prepared& p, const Options& opt, LoadReport& report) {
    const bool cache = uint64_t(p.water.count) * p.terrain.values.size() * 4 <= kWaterCacheBytes;
    p.water.load = [&p, &opt, &report, cache](size_t k) {
        if (cache && !p.waterCache[k].values.empty()) return p.waterCache[k];
        Raster d = loadWater(opt, p.terrain, report, k);
        if (cache) p.waterCache[k] = d;
        return d;
    };
}

void setBuild(Prepared& p, const Options& opt, LoadReport& report) {
    p.build = buildOptions(opt, p.terrain.pixelSizeM, report);
}

void finishSourceCheck(const detail::SourceCheckSums& sums, LoadReport& report);

// Every valid source pixel against the cell covering its centre (LoadReport::sourceCheck): the
// figure a user means by "the grid differs from my survey by at most ...", and the count of source
// pixels that reached no cell (lost at a projection's edge, a split, a hole's resampled edge).
void checkAgainstSource(const detail::SourceTrace& trace, const Raster& working, const std::vector<float>& cellZ,
                        unsigned threads, LoadReport& report) {
    const detail::SourceBand& src = trace.band;
    struct Acc {
        detail::SourceCheckSums sums;
        std::vector<double> x, y;
        std::vector<int> ok;
    };
    std::vector<Acc> acc(trace.rowToWorldThreadSafe ? resolveThreads(threads) : 1);
    parallelFor(src.height, 16, trace.rowToWorldThreadSafe ? threads : 1,
                [&](size_t begin, size_t end, unsigned worker) {
                    Acc& a = acc[worker];
                    a.x.resize(src.width), a.y.resize(src.width), a.ok.resize(src.width);
                    for (size_t row = begin; row < end; ++row) {
                        trace.rowToWorld(row, a.x, a.y, a.ok);
                        for (size_t c = 0; c < src.width; ++c) {
                            const size_t i = row * src.width + c;
                            if (std::isnan(src.values[i])) continue;
                            const int64_t at = detail::workingPixelAt(working, a.x[c], a.y[c], a.ok[c]);
                            a.sums.addPixel(src.exact(i), at < 0 ? NAN : cellZ[size_t(at)]);
                        }
                    }
                });
    detail::SourceCheckSums sums;
    for (const Acc& a : acc) sums.add(a.sums);
    finishSourceCheck(sums, report);
}

// The check's figures from its sums (one process's workers, or every rank's strips added), and the warning when
// data was lost.
void finishSourceCheck(const detail::SourceCheckSums& sums, LoadReport& report) {
    LoadReport::SourceCheck& out = report.sourceCheck;
    out = {};
    out.done = true;
    out.checked = sums.checked;
    out.missed = sums.missed;
    out.maxDevM = sums.maxDev;
    out.rmsDevM = out.checked ? std::sqrt(sums.sumSq / double(out.checked)) : 0.0;
    const uint64_t valid = out.checked + out.missed;
    // Resampling loses a few pixels at the edges of holes and of the raster; more is lost data.
    if (valid > 0 && double(out.missed) > 0.005 * double(valid))
        report.warnings.push_back(
            std::to_string(out.missed) + " of " + std::to_string(valid) + " valid source pixels (" +
            fmtM(100.0 * double(out.missed) / double(valid)) +
            " %) reached no cell: their centre falls outside the grid or on a hole of the working raster");
}

// The build's own figure, said plainly when float32 storage cannot hold the tolerance.
// `rounded`: float32 lost part of some source values (Raster::roundingM).
void noteStorage(const IngestStats& s, bool rounded, LoadReport& report) {
    if (s.maxDevM > s.toleranceM && rounded)
        report.warnings.push_back("cells differ from the source's own (Float64 or integer) values by up to " +
                                  fmtM(s.maxDevM) + " m, more than --tolerance " + fmtM(s.toleranceM) +
                                  " m: the grid stores float32, which cannot hold these values closer");
}

// Where the working raster is not the source itself, the build records the cell elevation over each pixel,
// for the check against the source after it (p must not move between this and afterBuild).
void traceBuild(Prepared& p) {
    if (!p.trace.band.values.empty()) p.build.cellElevations = &p.cellElevations;
}

// What is checked once the grid is built: the source pixels against their cells, the tolerance in float32.
void afterBuild(const Prepared& p, const IngestStats& stats, const Options& opt, LoadReport& report) {
    if (p.build.cellElevations) checkAgainstSource(p.trace, p.terrain, p.cellElevations, opt.threads, report);
    noteStorage(stats, !p.terrain.roundingM.empty(), report);
}

}  // namespace

Grid ingest(const Options& opt, LoadReport& report) {
    const Stopwatch clock;
    if (!opt.waterMesh.empty()) throw Error("--water-mesh needs ingestToFile (hc-ingest)");
    if (waterStepCount(opt) > 1)
        throw Error("an in-memory grid holds one water step; " + std::to_string(waterStepCount(opt)) +
                    " need ingestToFile (hc-ingest)");
    Prepared p = prepare(opt, report);
    setBuild(p, opt, report);
    traceBuild(p);
    Raster water;
    if (p.water.count) water = loadWater(opt, p.terrain, report, 0);
    Grid g = buildGrid(p.terrain, p.water.count ? &water : nullptr, p.build);
    afterBuild(p, g.stats, opt, report);
    g.stats.sourcePath = opt.input;
    g.stats.sourceCrsName = report.sourceCrsName;
    g.stats.seconds = clock.seconds();
    return g;
}

namespace {

// Every rank's check against the source (its share of the source's rows), added in rank order (collective).
detail::SourceCheckSums allRanksCheck(const detail::SourceCheckSums& mine) {
    const std::vector<double> row{double(mine.checked), double(mine.missed), mine.maxDev, mine.sumSq};
    detail::SourceCheckSums sums;
    for (const auto& r : ranks::allGatherVectors(row)) {
        if (r.size() != 4) throw Error("a rank sent no source check");
        sums.add({uint64_t(r[0]), uint64_t(r[1]), r[2], r[3]});
    }
    return sums;
}

// Under mpirun, a terrain and its water steps read window by window: every rank reads only the windows of its share
// (buildGridFile over RasterWindows), each step's raster warped onto the same windows (or a level's bathtub flooded
// over them by the builder), the readers' counts are added over the ranks, and rank 0 reports them. In one process, a
// terrain without water larger than heldPixelsMax (RasterWindows): the same, the windows read in pieces.
BuildSummary ingestByWindows(const Options& opt, std::unique_ptr<detail::TerrainWindows> windows,
                             uint64_t heldPixelsMax, const std::string& path, LoadReport& report,
                             const Stopwatch& clock) {
    RasterWindows w;
    w.shape = windows->shape();
    w.source = opt.input;
    w.heldPixelsMax = heldPixelsMax;
    w.read = [&](size_t c0, size_t r0, size_t width, size_t height, std::vector<float>& values,
                 std::vector<float>& rounding,
                 bool first) { windows->read(c0, r0, width, height, values, rounding, first); };
    w.checkHeld = [&](uint64_t valid) { windows->checkValid(valid); };
    // Water steps from rasters: each window of a step warped onto the working raster as the whole would be
    // (detail::WaterStepWarp), step by step (the builder reads every window of step k before step k + 1).
    const size_t stepCount = waterStepCount(opt);
    std::vector<uint64_t> negative(stepCount, 0);  // this rank's pixels of negative depth, per step (its first reads)
    std::unique_ptr<detail::WaterStepWarp> stepWarp;
    size_t warpStep = 0;
    for (size_t k = 0; k < stepCount; ++k) w.stepTimesS.push_back(waterStepTimeS(opt, k));
    if (opt.water == WaterSource::Level)  // bathtubs: flooded by the builder over the ranks' windows
        w.stepLevelsM = opt.waterLevelsM.empty() ? std::vector<double>{opt.waterLevelM} : opt.waterLevelsM;
    else if (stepCount > 0)
        w.readStep = [&](size_t k, size_t c0, size_t r0, size_t width, size_t height, const float* terrain,
                         std::vector<float>& depth, bool first) {
            if (!stepWarp || warpStep != k) {
                LoadReport again;  // the step's warnings once, from its first reads
                stepWarp = std::make_unique<detail::WaterStepWarp>(opt, w.shape, k, first ? report : again);
                warpStep = k;
            }
            depth.resize(width * height);
            uint64_t n = 0;
            stepWarp->depth(c0, r0, width, height, terrain, depth.data(), n);
            if (first) negative[k] += n;
        };
    const BuildOptions build = buildOptions(opt, w.shape.pixelSizeM, report);
    IngestStats extra;
    extra.sourcePath = opt.input;
    extra.sourceCrsName = report.sourceCrsName;
    extra.seconds = clock.seconds();
    // Together: rank 1 writes on after the others returned; a failure there must not leave them waiting below.
    BuildSummary b;
    ranks::together([&] { b = buildGridFile(w, build, path, extra); });
    // A resampled source: every rank checks its share of the source pixels against the cells under them (the same pass
    // over the source as its tally), from the file rank 0 just committed (together() above waited for it).
    std::optional<detail::SourceCheckSums> mine;
    const Stopwatch checking;
    ranks::together([&] { mine = windows->checkAgainst(path); });
    if (mine)
        ranks::log(
            "hc-ingest",
            fmt::format("{} source pixels of its rows checked against the cells under them (and counted), {:.3f} s",
                        mine->checked + mine->missed, checking.seconds()));
    // The whole raster's counts (valid pixels, +-inf, sentinels): every rank's windows added.
    detail::SourceTally all;
    for (const auto& t : ranks::allGatherVectors(std::vector<detail::SourceTally>{windows->tally()})) {
        if (t.size() != 1) throw Error("a rank sent no reading tally");
        all.add(t[0]);
    }
    windows->finish(all, report);
    const std::vector<std::vector<uint64_t>> negatives = ranks::allGatherVectors(negative);
    for (size_t k = 0; k < stepCount; ++k) {  // the steps' warnings, over every rank's pixels, as one process says them
        uint64_t n = 0;
        for (const auto& r : negatives) n += k < r.size() ? r[k] : 0;
        if (n > 0) report.warnings.push_back(detail::negativeDepthWarning(detail::waterStepName(opt, k), n));
    }
    if (mine)
        finishSourceCheck(allRanksCheck(*mine),
                          report);  // its report (and warning) after the reading's, as in one process
    if (ranks::rank() == 0) noteStorage(b.shape.stats, report.sourcePrecisionDouble, report);
    return b;
}

// One process: the window reader of a terrain without water whose working raster exceeds Options::rasterMemoryMB (as
// float32; each window then read twice), else none (the raster held whole). The source's size decides whether the
// working raster's is looked at (opening its reader settles the georeferencing): a resampled raster holds at most a few
// times the source's pixels (square pixels of the smaller side, at high latitudes).
std::unique_ptr<detail::TerrainWindows> windowsOverMemory(const Options& opt, uint64_t heldPixelsMax,
                                                          LoadReport& report) {
    if (!opt.waterMesh.empty() || waterStepCount(opt) > 0) return nullptr;  // pieces take no water (Builder::piecesOf)
    {
        const detail::DatasetPtr ds = detail::openRaster(opt.input, "terrain");
        if (uint64_t(ds->GetRasterXSize()) * uint64_t(ds->GetRasterYSize()) * 8 <= heldPixelsMax) return nullptr;
    }
    LoadReport opened = report;
    std::unique_ptr<detail::TerrainWindows> w = detail::openTerrainWindows(opt, opened);
    if (uint64_t(w->shape().width) * w->shape().height <= heldPixelsMax) return nullptr;
    report = std::move(opened);
    return w;
}

}  // namespace

uint64_t heldPixelsMax(const Options& opt) {
    const double mb = opt.rasterMemoryMB > 0 ? opt.rasterMemoryMB : kDefaultRasterMemoryMB;
    return uint64_t(std::max(1.0, mb * 1e6 / sizeof(float)));
}

BuildSummary ingestToFile(const Options& opt, const std::string& path, LoadReport& report) {
    const Stopwatch clock;
    if (ranks::distributed() && !opt.waterMesh.empty())
        throw Error("--water-mesh runs in one process: run hc-ingest without mpirun");
    if (ranks::distributed())  // each rank its own windows
        return ingestByWindows(opt, detail::openTerrainWindows(opt, report), 0, path, report, clock);
    if (std::unique_ptr<detail::TerrainWindows> w = windowsOverMemory(opt, heldPixelsMax(opt), report)) {
        report.heldInPieces = true;
        return ingestByWindows(opt, std::move(w), heldPixelsMax(opt), path, report, clock);
    }
    Prepared p = prepare(opt, report);
    setBuild(p, opt, report);
    if (opt.waterMesh.empty())
        bindWater(p, opt, report);
    else
        p.water = detail::meshWaterSteps(opt, p.terrain, report);
    traceBuild(p);
    IngestStats extra;
    extra.sourcePath = opt.input;
    extra.sourceCrsName = report.sourceCrsName;
    extra.seconds = clock.seconds();
    BuildSummary b = buildGridFile(p.terrain, p.water.count ? &p.water : nullptr, p.build, path, extra);
    afterBuild(p, b.shape.stats, opt, report);
    return b;
}

}  // namespace hc::ingest
