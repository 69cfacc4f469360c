// bench/bench_influence_accuracy.cpp: hc-bench-influence's table 3 (bench_influence.h): how much error the smooth
// surface adds to the grid it smooths, against every valid pixel of the working raster the grid was built from.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "bench_influence.h"
#include "svg_plot.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/timer.h"
#include "heightcast/influence/influence.h"
#include "heightcast/influence/surface.h"
#include "heightcast/ingest/ingest.h"

namespace hc::bench::influence {

namespace {

namespace fs = std::filesystem;
using hc::Grid;
using hc::influence::InfluenceLists;
using hc::influence::KernelParams;
using hc::influence::SurfaceEvaluator;

struct AccuracyRow {
    std::string dem, path;  // file name, path as given
    size_t width = 0, height = 0;
    double pixelM = 0, toleranceM = 0, sigma = 0, maxCellM = 0;
    uint64_t validPx = 0, cells = 0, evaluated = 0, undefined = 0;
    bool sampled = false;
    std::string levels;
    double gridRms = 0, gridMax = 0, surfRms = 0, surfMax = 0;
    double checkRms = 0, checkMax = 0;  // covering cell - pixel over the evaluated pixels
    double entriesMean = 0, buildS = 0, evalS = 0;
};

// Evaluates the surface at the centre of each listed pixel of `raster` (the grid's working raster, so
// the grid's local frame has its origin at the raster's south-west corner) and compares with the pixel.
double evaluatePixels(const SurfaceEvaluator& ev, const hc::ingest::Raster& raster, const std::vector<uint32_t>& pixels,
                      unsigned threads, Accum& out) {
    const Grid& g = ev.grid();
    const hc::influence::Layer elevation{};
    std::vector<Accum> parts(hc::resolveThreads(threads));
    const hc::Stopwatch clock;
    hc::parallelFor(pixels.size(), 4096, threads, [&](size_t b, size_t e, unsigned w) {
        Accum& a = parts[w];
        for (size_t i = b; i < e; ++i) {
            const size_t col = pixels[i] % raster.width, row = pixels[i] / raster.width;
            const double x = (static_cast<double>(col) + 0.5) * raster.pixelSizeM;
            const double y = (static_cast<double>(raster.height - row) - 0.5) * raster.pixelSizeM;
            const double z = raster.values[pixels[i]];
            auto v = ev.value(x, y, elevation);
            if (!v) {
                ++a.undefined;  // a valid pixel outside every cell: a library bug, reported below
                continue;
            }
            ++a.defined;
            a.sum += *v;
            const double d = *v - z;
            a.sumSq += d * d;
            a.maxAbs = std::max(a.maxAbs, std::abs(d));
            if (auto k = g.locate(x, y)) {
                const double dg = static_cast<double>(g.values[0][*k]) - z;
                a.gridSumSq += dg * dg;
                a.gridMaxAbs = std::max(a.gridMaxAbs, std::abs(dg));
            }
        }
    });
    const double s = clock.seconds();
    out = reduce(parts);
    return s;
}

// The rows: every DEM at every tolerance and sigma; missing DEMs into `skipped`, oddities into `warnings`.
std::vector<AccuracyRow> measure(const AccuracyOptions& opt, std::vector<std::string>& skipped,
                                 std::vector<std::string>& warnings) {
    const std::vector<double>& tols = opt.tolerances;
    const std::vector<double>& sigmaList = opt.sigmas;
    const double maxCellM = opt.maxCellM;
    const int maxEvalPx = opt.maxEvalPx;
    const unsigned threads = opt.threads;
    std::vector<AccuracyRow> acc;
    for (const std::string& dem : opt.dems) {
        if (!fs::is_regular_file(dem)) {
            skipped.push_back(dem);
            continue;
        }
        try {
            hc::ingest::Options o;
            o.input = dem;
            o.maxCellM = maxCellM;
            o.threads = threads;
            hc::ingest::LoadReport rep;
            const hc::ingest::Raster raster = hc::ingest::loadTerrain(o, rep);
            const uint64_t valid = raster.validCount();
            // The pixels to evaluate: every valid one, or a fixed sample of 1 M of them (kept in raster order).
            std::vector<uint32_t> pixels;
            pixels.reserve(valid);
            for (size_t i = 0; i < raster.values.size(); ++i)
                if (!std::isnan(raster.values[i])) pixels.push_back(static_cast<uint32_t>(i));
            const bool sampled = valid > static_cast<uint64_t>(maxEvalPx);
            if (sampled) {
                std::mt19937_64 rng(7);
                const size_t m = std::min<size_t>(1000000, static_cast<size_t>(maxEvalPx));
                for (size_t i = 0; i < m; ++i) std::swap(pixels[i], pixels[i + rng() % (pixels.size() - i)]);
                pixels.resize(m);
                std::sort(pixels.begin(), pixels.end());
            }
            const std::string name = fs::path(dem).filename().string();
            for (double tol : tols) {
                o.toleranceM = tol;
                hc::ingest::LoadReport gridReport;
                const Grid g = hc::ingest::ingest(o, gridReport);
                if (g.stats.sourceWidth != raster.width || g.stats.sourceHeight != raster.height ||
                    g.stats.validPixels != valid)
                    throw hc::Error(dem + ": the grid's working raster (" +
                                    fmt::format("{} x {}", g.stats.sourceWidth, g.stats.sourceHeight) +
                                    ") is not the one loadTerrain gave: the comparison would be meaningless");
                for (double sigma : sigmaList) {
                    KernelParams params;
                    params.sigma = sigma;
                    AccuracyRow r;
                    r.dem = name;
                    r.path = dem;
                    r.width = raster.width;
                    r.height = raster.height;
                    r.pixelM = raster.pixelSizeM;
                    r.toleranceM = tol;
                    r.sigma = sigma;
                    r.maxCellM = g.levelSizeM(g.maxLevel);
                    r.validPx = valid;
                    r.cells = g.cellCount();
                    r.levels = levelRange(g);
                    r.gridRms = g.stats.rmsDevM;
                    r.gridMax = g.stats.maxDevM;
                    r.sampled = sampled;
                    const hc::Stopwatch clock;
                    const InfluenceLists lists = hc::influence::buildInfluenceLists(g, params, threads, false);
                    r.buildS = clock.seconds();
                    r.entriesMean = lists.stats().meanLength;
                    SurfaceEvaluator ev(g, lists);
                    Accum a;
                    r.evalS = evaluatePixels(ev, raster, pixels, threads, a);
                    r.evaluated = a.defined;
                    r.undefined = a.undefined;
                    const double n = static_cast<double>(std::max<uint64_t>(a.defined, 1));
                    r.surfRms = std::sqrt(a.sumSq / n);
                    r.surfMax = a.maxAbs;
                    r.checkRms = std::sqrt(a.gridSumSq / n);
                    r.checkMax = a.gridMaxAbs;
                    if (a.undefined)
                        warnings.push_back(
                            fmt::format("{} tol {:g} sigma {:g}: the surface is undefined at {} valid pixel centres",
                                        name, tol, sigma, a.undefined));
                    // Our own pixel-by-pixel grid error must match the ingest's (same pixels, same cells).
                    if (!sampled &&
                        (std::abs(r.checkMax - r.gridMax) > 1e-4 || std::abs(r.checkRms - r.gridRms) > 1e-4))
                        warnings.push_back(
                            fmt::format("{} tol {:g}: grid error measured here (RMS {:.5f}, max {:.5f}) differs from "
                                        "Grid::stats (RMS {:.5f}, max {:.5f})",
                                        name, tol, r.checkRms, r.checkMax, r.gridRms, r.gridMax));
                    acc.push_back(r);
                }
            }
        } catch (const std::exception& e) {
            throw hc::Error(std::string("table 3, ") + dem + ": " + e.what());
        }
    }
    return acc;
}

// The table, its notes and its CSV rows.
void print(const std::vector<AccuracyRow>& acc, const AccuracyOptions& opt, Csv& out) {
    const int maxEvalPx = opt.maxEvalPx;
    std::printf(
        "\n3. speed / accuracy: every valid working-raster pixel (the raster the grid was built from) is compared "
        "with\n"
        "the grid (the ingest's own measurement, Grid::stats) and with the smooth surface at its centre; R %g; "
        "every\n"
        "ingest with max cell %g m (max cell = the coarsest level it allowed, capped by the raster's size); "
        "cells/px =\n"
        "cells per valid pixel; entries = mean list length; lists ms = buildInfluenceLists; eval ms = all %u "
        "threads\n"
        "over the evaluated pixels; RMS / max in metres\n\n",
        opt.truncation, opt.maxCellM, opt.allThreads);
    std::printf("%-28s %9s %6s %5s %5s %6s %8s %6s %7s %7s %7s %7s %7s %8s %8s %7s\n", "dem", "px", "px m", "tol",
                "sigma", "max m", "cells", "cells/px", "grd RMS", "grd max", "srf RMS", "srf max", "entries",
                "lists ms", "eval ms", "M px/s");
    for (const AccuracyRow& r : acc) {
        const double rate = static_cast<double>(r.evaluated) / r.evalS / 1e6;
        std::printf("%-28s %9s %6.3g %5.3g %5.3g %6.4g %8llu %6.3f %7.4f %7.4f %7.4f %7.4f %7.1f %8.1f %8.1f %7.2f%s\n",
                    r.dem.c_str(), fmt::format("{}x{}", r.width, r.height).c_str(), r.pixelM, r.toleranceM, r.sigma,
                    r.maxCellM, (unsigned long long)r.cells,
                    static_cast<double>(r.cells) / static_cast<double>(r.validPx), r.gridRms, r.gridMax, r.surfRms,
                    r.surfMax, r.entriesMean, r.buildS * 1e3, r.evalS * 1e3, rate, r.sampled ? " (sample)" : "");
        out.add({{"table", "accuracy"},
                 {"grid", r.dem},
                 {"source", r.path},
                 {"tolerance_m", fmt::format("{:g}", r.toleranceM)},
                 {"sigma", fmt::format("{:g}", r.sigma)},
                 {"truncation", fmt::format("{:g}", opt.truncation)},
                 {"max_cell_m", fmt::format("{:g}", r.maxCellM)},
                 {"threads", fmt::format("{}", opt.allThreads)},
                 {"working_px", fmt::format("{}x{}", r.width, r.height)},
                 {"pixel_m", fmt::format("{:.6g}", r.pixelM)},
                 {"valid_px", fmt::format("{}", r.validPx)},
                 {"cells", fmt::format("{}", r.cells)},
                 {"cells_per_valid_px",
                  fmt::format("{:.5f}", static_cast<double>(r.cells) / static_cast<double>(r.validPx))},
                 {"min_cell_m", fmt::format("{:.6g}", r.pixelM)},
                 {"coarsest_cell_m", r.levels.substr(r.levels.find("..") + 2)},
                 {"build_ms", fmt::format("{:.3f}", r.buildS * 1e3)},
                 {"entries_mean", fmt::format("{:.3f}", r.entriesMean)},
                 {"points", fmt::format("{}", r.evaluated)},
                 {"eval_ms", fmt::format("{:.3f}", r.evalS * 1e3)},
                 {"m_points_per_s", fmt::format("{:.4f}", rate)},
                 {"grid_rms_m", fmt::format("{:.6g}", r.gridRms)},
                 {"grid_max_m", fmt::format("{:.6g}", r.gridMax)},
                 {"surface_rms_m", fmt::format("{:.6g}", r.surfRms)},
                 {"surface_max_m", fmt::format("{:.6g}", r.surfMax)},
                 {"sampled", r.sampled ? "1" : "0"}});
    }
    bool anySampled = false;
    for (const AccuracyRow& r : acc) anySampled |= r.sampled;
    if (anySampled)
        std::printf("(sample): more than %d valid pixels: errors and time over a fixed random sample of %d of them\n",
                    maxEvalPx, std::min(maxEvalPx, 1000000));
}

// Table 3 plotted: RMS error against the tolerance, per DEM, the grid dotted and the surface per sigma.
void plotAccuracy(const std::vector<AccuracyRow>& acc, const std::vector<double>& sigmaList, const std::string& plot) {
    // One colour per DEM; the grid's error dotted, the surface's solid for the first sigma, then dashed.
    hc::bench::LinePlot lp;
    lp.title = "Speed against accuracy: RMS error against the source raster (table 3)";
    lp.xLabel = "ingest tolerance [m]";
    lp.yLabel = "RMS error against every valid source pixel [m]";
    lp.logX = lp.logY = true;
    std::vector<std::string> demOrder;
    for (const AccuracyRow& r : acc)
        if (std::find(demOrder.begin(), demOrder.end(), r.dem) == demOrder.end()) demOrder.push_back(r.dem);
    const char* dashes[] = {"", "8,4", "12,3,2,3", "4,2"};
    for (size_t d = 0; d < demOrder.size(); ++d) {
        const std::string color = hc::bench::plotColor(d);
        const std::string name = fs::path(demOrder[d]).stem().string();
        hc::bench::LineSeries grid{name + ": grid (cells)", color, "1,3", {}};
        for (const AccuracyRow& r : acc)
            if (r.dem == demOrder[d] && r.sigma == sigmaList.front()) grid.points.emplace_back(r.toleranceM, r.gridRms);
        lp.series.push_back(grid);
        for (size_t k = 0; k < sigmaList.size(); ++k) {
            hc::bench::LineSeries surf{name + ": smooth surface, sigma " + fmt::format("{:g}", sigmaList[k]),
                                       color,
                                       dashes[std::min<size_t>(k, 3)],
                                       {}};
            for (const AccuracyRow& r : acc)
                if (r.dem == demOrder[d] && r.sigma == sigmaList[k]) surf.points.emplace_back(r.toleranceM, r.surfRms);
            lp.series.push_back(surf);
        }
    }
    hc::bench::writeSvg(plot, lp.svg());
    std::printf("plot written to %s\n", plot.c_str());
}

}  // namespace

void accuracyTable(const AccuracyOptions& o, Csv& out, const std::string& plot) {
    std::vector<std::string> skipped, warnings;
    const std::vector<AccuracyRow> acc = measure(o, skipped, warnings);
    print(acc, o, out);
    for (const std::string& s : skipped) std::printf("skipped %s: missing\n", s.c_str());
    for (const std::string& w : warnings) std::printf("warning: %s\n", w.c_str());
    if (!plot.empty() && !acc.empty()) plotAccuracy(acc, o.sigmas, plot);
}

}  // namespace hc::bench::influence
