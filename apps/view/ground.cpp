// apps/view/ground.cpp: the terrain under the viewer's camera (see ground.h).
#include "view/ground.h"

#include <algorithm>
#include <cmath>

namespace hc::view {

Ground::Ground(const cli::LoadedScene& loaded)
    : loaded_(loaded), evaluator_(loaded.grid, loaded.lists), elevation_(influence::Layer::byName(loaded.grid, "elevation")) {}

std::optional<double> Ground::elevationAt(double xWorld, double yWorld) const {
    return evaluator_.value(xWorld - loaded_.grid.originWorldX, yWorld - loaded_.grid.originWorldY, elevation_);
}

std::optional<double> Ground::heightAboveGround(const render::Camera& c) const {
    auto g = elevationAt(c.xWorld, c.yWorld);
    return g ? std::optional<double>(c.zWorld - *g) : std::nullopt;
}

double Ground::heightAboveGroundOr(const render::Camera& c, double fallback) const {
    auto h = heightAboveGround(c);
    return h ? std::max(std::abs(*h), 1.0) : fallback;
}

double Ground::aboveHighestM(const render::Camera& c) const { return c.zWorld - loaded_.scene->zMax; }

double Ground::speed(const render::Camera& c) const {
    auto h = heightAboveGround(c);
    const double height = h ? std::abs(*h) : aboveHighestM(c);
    return std::max({0.5 * height, 4 * loaded_.grid.finestCellM, 1.0});
}

std::array<double, 3> Ground::pickCentre(const render::Camera& c, double centreDistanceM) const {
    const render::CameraBasis b = render::basisOf(c);
    const auto& f = b.forward;
    auto along = [&](double t) { return std::array<double, 3>{c.xWorld + f[0] * t, c.yWorld + f[1] * t, c.zWorld + f[2] * t}; };
    if (std::isfinite(centreDistanceM)) return along(centreDistanceM);
    const render::Scene& scene = *loaded_.scene;
    const double diag = std::hypot(scene.xMax - scene.xMin, scene.yMax - scene.yMin, scene.zMax - scene.zMin);
    const double reach = diag + std::hypot(c.zWorld - scene.zMin, 1.0) * 4;
    const double step = std::max(reach / 2000, loaded_.grid.finestCellM * 0.5);
    auto below = [&](double t) {
        const auto p = along(t);
        auto g = elevationAt(p[0], p[1]);
        return g && p[2] <= *g;
    };
    double prevT = 0;
    for (double t = step; t < reach; t += step) {
        if (below(t)) {
            double lo = prevT, hi = t;  // bisect the crossing
            for (int k = 0; k < 20; ++k) {
                const double m = 0.5 * (lo + hi);
                if (below(m)) hi = m;
                else lo = m;
            }
            return along(hi);
        }
        prevT = t;
    }
    // No hit: orbit around a point in front, at the distance of the scene's centre.
    const double cx = loaded_.grid.originWorldX + 0.5 * (scene.xMin + scene.xMax);
    const double cy = loaded_.grid.originWorldY + 0.5 * (scene.yMin + scene.yMax);
    return along(std::max(std::hypot(cx - c.xWorld, cy - c.yWorld), 1.0));
}

double Ground::pivotDistance(const render::Camera& c, double centreDistanceM) const {
    const auto p = pickCentre(c, centreDistanceM);
    return std::max(std::hypot(p[0] - c.xWorld, p[1] - c.yWorld, p[2] - c.zWorld), 1.0);
}

}  // namespace hc::view
