// hc-bench: how fast does the CPU renderer draw the report's four flood scenes, and in how much memory?
//
// The scenes are the report's four flood simulations as synthetic stand-ins with the same extents, cell sizes
// and cell counts, generated deterministically by hc_scenes (bench/scenes/include/heightcast/scenes/scenes.h
// says how: terrain, water, the calibrated quadtree, the camera); --scale divides every cell count (below 1: more
// cells than the report's), --cells asks every scenario for the same count, and the actual count is printed beside
// the target (the table's cell sizes show where the finest size was raised or lowered).
// Each scenario then runs in its own forked child (so getrusage's peak RSS is that scenario's alone, and
// its memory is returned before the next): generate the grid, build the influence lists (sigma 1, R 3.5;
// timed), and render --repeat frames (default 3) at 1920 x 1080 with three 1024^2 cascades from the scene's
// fixed oblique camera over the flood (hc::scenes::floodCamera). Where the lists (~220 B a cell) and a frame would not
// fit the memory available (MemAvailable, or what ulimit -v leaves, or --memory-gb), a scenario runs as the tools do
// by default at such sizes: the grid streamed into a temporary file, its surface pyramid built from it a node at a
// time, the frames rendered out of core (as with --out-of-core --pyramid; at 400 M cells the lists would take 88 GB).
// Nearer the limit the child estimates the lists' size from the generated grid (hc::scenes::estimateInfluenceLists)
// and skips the lists and frames if they would not fit, rather than being killed for memory. Stage times are the best
// over the repeats; Gaussians/s = the cascades' kernel evaluations / approximation time; rays/s = pixels / ray casting
// time.
// Targets on this 2-core machine: approximation >= 2 G Gaussians/s; ray casting of 1920 x 1080 within 250 ms
// (>= 8.29 M rays/s at other sizes).
// Why a program and not a test: the figures depend on the machine; tests never time anything.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>
#include <unistd.h>

#include "bench_common.h"
#include "heightcast/support/backend_choice.h"
#include "heightcast/support/cli.h"
#include "heightcast/core/error.h"
#include "heightcast/core/heap.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/timer.h"
#include "heightcast/render/renderer.h"
#include "heightcast/scenes/scenes.h"

#include "bench_render.h"

namespace fs = std::filesystem;
using hc::scenes::Scenario;
using namespace hc::bench;

