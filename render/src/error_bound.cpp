// render/src/error_bound.cpp: what error a frame carries. Before the frame: the error of each pyramid level's bilinear
// patches (Scene::levelErrorM), which the cascades' fit reads to meet an error budget (cascades.cpp); after it, the
// bound of each cascade and of the frame (boundFrame); and the error measured at the frame's hits against the exact
// surface (verifyFrameError).
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <optional>
#include <vector>

#include "heightcast/core/quantile.h"
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

void detail::boundFrame(const Scene& scene, const FrameSetup& setup, const CascadeFit& fit, Timings& timings) {
    const bool bounded = !scene.levelErrorM().empty();
    const double nan = std::numeric_limits<double>::quiet_NaN();
    timings.errorBoundM = timings.errorBoundPx = bounded ? 0.0 : nan;
    for (size_t k = 0; k < fit.cascades.size() && k < timings.cascades.size(); ++k) {
        const Cascade& c = fit.cascades[k];
        CascadeStats& cs = timings.cascades[k];
        cs.budgetM = c.budgetM;
        if (!bounded) {
            cs.errorBoundM = cs.errorBoundPx = nan;
            continue;
        }
        if (c.empty()) {
            cs.errorBoundM = cs.errorBoundPx = 0;
            continue;
        }
        // Over the cascade's polygon (placeTexture); the whole domain's for a cascade fitted without them.
        const std::vector<double>& levels = c.levelErrorM.empty() ? scene.levelErrorM() : c.levelErrorM;
        // The patches' error at the texel spacing, plus, where texels were interpolated from a coarser level, that
        // level's (the interpolation is tested to lie within a bilinear patch's error at the source's spacing).
        // Off the pyramid's ladder (the GL backend in memory) the spacing lies between two levels: the coarser's error.
        const int level = int(std::ceil(std::log2(c.texelM / scene.grid().finestCellM) - 1e-9));
        const int up = cs.pyramidInterpolated > 0 ? cs.pyramidInterpolatedUp : 0;
        cs.errorBoundM = levelErrorM(levels, level) + (up > 0 ? levelErrorM(levels, level + up) : 0.0) +
                         (cs.gaussians > 0 ? kSummedTexelErrorM : 0.0);
        cs.errorBoundPx = cs.errorBoundM / (setup.view.pixelRad * c.nearestM);
        timings.errorBoundM = std::max(timings.errorBoundM, cs.errorBoundM);
        timings.errorBoundPx = std::max(timings.errorBoundPx, cs.errorBoundPx);
    }
}

namespace {

// The hits to check: every hit off the walls, or `samples` of them spread evenly.
std::vector<size_t> hitsToCheck(const Frame& f, size_t samples) {
    std::vector<size_t> hits;
    for (size_t i = 0; i < f.distanceM.size(); ++i)
        if (std::isfinite(f.distanceM[i]) && !(i < f.wall.size() && f.wall[i] != 0)) hits.push_back(i);
    if (hits.size() <= samples) return hits;
    std::vector<size_t> picked(samples);
    for (size_t k = 0; k < samples; ++k) picked[k] = hits[(k * hits.size()) / samples];
    return picked;
}

// The exact layer at local points: over the grid and its lists in memory, else from the file around the points.
std::vector<std::optional<double>> exactValues(const Scene& scene, const std::vector<std::array<double, 2>>& pts,
                                               const influence::Layer& layer, unsigned threads) {
    if (scene.outOfCore()) return influence::valuesFromFile(*scene.file(), pts, layer, scene.params(), threads);
    return scene.evaluator().values(pts, layer, threads);
}

}  // namespace

ErrorCheck verifyFrameError(const Scene& scene, const Camera& camera, const Frame& f, size_t samples,
                            unsigned threads) {
    const std::vector<size_t> hits = hitsToCheck(f, samples);
    const Grid& grid = scene.grid();
    std::vector<std::array<double, 2>> dry, wet;
    std::vector<size_t> dryAt, wetAt;
    for (const size_t i : hits) {
        std::array<double, 2> p{};
        grid.worldToLocal(f.originWorldX + f.posX[i], f.originWorldY + f.posY[i], p[0], p[1]);
        const bool water = i < f.waterDepthM.size() && f.waterDepthM[i] > 0;
        (water ? wet : dry).push_back(p);
        (water ? wetAt : dryAt).push_back(i);
    }
    ErrorCheck check;
    std::vector<double> errors;
    const double pixelRad = detail::setUpFrame(scene, camera).view.pixelRad;
    auto compare = [&](const std::vector<std::array<double, 2>>& pts, const std::vector<size_t>& at, const char* name) {
        if (pts.empty()) return;
        const std::vector<std::optional<double>> exact =
            exactValues(scene, pts, influence::Layer::byName(grid, name), threads);
        for (size_t k = 0; k < pts.size(); ++k) {
            if (!exact[k]) continue;  // a hit on a patch over a hole's edge: no exact surface there to compare with
            const double e = std::abs(double(f.posZ[at[k]]) - *exact[k]);
            errors.push_back(e);
            check.maxPx = std::max(check.maxPx, e / (pixelRad * double(f.distanceM[at[k]])));
        }
    };
    compare(dry, dryAt, "elevation");
    compare(wet, wetAt, "water_surface");
    check.hits = errors.size();
    check.maxM = errors.empty() ? 0 : *std::max_element(errors.begin(), errors.end());
    check.p99M = quantile(errors, 0.99);
    check.medianM = quantile(errors, 0.5);
    return check;
}

}  // namespace hc::render
