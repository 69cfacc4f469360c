// heightcast/render/camera.h: a pinhole camera in the grid's CRS.
//
// Position in world coordinates (double, metres: UTM northings of 5e6 m stay exact); the renderer
// subtracts the grid origin once, in double, and works camera-relative from there.
// Angles in degrees: yaw 0 looks north (+y), 90 east (+x); pitch 0 is level, negative looks down,
// -90 straight down; roll turns the image clockwise. fovYDeg is the vertical field of view.
#pragma once

#include <array>
#include <string>

namespace hc::render {

struct Camera {
    double xWorld = 0, yWorld = 0, zWorld = 0;  // [m]
    double yawDeg = 0, pitchDeg = -30, rollDeg = 0;
    double fovYDeg = 50;
    int width = 1280, height = 720;  // pixels

    // Throws hc::Error naming the first bad value (non-finite numbers, fov outside (0, 179], sizes).
    void validate() const;
    // Camera at `eye` looking at `target` (world, metres); throws if they coincide.
    static Camera lookAt(const std::array<double, 3>& eye, const std::array<double, 3>& target, double fovYDeg, int width, int height);
};

// The camera's orthonormal basis in the world frame (x east, y north, z up).
struct CameraBasis {
    std::array<double, 3> forward, right, up;
    double tanHalfY, tanHalfX;  // image plane half extents at unit distance
};
CameraBasis basisOf(const Camera& c);

}  // namespace hc::render
