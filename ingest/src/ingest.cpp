#include "heightcast/ingest/ingest.h"

#include <chrono>
#include <cmath>
#include <cstdio>

#include "heightcast/grid/error.h"
#include "heightcast/ingest/build.h"

namespace hc::ingest {

namespace {
std::string fmtM(double v) {
    char b[32];
    std::snprintf(b, sizeof b, "%.6g", v);
    return b;
}
}  // namespace

int chooseMaxLevel(const Options& opt, double pixelSizeM, LoadReport&) {
    const double target = opt.maxCellM ? *opt.maxCellM : 96.0;  // the report's coarsest cell
    if (opt.maxCellM && *opt.maxCellM < pixelSizeM * (1 - 1e-9))
        throw Error("--max-cell " + fmtM(*opt.maxCellM) + " m is smaller than the finest cell (" + fmtM(pixelSizeM) + " m)");
    int level = 0;
    while (pixelSizeM * std::ldexp(1.0, level + 1) <= target * (1 + 1e-9) && level < kMaxLevel) ++level;
    return level;
}

namespace {

// Loads terrain (and water) and chooses the build options: the shared first half of both jobs.
struct Prepared {
    Raster terrain, water;
    bool hasWater = false;
    BuildOptions build;
};

Prepared prepare(const Options& opt, LoadReport& report) {
    Prepared p;
    p.terrain = loadTerrain(opt, report);
    if (p.terrain.validCount() == 0) throw Error(opt.input + ": every pixel is nodata: nothing to ingest");
    p.hasWater = opt.water != WaterSource::None;
    if (p.hasWater) p.water = loadWater(opt, p.terrain, report);
    p.build.toleranceM = opt.toleranceM;
    p.build.maxLevel = chooseMaxLevel(opt, p.terrain.pixelSizeM, report);
    p.build.threads = opt.threads;
    p.build.progress = opt.progress;
    return p;
}

double secondsSince(std::chrono::steady_clock::time_point t) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

}  // namespace

Grid ingest(const Options& opt, LoadReport& report) {
    auto start = std::chrono::steady_clock::now();
    Prepared p = prepare(opt, report);
    Grid g = buildGrid(p.terrain, p.hasWater ? &p.water : nullptr, p.build);
    g.stats.sourcePath = opt.input;
    g.stats.sourceCrsName = report.sourceCrsName;
    g.stats.seconds = secondsSince(start);
    return g;
}

BuildSummary ingestToFile(const Options& opt, const std::string& path, LoadReport& report) {
    auto start = std::chrono::steady_clock::now();
    Prepared p = prepare(opt, report);
    IngestStats extra;
    extra.sourcePath = opt.input;
    extra.sourceCrsName = report.sourceCrsName;
    extra.seconds = secondsSince(start);
    return buildGridFile(p.terrain, p.hasWater ? &p.water : nullptr, p.build, path, extra);
}

}  // namespace hc::ingest
