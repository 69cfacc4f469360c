// bench/bench_render_trade.cpp: hc-bench --trade: frame time against the error a frame carries, over error budgets
// (1 cm to 100 m, and 0.5 to 2 px) and the fixed knobs (--pyramid-coarse, --texels), on the CPU and the GL backend,
// for the report's scenes and a real grid file. Every frame is rendered from scratch (best of --repeat), then read
// back once and checked against the exact smooth surface at --trade-samples of its hits (render::verifyFrameError).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "bench_common.h"
#include "bench_render.h"
#include "heightcast/core/atomic_file.h"
#include "heightcast/core/error.h"
#include "heightcast/core/progress.h"
#include "heightcast/core/quantile.h"
#include "heightcast/core/timer.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/influence/pyramid.h"
#include "heightcast/render/gl/gl_renderer.h"
#include "heightcast/render/renderer.h"
#include "svg_plot.h"

namespace hc::bench {
namespace {

// One point of the sweep: a budget or a fixed knob over the run's options.
struct TradeSetting {
    const char* label;
    bool budget, isDefault;
    double maxErrorM, maxErrorPx;
    bool coarse;
    double texelsFactor;  // times the run's --texels (the label's N is the product)
};

constexpr TradeSetting kSettings[] = {
    {"default", false, true, 0, 0, false, 1},     {"--pyramid-coarse", false, false, 0, 0, true, 1},
    {"--texels", false, false, 0, 0, false, 0.5}, {"--texels", false, false, 0, 0, false, 2},
    {"1 cm", true, false, 0.01, 0, false, 1},     {"10 cm", true, false, 0.1, 0, false, 1},
    {"1 m", true, false, 1, 0, false, 1},         {"10 m", true, false, 10, 0, false, 1},
    {"100 m", true, false, 100, 0, false, 1},     {"0.5 px", false, false, 0, 0.5, false, 1},
    {"1 px", false, false, 0, 1, false, 1},       {"2 px", false, false, 0, 2, false, 1},
};
static_assert(2 * std::size(kSettings) <= size_t(kMaxTradePoints));

// The issue-43 targets: a budget of M metres holds every non-wall hit within M + 5 mm (float32); the loose budget
// (10 m) renders at least 2x faster than the tight one (0.1 m) on the CPU; the bound is tight: within 10x of the
// largest error measured, on the median frame (the "within 10x of it on the median", read over the frames: an
// error's median over a frame's hits lies near 0 wherever hits fall near the samples, whatever the bound).
constexpr double kBudgetSlackM = 0.005;
constexpr double kLooseOverTightTarget = 2.0;
constexpr double kBoundOverMaxTarget = 10.0;

render::RenderOptions optionsFor(const TradeSetting& s, const render::RenderOptions& base) {
    render::RenderOptions o = base;
    o.maxErrorM = s.maxErrorM;
    o.maxErrorPx = s.maxErrorPx;
    o.pyramidCoarseTexels = s.coarse;
    o.texelsPerSide = std::clamp(int(std::lround(s.texelsFactor * base.texelsPerSide)), 16, 8192);
    return o;
}

// "--texels 512" for the knobs that scale --texels (N the product), else the setting's label.
std::string labelOf(const TradeSetting& s, const render::RenderOptions& base) {
    if (s.texelsFactor == 1) return s.label;
    return fmt::format("{} {}", s.label, optionsFor(s, base).texelsPerSide);
}

void keepFastest(const render::Timings& tm, TradePoint& p) {
    if (!(tm.totalMs < p.totalMs)) return;
    p.totalMs = tm.totalMs, p.approximationMs = tm.approximationMs, p.raycastMs = tm.raycastMs;
    p.boundM = tm.errorBoundM, p.boundPx = tm.errorBoundPx, p.shoreBoundM = tm.shoreBoundM;
    p.texels = 0;
    for (const auto& c : tm.cascades) p.texels += c.visibleTexels;
}

const TradePoint* find(const RunResult& r, bool gl, const char* label) {
    for (int k = 0; k < r.tradeCount; ++k)
        if (r.trade[k].gl == gl && std::string(r.trade[k].label) == label) return &r.trade[k];
    return nullptr;
}

// The point's own budget at its hits: "yes" (met at every checked hit), "NO", "short" (the texels could not meet it:
// the frame's bound is above it, as the renderer says), or "-" without one.
std::string budgetHeld(const TradePoint& p) {
    if (p.maxErrorM > 0) return p.boundM > p.maxErrorM ? "short" : p.maxM <= p.maxErrorM + kBudgetSlackM ? "yes" : "NO";
    if (p.maxErrorPx > 0) return p.boundPx > p.maxErrorPx ? "short" : p.maxPx <= p.maxErrorPx ? "yes" : "NO";
    return "-";
}

}  // namespace

void tradeSweep(const render::Scene& scene, const render::Camera& camera, const Settings& set, RunResult& r) {
    if (!scene.pyramid()) throw Error("--trade: the scene has no surface pyramid (the bound needs one)");
    std::unique_ptr<render::GlRenderer> gl;
    if (set.tradeGl) {  // warm-up frames first, unmeasured (shader compiles; an idle GPU's clocks), as hc-bench's
        gl = render::GlRenderer::headless(scene);
        const Stopwatch warmUp;
        do {
            render::Timings warm;
            gl->forgetCascades(), gl->renderToTexture(camera, set.options, warm);
        } while (warmUp.seconds() < 1.0);
    }
    if (set.tradeCpu) {  // one unmeasured CPU frame first: the first frame pays page faults (an out-of-core pyramid's)
        render::Timings warm;
        (void)render::renderFrame(scene, camera, set.options, warm);
    }
    for (const bool onGl : {false, true}) {
        if (onGl ? !set.tradeGl : !set.tradeCpu) continue;
        for (const TradeSetting& s : kSettings) {
            const std::string label = labelOf(s, set.options);
            progressLine(set.interactive, r.name, fmt::format("trade: {} {}", onGl ? "GL" : "CPU", label));
            TradePoint& p = r.trade[r.tradeCount++];
            std::snprintf(p.label, sizeof p.label, "%s", label.c_str());
            p.gl = onGl, p.budget = s.budget, p.isDefault = s.isDefault;
            p.maxErrorM = s.maxErrorM, p.maxErrorPx = s.maxErrorPx;
            const render::RenderOptions o = optionsFor(s, set.options);
            render::Frame frame;
            try {
                for (int k = 0; k < set.repeat; ++k) {
                    render::Timings tm;
                    if (onGl)
                        gl->forgetCascades(), gl->renderToTexture(camera, o, tm);
                    else
                        frame = render::renderFrame(scene, camera, o, tm);
                    keepFastest(tm, p);
                }
                if (onGl) {  // the picture read back once, from scratch as the timed frames
                    render::Timings tm;
                    gl->forgetCascades();
                    frame = gl->render(camera, o, tm);
                }
            } catch (const Error& e) {  // a GL driver's limits (storage buffer size): said in the table, not fatal
                if (!onGl) throw;
                std::snprintf(p.skipped, sizeof p.skipped, "%s", e.what());
                continue;
            }
            const render::ErrorCheck c =
                render::verifyFrameError(scene, camera, frame, set.tradeSamples, set.options.threads);
            p.checked = c.hits, p.maxM = c.maxM, p.p99M = c.p99M, p.medianM = c.medianM, p.maxPx = c.maxPx;
            p.shoreM = c.shoreDistanceM;
        }
    }
}

RunResult runTradeOnGrid(const std::string& gridPath, const Settings& set) {
    return inChild<RunResult>(gridPath, [&](RunResult& r) {
        std::snprintf(r.name, sizeof r.name, "%s", std::filesystem::path(gridPath).stem().string().c_str());
        r.baselineRss = currentRssBytes();
        const GridRegionReader file(gridPath);
        const std::string pyramidPath = influence::defaultPyramidPath(gridPath);
        if (!std::filesystem::exists(pyramidPath))
            throw Error(gridPath + ": no surface pyramid beside it (" + pyramidPath +
                        "); --trade-grid needs one: hc-influence " + gridPath);
        const influence::KernelParams params;
        const influence::SurfacePyramid pyramid = influence::readSurfacePyramid(pyramidPath, file.info(), params);
        const render::Scene scene(file, params, &pyramid);
        r.cells = file.cellCount();
        r.finestM = file.shape().finestCellM;
        r.coarsestM = file.shape().levelSizeM(file.shape().maxLevel);
        r.width = set.width, r.height = set.height, r.repeats = set.repeat;
        tradeSweep(scene, render::overviewCamera(scene, set.width, set.height), set, r);
        r.peakRss = peakRssBytes();
    });
}

void printTrade(const std::vector<RunResult>& results, const Settings& set) {
    std::printf(
        "\ntrade: frame time (best of %d, from scratch, %dx%d) against the error at the frame's hits (walls aside), "
        "%zu hits checked a frame against the exact surface\n"
        "bound = the frame's reported bound (Timings error_bound_m, _px); max / p99 / median = measured |rendered - "
        "exact|; b/max = bound / max; held = the setting's own budget met at every checked hit (metres: + %g mm "
        "float32), short = the texels could not meet it (the bound is above it); with water, shore = the shoreline's "
        "bound (Timings shore_bound_m) and the farthest the exact shore lay from a hit on its wrong side\n",
        set.repeat, set.width, set.height, set.tradeSamples, kBudgetSlackM * 1e3);
    std::printf("%-14s %-4s %-17s %7s %8s %9s %9s %8s %9s %9s %9s %8s %6s %5s %9s %9s\n", "scene", "", "setting",
                "cells M", "texels M", "frame ms", "bound m", "bound px", "max m", "p99 m", "median m", "max px",
                "b/max", "held", "shore m", "measured");
    bool boundsHold = true, budgetsHold = true, loosePays = true, shoresHold = true;
    std::vector<double> overMax;
    for (const RunResult& r : results) {
        for (int k = 0; k < r.tradeCount; ++k) {
            const TradePoint& p = r.trade[k];
            if (p.skipped[0]) {
                std::printf("%-14s %-4s %-17s not run: %s\n", r.name, p.gl ? "GL" : "CPU", p.label, p.skipped);
                continue;
            }
            const std::string held = budgetHeld(p);
            overMax.push_back(p.maxM > 0 ? p.boundM / p.maxM : HUGE_VAL);
            boundsHold = boundsHold && p.maxM <= p.boundM;
            budgetsHold = budgetsHold && held != "NO";
            shoresHold = shoresHold && p.shoreM <= p.shoreBoundM * render::kShoreRingStep;
            std::printf(
                "%-14s %-4s %-17s %7.2f %8.2f %9.1f %9.4f %8.3f %9.4f %9.4f %9.5f %8.3f %6.1f %5s %9.4g %9.4g%s\n",
                r.name, p.gl ? "GL" : "CPU", p.label, double(r.cells) / 1e6, double(p.texels) / 1e6, p.totalMs,
                p.boundM, p.boundPx, p.maxM, p.p99M, p.medianM, p.maxPx, overMax.back(), held.c_str(), p.shoreBoundM,
                p.shoreM, p.maxM <= p.boundM ? "" : "  (above its bound)");
        }
    }
    std::printf("\ntargets (issue 43):\n");
    for (const RunResult& r : results) {
        const TradePoint *tight = find(r, false, "10 cm"), *loose = find(r, false, "10 m");
        if (!tight || !loose) continue;
        const double ratio = tight->totalMs / loose->totalMs;
        loosePays = loosePays && ratio >= kLooseOverTightTarget;
        std::printf("  %-14s CPU: --max-error 10 renders %.2fx as fast as --max-error 0.1 (target >= %.0fx): %s\n",
                    r.name, ratio, kLooseOverTightTarget, ratio >= kLooseOverTightTarget ? "met" : "NOT met");
    }
    const double medianOverMax = quantile(overMax, 0.5);
    std::printf("  every budget the texels could meet held at every checked hit: %s\n",
                budgetsHold ? "met" : "NOT met");
    std::printf("  every measured error at or below its frame's bound: %s\n", boundsHold ? "met" : "NOT met");
    std::printf("  every measured shore distance within its frame's shoreline bound (+ %.0f %%, the rings' step): %s\n",
                (render::kShoreRingStep - 1) * 100, shoresHold ? "met" : "NOT met");
    std::printf("  the bound within %.0fx of the measured largest error on the median frame: %.1fx, %s\n",
                kBoundOverMaxTarget, medianOverMax, medianOverMax <= kBoundOverMaxTarget ? "met" : "NOT met");
    if (set.tradeCpu) std::printf("  the loose budget pays on every scene (CPU): %s\n", loosePays ? "met" : "NOT met");
}

void writeTradeJson(const std::vector<RunResult>& results, const Settings& set, const std::string& path) {
    std::string o = "[\n";
    bool first = true;
    for (const RunResult& r : results)
        for (int k = 0; k < r.tradeCount; ++k) {
            const TradePoint& p = r.trade[k];
            if (p.skipped[0]) continue;
            o += fmt::format(
                "{}  {{\"scene\": \"{}\", \"cells\": {}, \"backend\": \"{}\", \"setting\": \"{}\", \"default\": {}, "
                "\"max_error_m\": {:g}, \"max_error_px\": {:g}, \"width\": {}, \"height\": {}, \"frame_ms\": {:.3f}, "
                "\"approximation_ms\": {:.3f}, \"raycast_ms\": {:.3f}, \"visible_texels\": {}, \"bound_m\": {:.6g}, "
                "\"bound_px\": {:.6g}, \"checked_hits\": {}, \"error_max_m\": {:.6g}, \"error_p99_m\": {:.6g}, "
                "\"error_median_m\": {:.6g}, \"error_max_px\": {:.6g}, \"shore_bound_m\": {:.6g}, "
                "\"shore_distance_m\": {:.6g}}}",
                first ? "" : ",\n", r.name, r.cells, p.gl ? "gl" : "cpu", p.label, p.isDefault, p.maxErrorM,
                p.maxErrorPx, set.width, set.height, p.totalMs, p.approximationMs, p.raycastMs, p.texels, p.boundM,
                p.boundPx, p.checked, p.maxM, p.p99M, p.medianM, p.maxPx, p.shoreBoundM, p.shoreM);
            first = false;
        }
    o += "\n]\n";
    AtomicFileWriter w(path);
    w.write(std::as_bytes(std::span(o)));
    w.commit();
}

void writeTradePlot(const std::vector<RunResult>& results, const Settings& set, const std::string& path) {
    LinePlot plot;
    plot.title =
        fmt::format("hc-bench --trade: frame time against measured error, {}x{}, from scratch", set.width, set.height);
    plot.xLabel = "largest error at the frame's hits against the exact surface [m] (log)";
    plot.yLabel = "frame time, best of the repeats [ms] (log)";
    plot.logX = plot.logY = true;
    size_t color = 0;
    for (const RunResult& r : results)
        for (const bool gl : {false, true}) {
            LineSeries budgets{fmt::format("{} {}: budgets 1 cm .. 100 m", r.name, gl ? "GL" : "CPU"),
                               plotColor(color),
                               gl ? "6,4" : "",
                               {}};
            LineSeries knobs{
                fmt::format("{} {}: fixed knobs, px budgets", r.name, gl ? "GL" : "CPU"), plotColor(color), "", {}};
            knobs.line = false;
            for (int k = 0; k < r.tradeCount; ++k) {
                const TradePoint& p = r.trade[k];
                if (p.gl != gl || p.skipped[0]) continue;
                (p.budget ? budgets : knobs).points.push_back({p.maxM, p.totalMs});
                if (p.isDefault) plot.rings.push_back({"default", {p.maxM, p.totalMs}});
            }
            if (budgets.points.empty()) continue;
            plot.series.push_back(std::move(budgets));
            plot.series.push_back(std::move(knobs));
            ++color;
        }
    writeSvg(path, plot.svg());
    std::printf("trade plot written to %s\n", path.c_str());
}

}  // namespace hc::bench
