// render/src/timings.cpp: Timings (renderer.h) written out: as JSON (hc-render's timings file) and as the table
// hc-render and hc-view print.
#include <cmath>
#include <cstdio>
#include <string>
#include <utility>

#include <nlohmann/json.hpp>

#include "heightcast/core/rounded.h"
#include "heightcast/render/renderer.h"

namespace hc::render {

namespace {
// Milliseconds to the microsecond, metres to the millimetre.
double threeDecimals(double v) { return rounded(v, std::chars_format::fixed, 3); }
// A bound to three significant digits; null where there is none (no surface pyramid).
nlohmann::ordered_json bound(double v) {
    return std::isfinite(v) ? nlohmann::ordered_json(rounded(v, std::chars_format::general, 3))
                            : nlohmann::ordered_json(nullptr);
}
}  // namespace

std::string Timings::toJson() const {
    using Json = nlohmann::ordered_json;  // keys in the order written
    Json j;
    j["fitting_ms"] = threeDecimals(fittingMs);
    j["approximation_ms"] = threeDecimals(approximationMs);
    j["mipmap_ms"] = threeDecimals(mipmapMs);
    j["raycast_ms"] = threeDecimals(raycastMs);
    j["shading_ms"] = threeDecimals(shadingMs);
    j["total_ms"] = threeDecimals(totalMs);
    j["gpu_ms"] = threeDecimals(gpuMs);
    j["readback_ms"] = threeDecimals(readbackMs);
    j["upload_ms"] = threeDecimals(uploadMs);
    j["upload_bytes"] = uploadBytes;
    j["atlas_texels"] = atlasTexels;
    j["atlas_tiles_uploaded"] = atlasTilesUploaded;
    j["atlas_interpolated"] = atlasInterpolated;
    j["rays"] = rays;
    j["hits"] = hits;
    j["error_bound_m"] = bound(errorBoundM);
    j["error_bound_px"] = bound(errorBoundPx);
    j["error_bound_from"] = boundFromTexels ? "texels" : "pyramid";
    if (shoreBoundM > 0) {
        j["shore_bound_m"] = bound(shoreBoundM);
        j["shore_bound_px"] = bound(shoreBoundPx);
    }
    j["max_error_m"] = maxErrorM;
    j["max_error_px"] = maxErrorPx;
    if (!notes.empty()) j["notes"] = notes;
    if (verified)
        j["verified"] = {{"hits", verified->hits},
                         {"max_m", rounded(verified->maxM, std::chars_format::general, 4)},
                         {"p99_m", rounded(verified->p99M, std::chars_format::general, 4)},
                         {"median_m", rounded(verified->medianM, std::chars_format::general, 4)},
                         {"max_px", rounded(verified->maxPx, std::chars_format::general, 4)}};
    if (verified && verified->water) {
        j["verified"]["drawn_dry_over_water"] = verified->drawnDryOverWater;
        j["verified"]["drawn_wet_over_dry"] = verified->drawnWetOverDry;
        j["verified"]["shore_max_m"] = rounded(verified->shoreMaxM, std::chars_format::general, 4);
        j["verified"]["shore_distance_m"] = rounded(verified->shoreDistanceM, std::chars_format::general, 4);
        j["verified"]["shore_distance_px"] = rounded(verified->shoreDistancePx, std::chars_format::general, 4);
    }
    j["cascades"] = Json::array();
    for (size_t k = 0; k < cascades.size(); ++k) {
        const CascadeStats& c = cascades[k];
        j["cascades"].push_back({{"index", k},
                                 {"near_m", threeDecimals(c.nearM)},
                                 {"far_m", threeDecimals(c.farM)},
                                 {"texel_m", rounded(c.texelM, std::chars_format::general, 6)},
                                 {"visible_texels", c.visibleTexels},
                                 {"reused_texels", c.reusedTexels},
                                 {"pyramid_level", c.pyramidLevel},
                                 {"pyramid_texels", c.pyramidTexels},
                                 {"pyramid_interpolated", c.pyramidInterpolated},
                                 {"pyramid_interpolated_levels_up", c.pyramidInterpolatedUp},
                                 {"error_bound_m", bound(c.errorBoundM)},
                                 {"error_bound_px", bound(c.errorBoundPx)},
                                 {"nearest_hit_m", bound(c.nearestHitM)},
                                 {"budget_m", bound(c.budgetM)},
                                 {"texel_estimate_m", bound(c.texelEstimateM)},
                                 {"gaussians", c.gaussians},
                                 {"cells_visited", c.cellsVisited},
                                 {"cells_read", c.cellsRead},
                                 {"regions_read", c.regionsRead},
                                 {"approximation_ms", threeDecimals(c.approximationMs)}});
    }
    return j.dump(2) + "\n";
}

std::string Timings::toTable() const {
    char b[256];
    std::string s = "stage timings (ms):\n";
    std::snprintf(b, sizeof b, "  fitting         %9.2f\n  approximation   %9.2f\n", fittingMs, approximationMs);
    s += b;
    for (size_t k = 0; k < cascades.size(); ++k) {
        const CascadeStats& c = cascades[k];
        std::snprintf(
            b, sizeof b,
            "    cascade %zu     %9.2f   offsets %.0f..%.0f m, texel %.3g m, %llu visible texels, %llu Gaussians", k,
            c.approximationMs, c.nearM, c.farM, c.texelM, (unsigned long long)c.visibleTexels,
            (unsigned long long)c.gaussians);
        s += b;
        if (c.cellsVisited) {
            std::snprintf(b, sizeof b, ", %llu cells visited", (unsigned long long)c.cellsVisited);
            s += b;
        }
        if (c.regionsRead) {
            std::snprintf(b, sizeof b, ", %llu cells read from the grid file in %llu blocks",
                          (unsigned long long)c.cellsRead, (unsigned long long)c.regionsRead);
            s += b;
        }
        if (c.reusedTexels) {
            std::snprintf(b, sizeof b, " (%llu texels kept from the last frame)", (unsigned long long)c.reusedTexels);
            s += b;
        }
        if (c.pyramidLevel >= 0) {
            std::snprintf(b, sizeof b, ", %llu copied from pyramid level %d", (unsigned long long)c.pyramidTexels,
                          c.pyramidLevel);
            s += b;
        }
        if (c.pyramidInterpolated) {
            std::snprintf(b, sizeof b, ", %llu interpolated from up to %d level%s above",
                          (unsigned long long)c.pyramidInterpolated, c.pyramidInterpolatedUp,
                          c.pyramidInterpolatedUp == 1 ? "" : "s");
            s += b;
        }
        if (std::isfinite(c.errorBoundM)) {
            std::snprintf(b, sizeof b, "; within %.3g m (%.2g px)", c.errorBoundM, c.errorBoundPx);
            s += b;
            if (c.budgetM > 0 && c.errorBoundM > c.budgetM) {
                std::snprintf(b, sizeof b, ", over its budget of %.3g m by %.3g m (%s)", c.budgetM,
                              c.errorBoundM - c.budgetM,
                              boundFromTexels ? "no surface pyramid to choose its texel size by"
                                              : "its texels are capped at twice --texels a side, and none is finer "
                                                "than the finest cell");
                s += b;
            }
        }
        s += "\n";
    }
    std::snprintf(b, sizeof b,
                  "  mipmaps         %9.2f\n  ray casting     %9.2f   %llu rays, %llu hits\n  shading         %9.2f\n  "
                  "total           %9.2f\n",
                  mipmapMs, raycastMs, (unsigned long long)rays, (unsigned long long)hits, shadingMs, totalMs);
    s += b;
    if (std::isfinite(errorBoundM)) {
        std::snprintf(b, sizeof b, "accuracy: within %.3g m of the exact surface, %.3g px at the worst texel%s",
                      errorBoundM, errorBoundPx,
                      boundFromTexels
                          ? ", from the texels and the relief under them (no surface pyramid: hc-influence writes one)"
                          : "");
        s += b;
    } else {
        s += "accuracy: no bound claimed";
    }
    std::string budget;
    for (const auto& [v, unit] : {std::pair{maxErrorM, " m"}, std::pair{maxErrorPx, " px"}})
        if (v > 0) {
            std::snprintf(b, sizeof b, "%s%.3g%s", budget.empty() ? " (budget " : ", ", v, unit);
            budget += b;
        }
    s += budget.empty() ? "" : budget + ")";
    if (shoreBoundM > 0) {
        std::snprintf(b, sizeof b, "; the shoreline within %.3g m (%.2g px)", shoreBoundM, shoreBoundPx);
        s += b;
    }
    s += "\n";
    for (const std::string& n : notes) s += "note: " + n + "\n";
    if (gpuMs > 0 || readbackMs > 0) {
        std::snprintf(b, sizeof b,
                      "    GPU span      %9.2f   first stage's start to shading's end\n    read back     %9.2f   the "
                      "frame to host memory\n",
                      gpuMs, readbackMs);
        s += b;
    }
    if (uploadMs > 0) {
        std::snprintf(b, sizeof b, "    upload        %9.2f   the rows and new texels, to the GPU: %.2f MB\n", uploadMs,
                      double(uploadBytes) / 1e6);
        s += b;
    }
    if (atlasTexels > 0) {
        std::snprintf(
            b, sizeof b,
            "    pyramid tiles           %llu texels copied on the GPU from its tiles there (%llu tiles uploaded)\n",
            (unsigned long long)atlasTexels, (unsigned long long)atlasTilesUploaded);
        s += b;
    }
    if (atlasInterpolated > 0) {
        std::snprintf(b, sizeof b,
                      "    pyramid tiles           %llu texels interpolated on the GPU from level 0's tiles there\n",
                      (unsigned long long)atlasInterpolated);
        s += b;
    }
    return s;
}

}  // namespace hc::render