int main(int argc, char** argv) {
    hc::keepFreedMemory();  // frames reuse the last one's pages, as in hc-view and hc-render's flights (core/heap.h)
    return hc::cli::run("hc-bench", [&] {
        Settings set;
        std::string size = "1920x1080", scenarios = "Marchfeld,Petzenkirchen,Wachau,Florence", csv, json, plot,
                    backendText = "cpu";
        hc::cli::Parser p(
            "hc-bench", "[options]",
            "Benchmarks the CPU renderer on synthetic stand-ins for the technical report's four flood scenes\n"
            "(Marchfeld 82.9 x 57.1 km, 3-96 m cells, 7.46 M cells; Petzenkirchen 15.4 x 16.0 km, 0.75-96 m, 1.81 M;\n"
            "Wachau 24.1 x 16.5 km, 3-96 m, 1.95 M; Florence 44.6 x 28.2 km, 3-96 m, 4.53 M): terrain with a "
            "meandering\n"
            "river valley and a flood (water_depth), generated deterministically as an adaptive quadtree with about\n"
            "the report's cell count. Each scenario runs in its own process: generate, build the influence lists\n"
            "(sigma 1, R 3.5), render --repeat frames from a fixed oblique camera over the flood; it prints the best\n"
            "stage times beside the report's GTX 1080 times, Gaussians/s, rays/s and peak RSS, then checks the\n"
            "targets (approximation >= 2 G Gaussians/s; ray casting of 1920x1080 within 250 ms). MB = 10^6 bytes.");
        p.option(
            "--scale", "F",
            "divide every scenario's cell count by F > 0; below 1 asks for more cells than the report's\n"
            "      (the refinement threshold follows; the finest size doubles where the forced wet-edge and bank cells "
            "alone\n"
            "      exceed the count, and halves where the domain holds fewer than 1.5 x the count at it) (default 1)",
            set.scale);
        p.option("--cells", "N",
                 "every scenario's target cell count instead (e.g. 1e8; scenarios whose influence lists and\n"
                 "      frame would not fit in the memory available are generated but not rendered, and say so)\n"
                 "      (default: the report's count / --scale)",
                 set.cells);
        p.option("--scenarios", "LIST",
                 "comma-separated subset, in the order given; with --trade-grid, none runs the grid alone\n"
                 "      (default Marchfeld,Petzenkirchen,Wachau,Florence)",
                 scenarios);
        p.option("--size", "WxH", "image size in pixels (default 1920x1080)", size);
        p.option("--cascades", "K", "cascades per frame, 1..4 (default 3)", set.options.cascades);
        p.option("--texels", "N", "texels per cascade side, 16..8192 (default 1024)", set.options.texelsPerSide);
        p.option("--repeat", "N", "frames rendered per scenario; each stage's time is the best frame's (default 3)",
                 set.repeat);
        p.option("--threads", "N", "worker threads for generation, lists and rendering (default 0 = all cores)",
                 set.options.threads);
        p.option("--images", "DIR",
                 "also write each scenario's last frame as DIR/SCENARIO.png; DIR is created if missing\n"
                 "      (default: none)",
                 set.imagesDir);
        p.option("--backend", "B",
                 "cpu or gl: the OpenGL 4.3 compute backend in a headless context, stage times from GPU timer\n"
                 "      queries, after one unmeasured warm-up frame (default cpu)",
                 backendText);
        p.option("--csv", "OUT.csv", "also write one row per scenario as CSV with a header line (default: none)", csv);
        p.option("--json", "OUT.json",
                 "also write a JSON array, one object per scenario (scenario, cells, approximation_ms,\n"
                 "      raycast_ms, gaussians_per_s, rays_per_s, peak_rss_mb, and more) (default: none)",
                 json);
        p.option("--fly-frames", "N",
                 "after the timed frames, fly the camera forward for N frames, each evaluated afresh and\n"
                 "      then with incremental cascades (texels kept from the last frame); prints both (default 0: "
                 "off). GL:\n"
                 "      frames back to back into the texture, the texels kept on the GPU (in memory and --out-of-core)",
                 set.flyFrames);
        p.option("--fly-step", "M", "metres the camera moves forward per fly-through frame (default 10)", set.flyStepM);
        p.flag("--pyramid",
               "also build the surface pyramid (hc-influence's .hcp, docs/design.md section 4) and render from it:\n"
               "      texel sizes on its ladder (powers of two of the finest cell), texels it holds copied (CPU)",
               set.pyramid);
        p.flag("--pyramid-coarse",
               "with --pyramid: texels up to 2x coarser than without it (N a side) instead of up to\n"
               "      2x finer (up to 2N a side)",
               set.options.pyramidCoarseTexels);
        p.option("--pyramid-interpolate", "L",
                 "with --pyramid: texels finer than every level stored around them interpolated\n"
                 "      (bicubic) from a coarser stored level, at most L levels up; 0 sums them from the kernels "
                 "(default 3)",
                 set.options.pyramidInterpolateLevels);
        p.option("--max-error", "M",
                 "with --pyramid: error budget [m] (hc-render's --max-error): each cascade the coarsest spacing\n"
                 "      whose error is within M; the JSON's cascades give each one's bound (default 0: none)",
                 set.options.maxErrorM);
        p.option("--max-error-px", "P",
                 "with --pyramid: error budget [pixels] at each cascade's nearest point (default 0: none)",
                 set.options.maxErrorPx);
        p.option("--beam-tile", "P",
                 "ray casting, both backends: tiles of P x P pixels march their beam first and start their rays'\n"
                 "      walks there (the same hits); 0 walks every ray from its cascade's start (default 4)",
                 set.options.beamTilePx);
        p.flag(
            "--out-of-core",
            "stream each grid into a temporary .hcg and render out of core from it, without lists\n"
            "      (render::Scene over a GridRegionReader; with --pyramid the texels it holds need no cell; GL: the\n"
            "      texels a frame newly sees evaluated on the CPU, the cascades kept on the GPU, the mipmaps, ray\n"
            "      casting and shading there)",
            set.outOfCore);
        p.option("--memory-gb", "G",
                 "memory a scenario may hold [GB]; where its influence lists (~220 B a cell) and frame would\n"
                 "      not fit, it runs as --out-of-core --pyramid (default: what the machine has available,\n"
                 "      MemAvailable or what ulimit -v leaves)",
                 set.memoryGb);
        p.flag("--accuracy",
               "measure the last frame's terrain hits against the exact surface: max, p99 and RMS of\n"
               "      |hit height - exact height| [m] (walls and water aside)",
               set.accuracy);
        p.option("--plot", "OUT.svg",
                 "also draw each scenario's best stage times as stacked bars with the targets, SVG\n"
                 "      (default: none)",
                 plot);
        std::string tradeGrid;
        int tradeSamples = int(set.tradeSamples);
        p.flag(
            "--trade",
            "instead of the timed frames: the speed/accuracy trade. Each scene (with its surface pyramid) is\n"
            "      rendered from scratch under error budgets of 1 cm to 100 m and 0.5 to 2 px and under the fixed\n"
            "      knobs (default, --pyramid-coarse, half and twice --texels), best of --repeat, on each backend of\n"
            "      --backend (here a list: cpu, gl or cpu,gl); each frame's hits are checked against the exact\n"
            "      surface (with water, the shoreline too). Prints a table and the issue-43 targets; --json and\n"
            "      --plot write its points and an SVG of error against frame time",
            set.trade);
        p.option("--trade-grid", "GRID.hcg",
                 "with --trade: also a real grid file, its surface pyramid beside it (hc-influence's .hcp),\n"
                 "      out of core, from hc-render's default camera (default: none)",
                 tradeGrid);
        p.option("--trade-samples", "N",
                 "with --trade: hits per frame checked against the exact surface, 100..10000000 (default 20000)",
                 tradeSamples);
        if (!p.parse(argc, argv)) return 0;
        if (set.trade) {
            if (set.options.maxErrorM > 0 || set.options.maxErrorPx > 0)
                throw hc::Error("--trade sweeps the error budgets itself: drop --max-error and --max-error-px");
            if (set.flyFrames || set.accuracy)
                throw hc::Error("--trade: --fly-frames and --accuracy measure other things; run them apart");
            if (tradeSamples < 100 || tradeSamples > 10000000)
                throw hc::Error("--trade-samples " + std::to_string(tradeSamples) + ": must be in 100..10000000");
            set.tradeSamples = size_t(tradeSamples);
            if (!csv.empty()) throw hc::Error("--csv: not written with --trade (its points go to --json)");
            for (const std::string& b : splitList(backendText, "--backend")) {
                if (b != "cpu" && b != "gl") throw hc::Error("--backend " + b + ": with --trade, cpu, gl or cpu,gl");
                (b == "gl" ? set.tradeGl : set.tradeCpu) = true;
            }
            backendText = "cpu";
            set.pyramid = true;  // the bound needs the pyramid
        } else if (!tradeGrid.empty() || tradeSamples != int(set.tradeSamples)) {
            throw hc::Error("--trade-grid and --trade-samples go with --trade");
        }
        if (!(set.scale > 0) || !std::isfinite(set.scale))
            throw hc::Error("--scale " + fmt::format("{:g}", set.scale) + ": must be a number > 0");
        if (!(set.cells >= 0) || !std::isfinite(set.cells) || (set.cells > 0 && set.cells < 1000) || set.cells >= 4e9)
            throw hc::Error("--cells " + fmt::format("{:g}", set.cells) +
                            ": must be a count in 1000 .. 4e9 (a grid holds fewer than 2^32 cells)");
        if (set.cells > 0 && set.scale != 1) throw hc::Error("--cells and --scale: give one of them");
        if (!(set.memoryGb >= 0) || !std::isfinite(set.memoryGb))
            throw hc::Error("--memory-gb " + fmt::format("{:g}", set.memoryGb) +
                            ": must be a number of GB, >= 0 (0: what is available)");
        if (set.repeat < 1) throw hc::Error("--repeat " + std::to_string(set.repeat) + ": must be at least 1");
        set.backend = hc::cli::parseBackend(backendText);
        if (set.backend == hc::cli::Backend::Auto)
            throw hc::Error("--backend auto: a benchmark names its backend, cpu or gl");
        if (set.flyFrames < 0 || set.flyFrames == 1)
            throw hc::Error("--fly-frames " + std::to_string(set.flyFrames) + ": 0 (off) or at least 2");
        if (!(set.flyStepM >= 0) || !std::isfinite(set.flyStepM))
            throw hc::Error("--fly-step " + fmt::format("{:g}", set.flyStepM) + ": metres >= 0");
        if (std::string why = set.options.validate(); !why.empty()) throw hc::Error(why);
        {
            auto x = size.find('x');
            if (x == std::string::npos) throw hc::Error("--size " + size + ": expected WxH, e.g. 1920x1080");
            const double w = hc::cli::parseNumber(size.substr(0, x), "--size"),
                         h = hc::cli::parseNumber(size.substr(x + 1), "--size");
            if (w != std::floor(w) || h != std::floor(h) || w < 1 || h < 1 || w > 16384 || h > 16384)
                throw hc::Error("--size " + size + ": width and height must be whole numbers in 1..16384");
            set.width = int(w), set.height = int(h);
        }
        std::vector<const Scenario*> chosen;
        const bool gridOnly = set.trade && !tradeGrid.empty() && scenarios == "none";  // the real grid alone
        for (const std::string& name : gridOnly ? std::vector<std::string>{} : splitList(scenarios, "--scenarios")) {
            const Scenario* found = hc::scenes::findScenario(name);
            if (!found)
                throw hc::Error("--scenarios " + name +
                                ": not a scenario (Marchfeld, Petzenkirchen, Wachau or Florence)");
            chosen.push_back(found);
        }
        for (const std::string* o : {&csv, &json, &plot})
            if (!o->empty()) hc::cli::checkWritable(*o, o == &csv ? "--csv" : o == &json ? "--json" : "--plot");
        if (!set.imagesDir.empty()) {
            std::error_code ec;
            fs::create_directories(set.imagesDir, ec);
            if (!fs::is_directory(set.imagesDir))
                throw hc::Error(set.imagesDir + ": cannot create the image folder (--images)");
        }
        set.interactive = isatty(STDERR_FILENO);
        const unsigned threads = hc::resolveThreads(set.options.threads);

        const std::string sizeText =
            set.cells > 0 ? fmt::format("{:g} cells each", set.cells) : fmt::format("scale {:g}", set.scale);
        std::printf(
            "hc-bench: %u worker thread%s (hardware threads: %u), %s, %dx%d, %d cascade%s of %d^2 texels, best of %d\n",
            threads, threads == 1 ? "" : "s", std::thread::hardware_concurrency(), sizeText.c_str(), set.width,
            set.height, set.options.cascades, set.options.cascades == 1 ? "" : "s", set.options.texelsPerSide,
            set.repeat);
        std::printf("load average (1 min) at start: %s\n", loadAverage().c_str());
        removeStaleGrids();
        const hc::Stopwatch wall;
        std::vector<RunResult> results;
        for (const Scenario* sc : chosen) results.push_back(runScenario(*sc, set));
        if (set.trade) {
            if (!tradeGrid.empty()) results.push_back(runTradeOnGrid(tradeGrid, set));
            if (set.interactive) std::fprintf(stderr, "\r%60s\r", "");
            printTrade(results, set);
            if (!json.empty()) writeTradeJson(results, set, json), std::printf("points written to %s\n", json.c_str());
            if (!plot.empty()) writeTradePlot(results, set, plot);
            return 0;
        }
        if (set.interactive) std::fprintf(stderr, "\r%60s\r", "");
        const double wallS = wall.seconds();

        printTables(chosen, results, set, wallS);

        if (!csv.empty()) {
            writeCsv(chosen, results, set, csv);
            std::printf("rows written to %s\n", csv.c_str());
        }
        if (!json.empty()) {
            writeJson(chosen, results, set, json);
            std::printf("objects written to %s\n", json.c_str());
        }
        if (!plot.empty()) writePlot(chosen, results, set, sizeText, plot);

        return 0;
    });
}
