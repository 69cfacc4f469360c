// hc-bench-influence: how fast are influence lists built and the smooth surface evaluated, and how much
// error does the smooth surface add to the grid it smooths?
//
// Three tables:
//   1 build       buildInfluenceLists (sigma 1, R 3.5, all cores, best of --repeat) on N00E010.hgt ingested
//                 at tolerances 0.5 and 2 m with --max-cell (default 768 m, so cells merge; SRTM's default
//                 96 m coarsest cell is one pixel), and on a synthetic grid whose cell sizes span a ratio of
//                 128 (0.75 m .. 96 m): the hard case for a candidate search, where a 96 m cell's disk
//                 (336 m) covers thousands of fine cells and a fine cell's list holds dozens of coarse ones.
//                 Target (issue 3): >= 2 M cells/s on 2 cores.
//   2 evaluate    SurfaceEvaluator::value at 1 M points drawn uniformly (in random order, so no cache
//                 locality helps) over the grid's bounding box, one thread and all threads. Only points where
//                 the surface is defined count in the rate (the rest cost one failed locate each).
//                 Target: >= 1 M points/s on 2 cores.
//   3 accuracy    real DEMs x tolerances x sigmas: the grid's error against its working raster (the ingest's
//                 own measurement, Grid::stats) next to the smooth surface's error, evaluated at every valid
//                 pixel centre of the same working raster (loadTerrain with the same options). The surface
//                 interpolates cell values with a Gaussian of sigma cell sizes, so it can only add error
//                 where the grid is exact (it blurs) and remove some where the grid steps: this shows which.
// Why a program and not a test: the figures depend on the machine; tests never time anything.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>
#include <optional>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "bench_common.h"
#include "bench_influence.h"
#include "svg_plot.h"
#include "heightcast/support/cli.h"
#include "heightcast/core/error.h"
#include "heightcast/grid/morton.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/timer.h"
#include "heightcast/influence/influence.h"
#include "heightcast/influence/surface.h"
#include "heightcast/ingest/build.h"
#include "heightcast/ingest/ingest.h"

namespace fs = std::filesystem;
using hc::Grid;
using hc::influence::InfluenceLists;
using hc::influence::KernelParams;
using hc::influence::SurfaceEvaluator;

