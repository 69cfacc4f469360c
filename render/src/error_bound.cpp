// render/src/error_bound.cpp: what error a frame carries. Before the frame: the error of each pyramid level's bilinear
// patches (Scene::levelErrorM), which the cascades' fit reads to meet an error budget (cascades.cpp); after it, the
// bound of each cascade and of the frame (boundFrame), from the pyramid or, without one, from the texels' own estimate
// (gpu::patchErrorEstimateM), which without a pyramid also predicts each level's error for a budget's fit
// (predictLevelErrorM). The error measured at a frame's hits is verify_error.cpp's.
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>
#include <vector>

#include "heightcast/core/parallel.h"
#include "heightcast/influence/region.h"
#include "heightcast/render/detail/frame.h"
#include "heightcast/render/renderer.h"

namespace hc::render {

void Scene::boundLevels() {
    levelErrorM_.clear();
    if (!pyramid_) return;
    terrainErrors_ = influence::RegionalLevelErrors(*pyramid_, influence::PyramidChannel::Elevation);
    if (hasWater())  // the water surface is drawn from the water level's samples: the larger of the two errors
        waterErrors_ = influence::RegionalLevelErrors(waterPyramid_ ? *waterPyramid_ : *pyramid_,
                                                      influence::PyramidChannel::WaterLevel);
    roundingErrorM_ = 2 * detail::pyramidCopyBoundM(*this);  // the samples' float32 rounding, the heights' in the patch
    const double domain = grid_.domainSizeM();
    levelErrorM_ = levelErrorM(0, 0, domain, domain);
}

int Scene::reliefRegionAt(double x) const {
    return std::clamp(int(std::floor(x / reliefRegionM_)), 0, reliefSide_ - 1);
}

void Scene::boundRelief() {
    if (pyramid_ || outOfCore()) return;
    const int side = 1 << influence::RegionalLevelErrors::kRegionsLog2;
    reliefSide_ = side, reliefRegionM_ = grid_.domainSizeM() / side;
    reliefMin_.assign(size_t(side) * size_t(side), HUGE_VALF);
    reliefMax_.assign(size_t(side) * size_t(side), -HUGE_VALF);
    for (size_t c = 0; c < grid_.cellCount(); ++c) {
        const CellKernel& k = kernels_[c];
        const double r = std::sqrt(double(k.r2));
        const float z = grid_.values[0][c];
        const float d = waterLayer_ >= 0 ? grid_.values[size_t(waterLayer_)][c] : 0.0f;
        const float top = d > 0 ? z + d : z;  // a wet cell's water level too
        for (int j = reliefRegionAt(k.cy - r); j <= reliefRegionAt(k.cy + r); ++j)
            for (int i = reliefRegionAt(k.cx - r); i <= reliefRegionAt(k.cx + r); ++i) {
                const size_t g = size_t(j) * size_t(side) + size_t(i);
                reliefMin_[g] = std::min(reliefMin_[g], z), reliefMax_[g] = std::max(reliefMax_[g], top);
            }
    }
}

double Scene::reliefM(double x0, double y0, double x1, double y1, double spanM) const {
    if (reliefSide_ == 0) return zMax - zMin;
    const int side = reliefSide_, k = int(std::ceil(spanM / reliefRegionM_));
    const int i0 = reliefRegionAt(x0), i1 = reliefRegionAt(x1), j0 = reliefRegionAt(y0), j1 = reliefRegionAt(y1),
              jEnd = std::min(side - 1, j1 + k);
    // A square with its corner in region (i, j) lies in regions i .. i + k, j .. j + k: their extremes, rows first.
    const size_t w = size_t(i1 - i0 + 1);
    std::vector<float> rowMin(w * size_t(jEnd - j0 + 1)), rowMax(rowMin.size());
    for (int j = j0; j <= jEnd; ++j)
        for (int i = i0; i <= i1; ++i) {
            float lo = HUGE_VALF, hi = -HUGE_VALF;
            for (int a = i; a <= std::min(side - 1, i + k); ++a) {
                const size_t r = size_t(j) * size_t(side) + size_t(a);
                lo = std::min(lo, reliefMin_[r]), hi = std::max(hi, reliefMax_[r]);
            }
            rowMin[size_t(j - j0) * w + size_t(i - i0)] = lo, rowMax[size_t(j - j0) * w + size_t(i - i0)] = hi;
        }
    double relief = 0;
    for (int j = j0; j <= j1; ++j)
        for (int i = i0; i <= i1; ++i) {
            float lo = HUGE_VALF, hi = -HUGE_VALF;
            for (int b = j; b <= std::min(jEnd, j + k); ++b)
                lo = std::min(lo, rowMin[size_t(b - j0) * w + size_t(i - i0)]),
                hi = std::max(hi, rowMax[size_t(b - j0) * w + size_t(i - i0)]);
            if (hi >= lo) relief = std::max(relief, double(hi) - double(lo));
        }
    return relief;
}

std::vector<double> Scene::levelErrorM(double x0, double y0, double x1, double y1) const {
    if (terrainErrors_.empty()) return {};
    std::vector<double> e = terrainErrors_.byLevelM(x0, y0, x1, y1);
    if (!waterErrors_.empty()) {
        const std::vector<double> water = waterErrors_.byLevelM(x0, y0, x1, y1);
        for (size_t t = 0; t < std::min(water.size(), e.size()); ++t) e[t] = std::max(e[t], water[t]);
    }
    for (double& v : e) v += roundingErrorM_;
    return e;
}

namespace {

// The coarsest texel spacing that resolves the surface: the kernels' width at the finest cell [m].
double resolvedSpacingM(const Scene& scene) { return scene.params().sigma * scene.grid().finestCellM; }

// Without a pyramid, the error of patches of spacing s over the box [x0, x1] x [y0, y1] of a cascade's polygon: the
// relief under them (Scene::reliefM) bounds it; where the texels resolve the surface, their estimate (`estimateM`:
// CascadeStats::texelEstimateM, or predictLevelErrorM's) gives it where that is less. Coarser, a feature of the finest
// cells can lie between samples unseen: the relief alone.
double texelPatchErrorM(const Scene& scene, double x0, double y0, double x1, double y1, double s, double estimateM) {
    // The texels lie within 1.5 texels of the polygon (Cascade::rows), their patches' corners too.
    const double relief = scene.reliefM(x0 - 2 * s, y0 - 2 * s, x1 + 2 * s, y1 + 2 * s, s);
    return s <= resolvedSpacingM(scene) ? std::min(estimateM, relief) : relief;
}

// The same for cascade c's patches, over its polygon's box.
double texelPatchErrorM(const Scene& scene, const Cascade& c, double estimateM) {
    double x0 = HUGE_VAL, y0 = HUGE_VAL, x1 = -HUGE_VAL, y1 = -HUGE_VAL;
    for (const glm::dvec2& p : c.polygon)
        x0 = std::min(x0, p.x), y0 = std::min(y0, p.y), x1 = std::max(x1, p.x), y1 = std::max(y1, p.y);
    return texelPatchErrorM(scene, x0, y0, x1, y1, c.texelM, estimateM);
}

// What a frame of texels summed from the kernels adds to its patches' error: float32 rounding and the sum's error [m].
double summedTexelsErrorM(const Scene& scene) { return 2 * detail::pyramidCopyBoundM(scene) + kSummedTexelErrorM; }

}  // namespace

std::vector<double> detail::predictLevelErrorM(const Scene& scene, double x0, double y0, double x1, double y1,
                                               double waterMinDepthM, unsigned threads) {
    // The probe: the box's surface at one spacing on the ladder of powers of two of the finest cell, the coarsest that
    // resolves it (resolvedSpacingM), or coarser where that takes more than kProbeSide texels a side.
    constexpr int kProbeSide = 256;
    // The probe's estimate, scaled, fell short of the texels' own by up to 1.37x on the bundled and test DEMs (a finer
    // spacing sees features the probe's smooths): taken twice.
    constexpr double kPredictionMargin = 2.0;
    const double finest = scene.grid().finestCellM, resolvedM = resolvedSpacingM(scene);
    const double extent = std::max({x1 - x0, y1 - y0, finest});
    int probeLevel = int(std::floor(std::log2(resolvedM / finest) + 1e-9));
    while (std::ceil(extent / std::ldexp(finest, probeLevel)) + 3 > kProbeSide) ++probeLevel;
    Cascade probe;
    probe.texelM = std::ldexp(finest, probeLevel);
    probe.n = int(std::ceil(extent / probe.texelM)) + 3;
    probe.x0 = (std::floor(x0 / probe.texelM) - 1) * probe.texelM;
    probe.y0 = (std::floor(y0 / probe.texelM) - 1) * probe.texelM;
    probe.polygon = {{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}};
    probe.rows.assign(size_t(probe.n), Cascade::RowSpan{0, probe.n - 1});
    CascadeTextures tex;
    approximate(scene, probe, tex, waterMinDepthM, threads);
    tex.extendWaterToShores(threads);  // as approximateCascades() before its estimate
    const double probeM = tex.errorEstimateM(threads);
    // Level t's patches as boundFrame will bound them, with the probe's estimate scaled with the square of the spacing.
    std::vector<double> levels;
    for (int t = 0;; ++t) {
        const double s = std::ldexp(finest, t), ratio = s / probe.texelM;
        levels.push_back(texelPatchErrorM(scene, x0, y0, x1, y1, s, kPredictionMargin * probeM * ratio * ratio) +
                         summedTexelsErrorM(scene));
        if (s >= extent) return levels;
    }
}

void detail::measureNearestHits(const Frame& f, unsigned threads, Timings& timings) {
    const size_t cascades = timings.cascades.size(), pixels = f.distanceM.size(), chunk = 1 << 16;
    std::vector<std::vector<float>> nearest(resolveThreads(threads),
                                            std::vector<float>(cascades, std::numeric_limits<float>::infinity()));
    parallelFor(pixels, chunk, threads, [&](size_t b, size_t e, unsigned worker) {
        std::vector<float>& mine = nearest[worker];
        for (size_t i = b; i < e; ++i) {
            const float k = f.cascade[i];  // -1: a miss
            if (k >= 0 && size_t(k) < cascades) mine[size_t(k)] = std::min(mine[size_t(k)], f.distanceM[i]);
        }
    });
    for (size_t k = 0; k < cascades; ++k) {
        timings.cascades[k].nearestHitM = HUGE_VAL;
        for (const std::vector<float>& mine : nearest)
            timings.cascades[k].nearestHitM = std::min(timings.cascades[k].nearestHitM, double(mine[k]));
    }
}

namespace {

// Where cascade k's bound in pixels is charged [m]: the nearest hit that shows its surface, its own or a blend's
// labelled with the cascade before it (Frame::cascade names the nearer of the two), never nearer than the fit's bound
// of its slab (Cascade::nearestM), which is all there is where the hits were not measured.
double pixelBoundDistanceM(const CascadeFit& fit, size_t k, const Timings& timings) {
    const double fitted = fit.cascades[k].nearestM;
    const double own = timings.cascades[k].nearestHitM, before = k > 0 ? timings.cascades[k - 1].nearestHitM : HUGE_VAL;
    if (std::isnan(own) || std::isnan(before)) return fitted;
    return std::max(fitted, std::min(own, before));
}

}  // namespace

void detail::boundFrame(const Scene& scene, const FrameSetup& setup, const CascadeFit& fit, Timings& timings) {
    const bool fromPyramid = !scene.boundFromTexels();
    timings.boundFromTexels = !fromPyramid;
    timings.errorBoundM = timings.errorBoundPx = timings.shoreBoundM = timings.shoreBoundPx = 0.0;
    bool unbounded = false;
    for (size_t k = 0; k < fit.cascades.size() && k < timings.cascades.size(); ++k) {
        const Cascade& c = fit.cascades[k];
        CascadeStats& cs = timings.cascades[k];
        cs.budgetM = c.budgetM;
        if (c.empty()) {
            cs.errorBoundM = cs.errorBoundPx = 0;
            continue;
        }
        if (fromPyramid) {
            // Over the cascade's polygon (placeTexture); the whole domain's for a cascade fitted without them.
            const std::vector<double>& levels = c.levelErrorM.empty() ? scene.levelErrorM() : c.levelErrorM;
            // The patches' error at the texel spacing, plus, where texels were interpolated from a coarser level, that
            // level's (the interpolation is tested to lie within a bilinear patch's error at the source's spacing).
            // Off the pyramid's ladder (the GL backend in memory) the spacing lies between two levels: the coarser's.
            const int level = int(std::ceil(std::log2(c.texelM / scene.grid().finestCellM) - 1e-9));
            const int up = cs.pyramidInterpolated > 0 ? cs.pyramidInterpolatedUp : 0;
            cs.errorBoundM = levelErrorM(levels, level) + (up > 0 ? levelErrorM(levels, level + up) : 0.0) +
                             (cs.gaussians > 0 ? kSummedTexelErrorM : 0.0);
        } else {  // every texel summed from the kernels: their patches' error, float32 rounding and the sum's error
            cs.errorBoundM = texelPatchErrorM(scene, c, cs.texelEstimateM) + summedTexelsErrorM(scene);
        }
        const double footprintM = setup.view.pixelRad * pixelBoundDistanceM(fit, k, timings);  // a pixel's, there
        cs.errorBoundPx = cs.errorBoundM / footprintM;
        if (scene.hasWater()) {  // Timings::shoreBoundM
            const int up = cs.pyramidInterpolated > 0 ? cs.pyramidInterpolatedUp : 0;
            const double shoreM = std::numbers::sqrt2 * std::ldexp(c.texelM, up);
            timings.shoreBoundM = std::max(timings.shoreBoundM, shoreM);
            timings.shoreBoundPx = std::max(timings.shoreBoundPx, shoreM / footprintM);
        }
        unbounded = unbounded || !std::isfinite(cs.errorBoundM);  // no estimate made (a bug): no bound claimed
        timings.errorBoundM = std::max(timings.errorBoundM, cs.errorBoundM);
        timings.errorBoundPx = std::max(timings.errorBoundPx, cs.errorBoundPx);
    }
    if (unbounded) timings.errorBoundM = timings.errorBoundPx = std::numeric_limits<double>::quiet_NaN();
}

}  // namespace hc::render
