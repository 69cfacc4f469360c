// apps/view/ground.h: the terrain as the viewer's controls see it: the exact surface under the camera (height
// above ground, flying speed) and the surface point under the screen centre (the orbit pivot, the zoom step).
// World coordinates [m] in the grid's CRS.
#pragma once

#include <array>
#include <optional>

#include "heightcast/support/render_setup.h"
#include "heightcast/influence/surface.h"
#include "heightcast/render/camera.h"

namespace hc::view {

class Ground {
public:
    explicit Ground(const cli::LoadedScene& loaded);  // `loaded` must outlive it

    // The terrain's elevation at (x, y); empty in holes and outside the grid.
    std::optional<double> elevationAt(double xWorld, double yWorld) const;
    // The camera's height above the terrain below it [m]; empty where there is none.
    std::optional<double> heightAboveGround(const render::Camera& c) const;
    // |height above ground|, at least 1 m, or `fallback` where there is no ground below.
    double heightAboveGroundOr(const render::Camera& c, double fallback) const;
    // How far above the scene's highest point the camera is [m] (negative below it).
    double aboveHighestM(const render::Camera& c) const;
    // Flying speed [m/s]: the height above ground per second, so low flights are slow and high ones fast.
    double speed(const render::Camera& c) const;
    // The surface point under the screen centre: `centreDistanceM` along the view ray when finite (the last
    // frame's, when it shows this camera), otherwise found by marching the exact surface along the ray; with
    // no hit, a point in front at the distance of the scene's centre.
    std::array<double, 3> pickCentre(const render::Camera& c, double centreDistanceM) const;
    // The distance from the camera to pickCentre() [m], at least 1 m.
    double pivotDistance(const render::Camera& c, double centreDistanceM) const;

private:
    const cli::LoadedScene& loaded_;
    std::optional<influence::SurfaceEvaluator>
        evaluator_;  // in memory; out of core the scene reads the cells around each point
    influence::Layer elevation_;
};

}  // namespace hc::view
