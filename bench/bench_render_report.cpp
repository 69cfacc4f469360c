// bench/bench_render_report.cpp: hc-bench's output (bench_render.h): the tables, CSV, JSON and the plot.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "bench_common.h"
#include "svg_plot.h"
#include "heightcast/support/backend_choice.h"
#include "heightcast/support/cli.h"
#include "heightcast/core/error.h"
#include "heightcast/core/rounded.h"
#include "heightcast/grid/grid.h"
#include "heightcast/influence/influence.h"
#include "heightcast/render/renderer.h"
#include "heightcast/scenes/scenes.h"

#include "bench_render.h"

using hc::scenes::Scenario;

namespace hc::bench {
namespace {

double mb(uint64_t bytes) { return double(bytes) / 1e6; }

std::string sizesText(const RunResult& r) { return fmt::format("{:g} - {:g}", r.finestM, r.coarsestM); }
std::string extentText(const RunResult& r) {
    return fmt::format("{:.1f} x {:.1f}", r.extentXM / 1e3, r.extentYM / 1e3);
}
double gaussiansPerS(const RunResult& r) { return double(r.gaussians) / (r.approximationMs / 1e3); }
double raysPerS(const RunResult& r) { return double(r.rays) / (r.raycastMs / 1e3); }
bool approximationMet(const RunResult& r) { return gaussiansPerS(r) >= kTargetGaussiansPerS; }
bool glFrameMet(const RunResult& r) { return r.gpuMs < 1e300 && r.totalMs <= kTargetGlFrameMs; }
bool raycastMet(const RunResult& r) {
    return (r.width == 1920 && r.height == 1080) ? r.raycastMs <= kTargetRaycastMs : raysPerS(r) >= kTargetRaysPerS;
}

// JSON numbers as the tables print them (core/rounded.h).
double ms(double v) { return hc::rounded(v, std::chars_format::fixed, 3); }
double sig6(double v) { return hc::rounded(v, std::chars_format::general, 6); }
double fixed1(double v) { return hc::rounded(v, std::chars_format::fixed, 1); }

}  // namespace

void writeJson(const std::vector<const Scenario*>& scs, const std::vector<RunResult>& rs, const Settings& set,
               const std::string& path) {
    using Json = nlohmann::ordered_json;  // keys in the order written
    Json all = Json::array();
    for (size_t k = 0; k < rs.size(); ++k) {
        const Scenario& sc = *scs[k];
        const RunResult& r = rs[k];
        Json o;
        o["scenario"] = sc.name;
        o["cells"] = r.cells;
        o["approximation_ms"] = ms(r.approximationMs);
        o["raycast_ms"] = ms(r.raycastMs);
        o["gaussians_per_s"] = sig6(gaussiansPerS(r));
        o["rays_per_s"] = sig6(raysPerS(r));
        o["peak_rss_mb"] = fixed1(mb(r.peakRss));
        o["scale"] = set.scale;
        o["target_cells"] = static_cast<int64_t>(std::nearbyint(r.targetCells));  // ties to even, as the tables
        o["extent_x_m"] = std::llround(r.extentXM);
        o["extent_y_m"] = std::llround(r.extentYM);
        o["finest_m"] = r.finestM;
        o["coarsest_m"] = r.coarsestM;
        o["wet_cells"] = r.wetCells;
        o["threshold_m"] = sig6(r.thresholdM);
        o["generation_s"] = ms(r.generationS);
        o["calibration_s"] = ms(r.calibrationS);
        Json perLevel = Json::array();
        for (int l = 0; l <= int(std::lround(std::log2(r.coarsestM / r.finestM))) && l < kMaxLevels; ++l)
            perLevel.push_back(r.cellsPerLevel[l]);
        o["cells_per_level"] = perLevel;
        o["lists_ms"] = ms(r.listsMs);
        o["list_mean"] = ms(r.listMean);
        o["list_p99"] = r.listP99;
        o["list_max"] = r.listMax;
        o["lists_mb"] = ms(mb(r.listBytes));
        auto degrees = [](double v) { return hc::rounded(v, std::chars_format::fixed, 4); };
        o["camera"] = {{"x", ms(r.camera[0])},
                       {"y", ms(r.camera[1])},
                       {"z", ms(r.camera[2])},
                       {"yaw_deg", degrees(r.camera[3])},
                       {"pitch_deg", degrees(r.camera[4])},
                       {"fov_y_deg", degrees(r.camera[5])}};
        o["width"] = r.width;
        o["height"] = r.height;
        o["cascades_requested"] = set.options.cascades;
        o["texels"] = set.options.texelsPerSide;
        o["repeat"] = r.repeats;
        o["fitting_ms"] = ms(r.fittingMs);
        o["mipmap_ms"] = ms(r.mipmapMs);
        o["shading_ms"] = ms(r.shadingMs);
        o["total_ms"] = ms(r.totalMs);
        o["worst_approximation_ms"] = ms(r.worstApproximationMs);
        o["worst_raycast_ms"] = ms(r.worstRaycastMs);
        o["gaussians"] = r.gaussians;
        o["rays"] = r.rays;
        o["hits"] = r.hits;
        o["water_hits"] = r.wetHits;
        o["backend"] = hc::cli::backendName(set.backend);
        o["device"] = std::string(r.device);
        o["gpu_ms"] = ms(r.gpuMs < 1e300 ? r.gpuMs : 0.0);
        o["readback_ms"] = ms(r.readbackMs);
        if (set.backend == hc::cli::Backend::Gl) o["gl_frame_target"] = glFrameMet(r) ? "met" : "MISSED";
        Json cascades = Json::array();
        for (int c = 0; c < r.cascadeCount; ++c) {
            const CascadeOut& cs = r.cascades[c];
            cascades.push_back(
                {{"near_m", ms(cs.nearM)},
                 {"far_m", ms(cs.farM)},
                 {"texel_m", sig6(cs.texelM)},
                 {"visible_texels", cs.visibleTexels},
                 {"gaussians", cs.gaussians},
                 {"approximation_ms", ms(cs.approximationMs)},
                 {"pyramid_level", cs.pyramidLevel},
                 {"pyramid_texels", cs.pyramidTexels},
                 {"pyramid_interpolated", cs.pyramidInterpolated},
                 {"error_bound_m", std::isfinite(cs.errorBoundM) ? Json(sig6(cs.errorBoundM)) : Json()}});
        }
        o["cascades"] = cascades;
        o["report_gtx1080_approximation_ms"] = sc.gpuApproxMs;
        o["report_gtx1080_raycast_ms"] = sc.gpuRaycastMs;
        o["baseline_rss_mb"] = fixed1(mb(r.baselineRss));
        o["grid_rss_mb"] = fixed1(mb(r.gridRss));
        o["approximation_target"] = approximationMet(r) ? "met" : "MISSED";
        o["raycast_target"] = raycastMet(r) ? "met" : "MISSED";
        if (r.image[0]) o["image"] = std::string(r.image);
        o["out_of_core"] = r.outOfCore;
        if (r.pyramid) {
            o["pyramid_ms"] = ms(r.pyramidMs);
            o["pyramid_mb"] = ms(mb(r.pyramidBytes));
        }
        if (set.accuracy) {
            o["accuracy_samples"] = r.accuracySamples;
            o["accuracy_max_m"] = sig6(r.accuracyMaxM);
            o["accuracy_p99_m"] = sig6(r.accuracyP99M);
            o["accuracy_rms_m"] = sig6(r.accuracyRmsM);
        }
        if (set.flyFrames > 1) {
            o["fly_frames"] = set.flyFrames;
            o["fly_step_m"] = set.flyStepM;
            o["fly_approximation_ms_fresh"] = ms(r.flyApproxFreshMs);
            o["fly_approximation_ms_cached"] = ms(r.flyApproxCachedMs);
            o["fly_total_ms_fresh"] = ms(r.flyTotalFreshMs);
            o["fly_total_ms_cached"] = ms(r.flyTotalCachedMs);
            o["fly_texels_kept"] = hc::rounded(r.flyKept, std::chars_format::fixed, 4);
            o["fly_upload_ms_fresh"] = ms(r.flyUploadFreshMs);
            o["fly_upload_ms_cached"] = ms(r.flyUploadCachedMs);
            o["fly_upload_mb_fresh"] = sig6(r.flyUploadFreshMB);
            o["fly_upload_mb_cached"] = sig6(r.flyUploadCachedMB);
            o["fly_cells_visited_fresh"] = std::llround(r.flyCellsFresh);
            o["fly_cells_visited_cached"] = std::llround(r.flyCellsCached);
        }
        all.push_back(std::move(o));
    }
    std::ofstream f(path);
    if (!f) throw hc::Error(path + ": cannot open for writing (--json)");
    // Device names and paths are outside text: bytes that are not UTF-8 become U+FFFD rather than an exception.
    f << all.dump(2, ' ', false, Json::error_handler_t::replace) << "\n";
    if (!f.flush()) throw hc::Error(path + ": write failed (--json)");
}

void writeCsv(const std::vector<const Scenario*>& scs, const std::vector<RunResult>& rs, const Settings& set,
              const std::string& path) {
    std::ofstream f(path);
    if (!f) throw hc::Error(path + ": cannot open for writing (--csv)");
    f << "scenario,scale,extent_x_m,extent_y_m,finest_m,coarsest_m,target_cells,cells,wet_cells,threshold_m,generation_"
         "s,lists_ms,list_mean,"
         "lists_mb,width,height,cascades,texels,fitting_ms,approximation_ms,mipmap_ms,raycast_ms,shading_ms,total_ms,"
         "gaussians,"
         "gaussians_per_s,rays,rays_per_s,peak_rss_mb,gtx1080_approximation_ms,gtx1080_raycast_ms,approximation_target,"
         "raycast_target,"
         "gpu_ms,readback_ms\n";
    for (size_t k = 0; k < rs.size(); ++k) {
        const Scenario& sc = *scs[k];
        const RunResult& r = rs[k];
        f << fmt::format(
            "{},{:g},{:.0f},{:.0f},{:g},{:g},{:.0f},{},{},{:.6g},{:.3f},{:.3f},{:.3f},{:.3f},{},{},{},{},{:.3f},{:.3f},"
            "{:.3f},{:.3f},{:.3f},{:.3f},{},{:.6g},{},{:.6g},"
            "{:.1f},{:.1f},{:.1f},{},{},{:.3f},{:.3f}\n",
            sc.name, set.scale, r.extentXM, r.extentYM, r.finestM, r.coarsestM, r.targetCells, r.cells, r.wetCells,
            r.thresholdM, r.generationS, r.listsMs, r.listMean, mb(r.listBytes), r.width, r.height,
            set.options.cascades, set.options.texelsPerSide, r.fittingMs, r.approximationMs, r.mipmapMs, r.raycastMs,
            r.shadingMs, r.totalMs, r.gaussians, gaussiansPerS(r), r.rays, raysPerS(r), mb(r.peakRss), sc.gpuApproxMs,
            sc.gpuRaycastMs, approximationMet(r) ? "met" : "MISSED", raycastMet(r) ? "met" : "MISSED",
            r.gpuMs < 1e300 ? r.gpuMs : 0.0, r.readbackMs);
    }
    if (!f.flush()) throw hc::Error(path + ": write failed (--csv)");
}

void printTables(std::vector<const Scenario*>& chosen, std::vector<RunResult>& results, const Settings& set,
                 double wallS) {
    // ---- table 1: the grids ----
    std::printf(
        "\n1. grids: synthetic, deterministic; extent rounded to whole 96 m cells; target = the report's cells / "
        "scale;\n"
        "T = calibrated refinement threshold [m]; wet = cells with water; calib s = finding T, build s = building "
        "the\n"
        "grid (neither is part of a frame); lists = buildInfluenceLists (sigma 1, R 3.5, all threads, one run): "
        "time,\n"
        "mean / p99 / max entries per cell, offsets + indices\n\n");
    std::printf("%-14s %13s %10s %10s %10s %7s %8s %6s %7s %7s %9s %6s %5s %5s %8s\n", "scenario", "extents km",
                "cells m", "target", "cells", "diff %", "T m", "wet %", "calib s", "build s", "lists ms", "mean", "p99",
                "max", "lists MB");
    for (size_t k = 0; k < results.size(); ++k) {
        const RunResult& r = results[k];
        const double target = r.targetCells;
        std::printf("%-14s %13s %10s %10.0f %10llu %+7.1f %8.3g %6.1f %7.1f %7.1f %9.1f %6.1f %5llu %5llu %8.1f\n",
                    chosen[k]->name, extentText(r).c_str(), sizesText(r).c_str(), target, (unsigned long long)r.cells,
                    (double(r.cells) / target - 1) * 100, r.thresholdM, 100.0 * double(r.wetCells) / double(r.cells),
                    r.calibrationS, r.generationS - r.calibrationS, r.listsMs, r.listMean,
                    (unsigned long long)r.listP99, (unsigned long long)r.listMax, mb(r.listBytes));
    }
    for (size_t k = 0; k < results.size(); ++k) {
        const RunResult& r = results[k];
        std::string counts;
        const int levels = int(std::lround(std::log2(r.coarsestM / r.finestM)));
        for (int l = 0; l <= levels && l < kMaxLevels; ++l)
            counts += fmt::format("{}{:g} m: {}", l ? ", " : "", r.finestM * double(1 << l), r.cellsPerLevel[l]);
        std::printf("%-14s cells per size: %s%s\n", chosen[k]->name, counts.c_str(),
                    r.finestRaised    ? " (finest size raised: the forced cells alone exceeded the scaled count)"
                    : r.finestLowered ? " (finest size lowered: the domain held too few cells at the scenario's)"
                                      : "");
        if (r.outOfCore && !set.outOfCore)
            std::printf(
                "%-14s out of core: lists and frame ~%.1f GB (%.0f B a cell) would not fit %.1f GB available; the "
                "grid was\n%-14s streamed into a file, its surface pyramid built a node at a time and the frames "
                "rendered from the file,\n%-14s as hc-influence and hc-render do by default at this size\n",
                chosen[k]->name, double(r.renderNeedBytes) / 1e9, hc::influence::kListBytesPerCell,
                double(r.memAvailableBytes) / 1e9, "", "");
    }
    // Scenarios whose lists and frame would not fit were generated only: said here, left out of what follows.
    {
        std::vector<const Scenario*> renderedScenarios;
        std::vector<RunResult> rendered;
        for (size_t k = 0; k < results.size(); ++k) {
            const RunResult& r = results[k];
            if (!r.renderSkipped) {
                renderedScenarios.push_back(chosen[k]);
                rendered.push_back(r);
                continue;
            }
            std::printf(
                "%-14s RENDERING SKIPPED: influence lists ~%.1f GB (estimated) + frame ~%.1f GB need %.1f GB; %.1f "
                "GB available"
                " (MemAvailable, what ulimit -v leaves or --memory-gb); grid generated in %.1f s, peak RSS %.0f "
                "MB\n",
                chosen[k]->name, double(r.listsEstimateBytes) / 1e9,
                double(r.renderNeedBytes - r.listsEstimateBytes) / 1e9, double(r.renderNeedBytes) / 1e9,
                double(r.memAvailableBytes) / 1e9, r.generationS, mb(r.peakRss));
        }
        chosen = std::move(renderedScenarios);
        results = std::move(rendered);
    }

    // ---- table 2: the renderer, in the report's form ----
    std::printf(
        "\n2. rendering with the %s backend (%s): %dx%d, %d cascade%s of %d^2 texels, best of %d frames per stage "
        "(worst in brackets); camera 1.5 km\n"
        "above the river 10 %% downstream, looking along it, pitch -20, fov 50; G Gauss/s = kernel evaluations in\n"
        "the approximation / its time; M rays/s = pixels / ray casting time; peak RSS = the scenario's process\n"
        "(getrusage) at the end; GTX 1080 = the report's times for the real data\n\n",
        hc::cli::backendName(set.backend), results.empty() ? "-" : results[0].device, set.width, set.height,
        set.options.cascades, set.options.cascades == 1 ? "" : "s", set.options.texelsPerSide, set.repeat);
    std::printf("%-14s %13s %10s %7s %19s %19s %8s %7s %8s %8s %11s %10s %8s %11s %11s\n", "scenario", "extents km",
                "cells m", "cells M", "approximation ms", "ray casting ms", "fit ms", "mip ms", "shade ms", "total ms",
                "G Gauss/s", "M rays/s", "peak MB", "GTX appr ms", "GTX ray ms");
    for (size_t k = 0; k < results.size(); ++k) {
        const RunResult& r = results[k];
        std::printf(
            "%-14s %13s %10s %7.2f %8.1f (%8.1f) %8.1f (%8.1f) %8.2f %7.1f %8.1f %8.1f %11.3f %10.2f %8.0f %11.1f "
            "%11.1f\n",
            chosen[k]->name, extentText(r).c_str(), sizesText(r).c_str(), double(r.cells) / 1e6, r.approximationMs,
            r.worstApproximationMs, r.raycastMs, r.worstRaycastMs, r.fittingMs, r.mipmapMs, r.shadingMs, r.totalMs,
            gaussiansPerS(r) / 1e9, raysPerS(r) / 1e6, mb(r.peakRss), chosen[k]->gpuApproxMs, chosen[k]->gpuRaycastMs);
    }
    if (set.backend == hc::cli::Backend::Gl) {
        std::printf(
            "\nGL frames: total = wall time of a frame ending in the texture, as hc-view draws it (fitting and "
            "visible spans on\n"
            "the CPU, uploads, the GPU's stages, waiting for its timers); GPU = its span from the first stage's "
            "start to\n"
            "shading's end; read back = copying one finished frame to host memory (hc-render's path, not the "
            "viewer's)\n");
        for (size_t k = 0; k < results.size(); ++k)
            std::printf("  %-14s total %7.2f ms   GPU %7.2f ms   CPU and waiting %7.2f ms   read back %7.2f ms\n",
                        chosen[k]->name, results[k].totalMs, results[k].gpuMs, results[k].totalMs - results[k].gpuMs,
                        results[k].readbackMs);
    }
    std::printf(
        "\ncascades (best approximation frame): offsets along the view [m], texel [m], visible texels, Gaussians, "
        "ms\n");
    for (size_t k = 0; k < results.size(); ++k) {
        const RunResult& r = results[k];
        for (int c = 0; c < r.cascadeCount; ++c) {
            const CascadeOut& cs = r.cascades[c];
            std::printf("  %-14s %d  %8.0f..%-8.0f %8.3g %9llu %11llu %8.1f", chosen[k]->name, c, cs.nearM, cs.farM,
                        cs.texelM, (unsigned long long)cs.visibleTexels, (unsigned long long)cs.gaussians,
                        cs.approximationMs);
            if (cs.pyramidLevel >= 0)
                std::printf("   %llu copied from pyramid level %d", (unsigned long long)cs.pyramidTexels,
                            cs.pyramidLevel);
            if (cs.pyramidInterpolated) std::printf(", %llu interpolated", (unsigned long long)cs.pyramidInterpolated);
            std::printf("\n");
        }
        if (r.pyramid)
            std::printf(
                "  %-14s    surface pyramid built in %.1f s (not part of a frame), %.1f MB = %.1f bytes per cell\n",
                chosen[k]->name, r.pyramidMs / 1e3, mb(r.pyramidBytes), double(r.pyramidBytes) / double(r.cells));
        if (set.accuracy)
            std::printf(
                "  %-14s    rendered error (terrain hits vs exact surface, %llu hits): max %.3g m, p99 %.3g m, RMS "
                "%.3g m\n",
                chosen[k]->name, (unsigned long long)r.accuracySamples, r.accuracyMaxM, r.accuracyP99M, r.accuracyRmsM);
        std::printf("  %-14s    hits %.1f %% of pixels, water %.1f %%; camera %.0f, %.0f, %.0f yaw %.1f\n",
                    chosen[k]->name, 100.0 * double(r.hits) / double(r.rays),
                    100.0 * double(r.wetHits) / double(r.rays), r.camera[0], r.camera[1], r.camera[2], r.camera[3]);
    }

    if (set.flyFrames > 1) {
        std::printf(
            "\nincremental cascades: the camera flies forward %g m a frame for %d frames; means over frames "
            "2..%d,\n"
            "every frame evaluated afresh against frames through a CascadeCache (texels kept from the last "
            "frame);\n"
            "cells = grid cells the approximation visited per frame\n\n",
            set.flyStepM, set.flyFrames, set.flyFrames);
        std::printf("%-14s %16s %16s %6s %14s %14s %14s %12s %12s\n", "scenario", "approx ms fresh", "approx ms cache",
                    "x", "frame ms fresh", "frame ms cache", "texels kept %", "cells fresh", "cells cache");
        for (size_t k = 0; k < results.size(); ++k) {
            const RunResult& r = results[k];
            std::printf("%-14s %16.1f %16.1f %6.1f %14.1f %14.1f %14.1f %12.0f %12.0f\n", chosen[k]->name,
                        r.flyApproxFreshMs, r.flyApproxCachedMs,
                        r.flyApproxCachedMs > 0 ? r.flyApproxFreshMs / r.flyApproxCachedMs : 0.0, r.flyTotalFreshMs,
                        r.flyTotalCachedMs, 100 * r.flyKept, r.flyCellsFresh, r.flyCellsCached);
        }
        bool uploads = false;
        for (const RunResult& r : results) uploads = uploads || r.flyUploadFreshMB > 0;
        if (uploads) {  // the GL backend: the cascades' rows and (out of core) the texels the CPU evaluated
                        // (Timings::uploadMs)
            std::printf("\n%-14s %16s %16s %16s %16s\n", "GL upload", "ms fresh", "ms cache", "MB fresh", "MB cache");
            for (size_t k = 0; k < results.size(); ++k) {
                const RunResult& r = results[k];
                std::printf("%-14s %16.2f %16.2f %16.2f %16.3f\n", chosen[k]->name, r.flyUploadFreshMs,
                            r.flyUploadCachedMs, r.flyUploadFreshMB, r.flyUploadCachedMB);
            }
        }
    }

    // ---- targets ----
    const bool glRun = set.backend == hc::cli::Backend::Gl;
    std::printf("\ntargets%s\n", glRun ? "" : " (2 cores)");
    if (glRun) {
        std::printf("  GL whole frame (issue 5, on a GPU): 1920x1080, 3 x 1024^2 cascades, within %.0f ms%s\n",
                    kTargetGlFrameMs, set.width == 1920 && set.height == 1080 ? "" : " (this run is another size)");
        for (size_t k = 0; k < results.size(); ++k)
            std::printf("    %-14s %8.2f ms   %s\n", chosen[k]->name, results[k].totalMs,
                        glFrameMet(results[k]) ? "met" : "MISSED");
    }
    std::printf("  approximation: >= %.0f G Gaussians/s\n", kTargetGaussiansPerS / 1e9);
    for (size_t k = 0; k < results.size(); ++k)
        std::printf("    %-14s %7.3f G Gaussians/s (%5.1f %% of the target), %8.1f ms vs GTX 1080 %5.1f ms   %s\n",
                    chosen[k]->name, gaussiansPerS(results[k]) / 1e9,
                    100 * gaussiansPerS(results[k]) / kTargetGaussiansPerS, results[k].approximationMs,
                    chosen[k]->gpuApproxMs, approximationMet(results[k]) ? "met" : "MISSED");
    if (set.width == 1920 && set.height == 1080)
        std::printf("  ray casting: 1920x1080 within %.0f ms\n", kTargetRaycastMs);
    else
        std::printf("  ray casting: >= %.2f M rays/s (1920x1080 within %.0f ms; this run is %dx%d)\n",
                    kTargetRaysPerS / 1e6, kTargetRaycastMs, set.width, set.height);
    for (size_t k = 0; k < results.size(); ++k)
        std::printf("    %-14s %8.1f ms, %6.2f M rays/s (%5.1f %% of the target rate), vs GTX 1080 %4.1f ms   %s\n",
                    chosen[k]->name, results[k].raycastMs, raysPerS(results[k]) / 1e6,
                    100 * raysPerS(results[k]) / kTargetRaysPerS, chosen[k]->gpuRaycastMs,
                    raycastMet(results[k]) ? "met" : "MISSED");

    for (size_t k = 0; k < results.size(); ++k)
        if (results[k].image[0]) std::printf("\nimage: %s", results[k].image);
    std::printf("%swall time %.1f s; load average (1 min) at the end: %s\n", set.imagesDir.empty() ? "\n" : "\n\n",
                wallS, loadAverage().c_str());
}

void writePlot(const std::vector<const Scenario*>& chosen, const std::vector<RunResult>& results, const Settings& set,
               const std::string& sizeText, const std::string& plot) {
    if (!plot.empty()) {
        const bool gl = set.backend == hc::cli::Backend::Gl;
        hc::bench::BarPlot bp;
        bp.title = std::string("hc-bench, ") + (gl ? "GL" : "CPU") + " backend: best stage times of a " +
                   std::to_string(set.width) + "x" + std::to_string(set.height) + " frame, " +
                   std::to_string(set.options.cascades) + " cascades of " + std::to_string(set.options.texelsPerSide) +
                   "^2" + (set.cells > 0 || set.scale != 1 ? ", " + sizeText : "");
        bp.xLabel = "milliseconds";
        // Ray casting first, so its bar ends where the ray casting target's line can meet it.
        bp.segmentNames = {"ray casting", "approximation", "mipmaps", "shading", "fitting"};
        for (size_t k = 0; k < results.size(); ++k) {
            const RunResult& r = results[k];
            if (r.totalMs >= 1e300) continue;  // the scenario failed
            bp.rows.push_back(
                {chosen[k]->name, {r.raycastMs, r.approximationMs, r.mipmapMs, r.shadingMs, r.fittingMs}});
        }
        if (gl)
            bp.markers.push_back(
                {"whole-frame target " + fmt::format("{:g}", kTargetGlFrameMs) + " ms", kTargetGlFrameMs});
        else if (set.width == 1920 && set.height == 1080)
            bp.markers.push_back({"ray casting target " + fmt::format("{:g}", kTargetRaycastMs) + " ms (first segment)",
                                  kTargetRaycastMs});
        if (!bp.rows.empty()) {
            hc::bench::writeSvg(plot, bp.svg());
            std::printf("plot written to %s\n", plot.c_str());
        }
    }
}

}  // namespace hc::bench