namespace {

using namespace hc::bench;
using namespace hc::bench::influence;

// Targets of issue 3 (2 cores).
constexpr double kTargetBuildMCellsPerS = 2.0;  // influence lists built per second
constexpr double kTargetEvalMPointsPerS = 1.0;  // defined surface points evaluated per second, all threads
// Table 1's N00E010 tolerances [m].
constexpr double kBuildTolerances[] = {0.5, 2.0};
// The synthetic grid: 2048 x 2048 pixels of 0.75 m, merged up to level 7 (96 m) at this tolerance.
constexpr size_t kSynthSide = 2048;
constexpr double kSynthPixelM = 0.75;
constexpr int kSynthMaxLevel = 7;
constexpr double kSynthToleranceM = 0.5;

std::vector<double> numberList(const std::string& text, const std::string& what, double above) {
    std::vector<double> out;
    for (const std::string& t : splitList(text, what)) {
        out.push_back(hc::cli::parseNumber(t, what));
        if (!(out.back() >= above))
            throw hc::Error(what + " " + t + ": must be at least " + fmt::format("{:g}", above));
    }
    return out;
}

// ---- the synthetic ratio-128 grid ----

// 2048 x 2048 pixels of 0.75 m (1536 m square). Everywhere a smooth swell of +-1 m over the whole square
// (slope <= 0.0041, so a 96 m cell spans < 0.4 m and merges at 0.5 m tolerance); on top of it, in strips
// 16 pixels (12 m) wide ending at every multiple of 256 pixels, in x and in y, a +-1 m checkerboard
// that no merge can keep within 0.5 m. So the strips stay 0.75 m cells, the 128-pixel blocks they do not
// touch become 96 m cells, and the strips' east and north sides touch 96 m cells directly (ratio 128).
hc::ingest::Raster syntheticRaster() {
    hc::ingest::Raster r;
    r.width = r.height = kSynthSide;
    r.pixelSizeM = kSynthPixelM;
    r.westWorld = 0;
    r.northWorld = static_cast<double>(kSynthSide) * kSynthPixelM;
    r.values.resize(kSynthSide * kSynthSide);
    const double side = static_cast<double>(kSynthSide) * kSynthPixelM, k = 2.0 * std::numbers::pi / side;
    auto rough = [](size_t i) { return i % 256 >= 240; };  // the last 16 of every 256 pixels
    for (size_t row = 0; row < kSynthSide; ++row)
        for (size_t col = 0; col < kSynthSide; ++col) {
            const double x = (static_cast<double>(col) + 0.5) * kSynthPixelM,
                         y = side - (static_cast<double>(row) + 0.5) * kSynthPixelM;
            double z = 100.0 + std::sin(k * x) * std::cos(k * y);
            if (rough(col) || rough(row)) z += ((col + row) & 1) ? 1.0 : -1.0;
            r.at(col, row) = static_cast<float>(z);
        }
    return r;
}

// ---- evaluation ----

struct Point {
    double x, y;
};

// Evaluates every point on `threads` workers (1 = the calling thread alone); returns seconds.
double evaluatePoints(const SurfaceEvaluator& ev, const std::vector<Point>& pts, unsigned threads, Accum& out) {
    const hc::influence::Layer elevation{};
    std::vector<Accum> parts(hc::resolveThreads(threads));
    const hc::Stopwatch clock;
    hc::parallelFor(pts.size(), 4096, threads, [&](size_t b, size_t e, unsigned w) {
        Accum& a = parts[w];
        for (size_t i = b; i < e; ++i) {
            if (auto v = ev.value(pts[i].x, pts[i].y, elevation)) {
                ++a.defined;
                a.sum += *v;
            } else {
                ++a.undefined;
            }
        }
    });
    const double s = clock.seconds();
    out = reduce(parts);
    return s;
}

// ---- table 1 ----

struct BuildRow {
    std::string name, source;
    double toleranceM = 0;
    const Grid* grid = nullptr;
    double buildS = 1e300;
    InfluenceLists::Stats stats;
    double mCellsPerS() const { return static_cast<double>(grid->cellCount()) / buildS / 1e6; }
};

// Builds the lists `repeat` times; keeps the best time and the last lists.
InfluenceLists timeBuild(const Grid& g, const KernelParams& params, unsigned threads, int repeat, double& bestS) {
    InfluenceLists lists;
    bestS = 1e300;
    for (int k = 0; k < repeat; ++k) {
        lists = InfluenceLists();  // free the previous run's lists first: each run allocates from scratch
        const hc::Stopwatch clock;
        lists = hc::influence::buildInfluenceLists(g, params, threads, false);
        bestS = std::min(bestS, clock.seconds());
    }
    return lists;
}

}  // namespace

