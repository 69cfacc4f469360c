#include "heightcast/ingest/ingest.h"

#include <chrono>
#include <cmath>

#include "heightcast/grid/error.h"
#include "heightcast/ingest/build.h"

namespace hc::ingest {

int chooseMaxLevel(const Options& opt, double pixelSizeM, LoadReport&) {
    const double target = opt.maxCellM ? *opt.maxCellM : 96.0;  // the report's coarsest cell
    if (opt.maxCellM && *opt.maxCellM < pixelSizeM * (1 - 1e-9))
        throw Error("--max-cell " + std::to_string(*opt.maxCellM) + " m is smaller than the finest cell (" +
                    std::to_string(pixelSizeM) + " m)");
    int level = 0;
    while (pixelSizeM * std::ldexp(1.0, level + 1) <= target * (1 + 1e-9) && level < kMaxLevel) ++level;
    return level;
}

Grid ingest(const Options& opt, LoadReport& report) {
    auto start = std::chrono::steady_clock::now();
    Raster terrain = loadTerrain(opt, report);
    if (terrain.validCount() == 0) throw Error(opt.input + ": every pixel is nodata: nothing to ingest");
    Raster water;
    bool hasWater = opt.water != WaterSource::None;
    if (hasWater) water = loadWater(opt, terrain, report);
    BuildOptions b;
    b.toleranceM = opt.toleranceM;
    b.maxLevel = chooseMaxLevel(opt, terrain.pixelSizeM, report);
    b.threads = opt.threads;
    b.progress = opt.progress;
    Grid g = buildGrid(terrain, hasWater ? &water : nullptr, b);
    g.stats.sourcePath = opt.input;
    g.stats.sourceCrsName = report.sourceCrsName;
    g.stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return g;
}

}  // namespace hc::ingest
