// apps/view/ground.cpp: the terrain under the viewer's camera (see ground.h).
#include "view/ground.h"

#include <algorithm>
#include <cmath>

namespace hc::view {

Ground::Ground(const cli::LoadedScene& loaded) : loaded_(loaded) {
    if (!loaded.scene->outOfCore()) evaluator_.emplace(loaded.grid, loaded.lists);
}

std::optional<double> Ground::elevationAt(double xWorld, double yWorld) const {
    const Grid& g = loaded_.scene->grid();
    double x = 0, y = 0;
    g.worldToLocal(xWorld, yWorld, x, y);
    return evaluator_ ? evaluator_->value(x, y, elevation_) : loaded_.scene->terrainAt(x, y);
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
    return std::max({0.5 * height, 4 * loaded_.scene->grid().finestCellM, 1.0});
}

std::array<double, 3> Ground::pickCentre(const render::Camera& c, double centreDistanceM) const {
    const render::CameraBasis b = render::basisOf(c);
    const auto& f = b.forward;
    auto along = [&](double t) {
        return std::array<double, 3>{c.xWorld + f[0] * t, c.yWorld + f[1] * t, c.zWorld + f[2] * t};
    };
    if (std::isfinite(centreDistanceM)) return along(centreDistanceM);
    const render::Scene& scene = *loaded_.scene;
    const double diag = std::hypot(scene.xMax - scene.xMin, scene.yMax - scene.yMin, scene.zMax - scene.zMin);
    const double reach = diag + std::hypot(c.zWorld - scene.zMin, 1.0) * 4;
    // Out of core each probe reads the cells around its point (about a millisecond): 200 steps, not 2000.
    const double steps = loaded_.scene->outOfCore() ? 200 : 2000;
    const double step = std::max(reach / steps, loaded_.scene->grid().finestCellM * 0.5);
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
                if (below(m))
                    hi = m;
                else
                    lo = m;
            }
            return along(hi);
        }
        prevT = t;
    }
    // No hit: orbit around a point in front, at the distance of the scene's centre.
    double cx = 0, cy = 0;
    scene.grid().localToWorld(0.5 * (scene.xMin + scene.xMax), 0.5 * (scene.yMin + scene.yMax), cx, cy);
    return along(std::max(std::hypot(cx - c.xWorld, cy - c.yWorld), 1.0));
}

double Ground::pivotDistance(const render::Camera& c, double centreDistanceM) const {
    const auto p = pickCentre(c, centreDistanceM);
    return std::max(std::hypot(p[0] - c.xWorld, p[1] - c.yWorld, p[2] - c.zWorld), 1.0);
}

}  // namespace hc::view