int main(int argc, char** argv) {
    return hc::cli::run("hc-bench-influence", [&] {
        std::string srtm = "../shared/data/N00E010.hgt";
        std::string dems =
            "data/lidar1m_minnesota_utm15.tif,data/south_glacier_utm7.tif,data/kootenai_1m.asc,data/hef_srtm.tif,"
            "../shared/data/N00E010.hgt";
        std::string tolerances = "0.1,0.5,2", sigmas = "0.5,1,1.5", csv, plot;
        double maxCellM = 768;
        int repeat = 3, points = 1000000, maxEvalPx = 2000000;
        unsigned threads = 0;
        bool quick = false;
        hc::cli::Parser p(
            "hc-bench-influence", "[options]",
            "Benchmarks the influence lists and the exact smooth surface (docs/design.md section 3).\n"
            "  1 build: buildInfluenceLists (sigma 1, R 3.5) on N00E010.hgt ingested at tolerances 0.5 and 2 m and\n"
            "    on a synthetic grid of cell sizes 0.75 .. 96 m (ratio 128); target >= 2 M cells/s on 2 cores.\n"
            "  2 evaluate: SurfaceEvaluator::value at uniform random points (defined ones counted), one thread\n"
            "    and all threads, on the N00E010 0.5 m grid and the synthetic grid; target >= 1 M points/s.\n"
            "  3 accuracy: real DEMs x tolerances x sigmas: grid-vs-source and smooth-surface-vs-source RMS and\n"
            "    max error at the working raster's valid pixel centres, entries per cell, evaluation time.\n"
            "Paths are relative to the current directory (run it from the repository root). MB = 10^6 bytes.");
        p.option("--srtm", "FILE",
                 "the SRTM tile for tables 1 and 2 (default ../shared/data/N00E010.hgt); rows are\n"
                 "      skipped, saying so, when it is missing",
                 srtm);
        p.option(
            "--dems", "LIST",
            "comma-separated rasters for table 3 (default data/lidar1m_minnesota_utm15.tif,\n"
            "      data/south_glacier_utm7.tif,data/kootenai_1m.asc,data/hef_srtm.tif,../shared/data/N00E010.hgt);\n"
            "      missing files are skipped, saying so",
            dems);
        p.option("--tolerances", "LIST",
                 "comma-separated ingest tolerances for table 3, metres >= 0 (default 0.1,0.5,2)", tolerances);
        p.option("--sigmas", "LIST",
                 "comma-separated kernel widths for table 3, in cell sizes; R stays 3.5 (default 0.5,1,1.5)", sigmas);
        p.option("--max-cell", "M",
                 "coarsest cell for every ingest, metres; rounded down to finest * 2^k (default 768, so\n"
                 "      SRTM's 90 m pixels can merge and the tolerance matters)",
                 maxCellM);
        p.option("--repeat", "N", "runs per timed case in tables 1 and 2; times are the best run (default 3)", repeat);
        p.option("--points", "N", "random points per evaluator case in table 2 (default 1000000)", points);
        p.option("--max-eval-px", "N",
                 "table 3 evaluates every valid pixel of rasters with at most N valid pixels, and a fixed\n"
                 "      random sample of min(N, 1000000) valid pixels of larger ones (default 2000000)",
                 maxEvalPx);
        p.option("--threads", "N",
                 "worker threads for building, ingest and the all-threads cases (default 0 = all cores)", threads);
        p.option("--csv", "OUT.csv",
                 "also write every row of every table as CSV, with a 'table' column (default: none)", csv);
        p.option("--plot", "OUT.svg",
                 "also draw table 3 as an SVG plot: RMS error against the source for each DEM over the\n"
                 "      tolerances, the grid's and the smooth surface's for each sigma (default: none)",
                 plot);
        p.flag("--quick",
               "smoke run: one tolerance (0.5 m, or the first of --tolerances), one sigma (1, or the first of\n"
               "      --sigmas), the first two DEMs, 100000 points (unless --points is given)",
               quick);
        if (!p.parse(argc, argv)) return 0;
        if (repeat < 1) throw hc::Error("--repeat " + std::to_string(repeat) + ": must be at least 1");
        if (points < 1) throw hc::Error("--points " + std::to_string(points) + ": must be at least 1");
        if (maxEvalPx < 1) throw hc::Error("--max-eval-px " + std::to_string(maxEvalPx) + ": must be at least 1");
        if (!(maxCellM > 0))
            throw hc::Error("--max-cell " + fmt::format("{:g}", maxCellM) + ": must be a positive size in metres");
        std::vector<double> tols = numberList(tolerances, "--tolerances", 0.0);
        std::vector<double> sigmaList = numberList(sigmas, "--sigmas", 1e-9);
        for (double s : sigmaList) {
            KernelParams k;
            k.sigma = s;
            if (std::string why = k.validate(); !why.empty())
                throw hc::Error("--sigmas " + fmt::format("{:g}", s) + ": " + why);
        }
        std::vector<std::string> demList = splitList(dems, "--dems");
        if (quick) {
            tols = {p.given("--tolerances") ? tols.front() : 0.5};
            sigmaList = {p.given("--sigmas") ? sigmaList.front() : 1.0};
            if (demList.size() > 2) demList.resize(2);
            if (!p.given("--points")) points = 100000;
        }
        if (!csv.empty()) hc::cli::checkWritable(csv, "--csv");
        if (!plot.empty()) hc::cli::checkWritable(plot, "--plot");
        const unsigned allThreads = hc::resolveThreads(threads);
        const KernelParams baseParams;  // sigma 1, R 3.5: the report's
        const bool haveSrtm = fs::is_regular_file(srtm);
        Csv out;

        std::printf("hc-bench-influence: %u worker thread%s (hardware threads: %u)%s\n", allThreads,
                    allThreads == 1 ? "" : "s", std::thread::hardware_concurrency(), quick ? ", --quick" : "");
        std::printf("load average (1 min) at start: %s\n", loadAverage().c_str());
        if (!haveSrtm)
            std::printf("note: %s is missing: the N00E010 rows of tables 1 and 2 are skipped\n", srtm.c_str());

        // ---------------- table 1: influence build ----------------
        std::vector<Grid> srtmGrids;  // kept for table 2
        std::vector<BuildRow> buildRows;
        hc::ingest::LoadReport report;
        if (haveSrtm)
            for (double tol : kBuildTolerances) {
                hc::ingest::Options o;
                o.input = srtm;
                o.toleranceM = tol;
                o.maxCellM = maxCellM;
                o.threads = threads;
                srtmGrids.push_back(hc::ingest::ingest(o, report));
            }
        const Grid synth = [&] {
            hc::ingest::BuildOptions b;
            b.toleranceM = kSynthToleranceM;
            b.maxLevel = kSynthMaxLevel;
            b.threads = threads;
            return hc::ingest::buildGrid(syntheticRaster(), nullptr, b);
        }();
        for (size_t i = 0; i < srtmGrids.size(); ++i)
            buildRows.push_back({.name = fmt::format("N00E010 tol {:g}", kBuildTolerances[i]),
                                 .source = srtm,
                                 .toleranceM = kBuildTolerances[i],
                                 .grid = &srtmGrids[i],
                                 .buildS = 1e300,
                                 .stats = {}});
        buildRows.push_back({.name = "ratio-128 synthetic",
                             .source = "synthetic 2048x2048 px of 0.75 m",
                             .toleranceM = kSynthToleranceM,
                             .grid = &synth,
                             .buildS = 1e300,
                             .stats = {}});

        std::vector<InfluenceLists> builtLists;  // sigma 1, per build row: reused by table 2
        builtLists.reserve(buildRows.size());
        for (BuildRow& r : buildRows) {
            builtLists.push_back(timeBuild(*r.grid, baseParams, threads, repeat, r.buildS));
            r.stats = builtLists.back().stats();
        }

        std::printf(
            "\n1. influence build: buildInfluenceLists, sigma %g, R %g, %u threads, best of %d; N00E010 ingested with\n"
            "max cell %g m (its coarsest level: %s); levels = smallest..largest cell present [m]; M cells/s = cells / "
            "best\n"
            "build time; entries = list length per cell (mean / p99 / max); MB = lists' offsets + indices\n\n",
            baseParams.sigma, baseParams.truncation, allThreads, repeat, maxCellM,
            srtmGrids.empty() ? "n/a"
                              : fmt::format("{:.4g} m", srtmGrids[0].levelSizeM(srtmGrids[0].maxLevel)).c_str());
        std::printf("%-20s %9s %13s %9s %9s %8s %6s %6s %8s %8s\n", "grid", "cells", "levels m", "build ms",
                    "M cells/s", "mean", "p99", "max", "MB", "target");
        for (const BuildRow& r : buildRows) {
            const bool met = r.mCellsPerS() >= kTargetBuildMCellsPerS;
            std::printf("%-20s %9zu %13s %9.1f %9.2f %8.1f %6llu %6llu %8.1f %8s\n", r.name.c_str(),
                        r.grid->cellCount(), levelRange(*r.grid).c_str(), r.buildS * 1e3, r.mCellsPerS(),
                        r.stats.meanLength, (unsigned long long)r.stats.p99Length,
                        (unsigned long long)r.stats.maxLength, static_cast<double>(r.stats.bytes) / 1e6,
                        met ? "met" : "MISSED");
            out.add({{"table", "build"},
                     {"grid", r.name},
                     {"source", r.source},
                     {"tolerance_m", fmt::format("{:g}", r.toleranceM)},
                     {"sigma", fmt::format("{:g}", baseParams.sigma)},
                     {"truncation", fmt::format("{:g}", baseParams.truncation)},
                     {"max_cell_m", fmt::format("{:g}", r.grid->levelSizeM(r.grid->maxLevel))},
                     {"threads", fmt::format("{}", allThreads)},
                     {"cells", fmt::format("{}", r.grid->cellCount())},
                     {"min_cell_m", fmt::format("{:g}", r.grid->finestCellM)},
                     {"coarsest_cell_m", levelRange(*r.grid).substr(levelRange(*r.grid).find("..") + 2)},
                     {"build_ms", fmt::format("{:.3f}", r.buildS * 1e3)},
                     {"m_cells_per_s", fmt::format("{:.4f}", r.mCellsPerS())},
                     {"entries_mean", fmt::format("{:.3f}", r.stats.meanLength)},
                     {"entries_p99", fmt::format("{}", r.stats.p99Length)},
                     {"entries_max", fmt::format("{}", r.stats.maxLength)},
                     {"lists_mb", fmt::format("{:.3f}", static_cast<double>(r.stats.bytes) / 1e6)},
                     {"target", met ? "met" : "MISSED"}});
        }
        {
            const auto per = synth.cellsPerLevel();
            std::string counts;
            for (size_t l = 0; l < per.size(); ++l)
                counts += fmt::format("{}{:.4g} m: {}", l ? ", " : "", synth.levelSizeM(static_cast<int>(l)), per[l]);
            std::printf("ratio-128 synthetic, cells per size: %s\n", counts.c_str());
        }
        std::printf("target: >= %.0f M cells/s on 2 cores (all cores here)\n", kTargetBuildMCellsPerS);

        // ---------------- table 2: evaluator ----------------
        std::printf(
            "\n2. evaluator: SurfaceEvaluator::value (elevation) at %d points, uniform over the grid's cell bounding "
            "box in\n"
            "random order; sigma %g, R %g; best of %d; defined = fraction of points inside a cell (the rest are holes\n"
            "and cost one failed locate each); M pts/s = defined points / time; order morton = the same points sorted\n"
            "into the grid's storage order (diagnostic: what cache locality is worth; the target is for random "
            "order)\n\n",
            points, baseParams.sigma, baseParams.truncation, repeat);
        std::printf("%-20s %-7s %7s %9s %7s %9s %9s %8s\n", "grid", "order", "threads", "points", "defined", "ms",
                    "M pts/s", "target");
        for (size_t gi = 0; gi < buildRows.size(); ++gi) {
            const BuildRow& r = buildRows[gi];
            if (r.grid != &synth && r.toleranceM != kBuildTolerances[0]) continue;  // N00E010: its 0.5 m grid only
            const Grid& g = *r.grid;
            SurfaceEvaluator ev(g, builtLists[gi]);
            double x0, y0, x1, y1;
            g.boundsLocal(x0, y0, x1, y1);
            std::mt19937_64 rng(20240611);  // fixed: the same points every run
            std::uniform_real_distribution<double> ux(x0, x1), uy(y0, y1);
            std::vector<Point> pts(static_cast<size_t>(points));
            for (Point& pt : pts) pt = {ux(rng), uy(rng)};
            // The same points in the grid's storage order (Morton order of the finest cell holding each): a
            // diagnostic for how much of the random-order time is cache misses, not arithmetic.
            std::vector<Point> sorted = pts;
            auto mortonOf = [&](const Point& q) {
                return hc::mortonEncode(static_cast<uint32_t>(q.x / g.finestCellM),
                                        static_cast<uint32_t>(q.y / g.finestCellM));
            };
            std::sort(sorted.begin(), sorted.end(),
                      [&](const Point& a, const Point& b) { return mortonOf(a) < mortonOf(b); });
            const std::vector<unsigned> threadCounts =
                allThreads == 1 ? std::vector<unsigned>{1} : std::vector<unsigned>{1, allThreads};
            // batch = SurfaceEvaluator::values() on the random points: it sorts them by cell itself (hc-probe's path).
            std::vector<std::array<double, 2>> asArrays(pts.size());
            for (size_t i = 0; i < pts.size(); ++i) asArrays[i] = {pts[i].x, pts[i].y};
            for (const char* order : {"random", "morton", "batch"}) {
                const std::vector<Point>& set = order[0] == 'm' ? sorted : pts;
                for (unsigned t : threadCounts) {
                    double best = 1e300;
                    Accum a;
                    for (int k = 0; k < repeat; ++k) {
                        if (order[0] != 'b') {
                            best = std::min(best, evaluatePoints(ev, set, t, a));
                            continue;
                        }
                        const hc::Stopwatch clock;
                        const auto vals = ev.values(asArrays, hc::influence::Layer{}, t);
                        best = std::min(best, clock.seconds());
                        a = Accum{};
                        for (const auto& v : vals) a.defined += v.has_value();
                    }
                    const double rate = static_cast<double>(a.defined) / best / 1e6;
                    const double fraction = static_cast<double>(a.defined) / static_cast<double>(set.size());
                    // The target: random input on all cores, through the per-point call or the batch call.
                    const bool counts = t == allThreads && order[0] != 'm';
                    const char* target = counts ? (rate >= kTargetEvalMPointsPerS ? "met" : "MISSED") : "-";
                    std::printf("%-20s %-7s %7u %9zu %7.3f %9.1f %9.2f %8s\n", r.name.c_str(), order, t, set.size(),
                                fraction, best * 1e3, rate, target);
                    out.add({{"table", "evaluate"},
                             {"grid", r.name},
                             {"source", r.source},
                             {"tolerance_m", fmt::format("{:g}", r.toleranceM)},
                             {"order", order},
                             {"sigma", fmt::format("{:g}", baseParams.sigma)},
                             {"truncation", fmt::format("{:g}", baseParams.truncation)},
                             {"threads", fmt::format("{}", t)},
                             {"cells", fmt::format("{}", g.cellCount())},
                             {"points", fmt::format("{}", set.size())},
                             {"defined_fraction", fmt::format("{:.5f}", fraction)},
                             {"eval_ms", fmt::format("{:.3f}", best * 1e3)},
                             {"m_points_per_s", fmt::format("{:.4f}", rate)},
                             {"target", counts ? target : ""}});
                }
            }
        }
        std::printf("target: >= %.0f M points/s on 2 cores (all threads)\n", kTargetEvalMPointsPerS);
        srtmGrids.clear();
        builtLists.clear();

        // ---------------- table 3: accuracy ----------------
        AccuracyOptions acc;
        acc.dems = demList, acc.tolerances = tols, acc.sigmas = sigmaList;
        acc.maxCellM = maxCellM, acc.truncation = baseParams.truncation, acc.maxEvalPx = maxEvalPx;
        acc.threads = threads, acc.allThreads = allThreads;
        accuracyTable(acc, out, plot);

        std::printf("\nload average (1 min) at the end: %s\n", loadAverage().c_str());
        if (!csv.empty()) {
            out.write(csv);
            std::printf("\nrows written to %s\n", csv.c_str());
        }
        return 0;
    });
}
