// heightcast/render/camera.h: a pinhole camera in the grid's CRS.
//
// Position in world coordinates (double, metres: UTM northings of 5e6 m stay exact); the renderer
// subtracts the grid origin once, in double, and works camera-relative from there.
// Angles in degrees: yaw 0 looks north (+y), 90 east (+x); pitch 0 is level, negative looks down,
// -90 straight down; positive roll banks the camera clockwise as seen from behind it (in the image
// the scene turns counterclockwise: the ground moves towards the right). fovYDeg is the vertical
// field of view.
// nearM and farM clip each ray (distances along the ray, metres); 0 means "from the scene": near is
// far / 1e7 (at least 1 mm) and far reaches the farthest corner of the scene's bounds.
#pragma once

#include <string>

#include <glm/vec3.hpp>

namespace hc::render {

struct Camera {
    double xWorld = 0, yWorld = 0, zWorld = 0;  // [m]
    double yawDeg = 0, pitchDeg = -30, rollDeg = 0;
    double fovYDeg = 50;
    double nearM = 0, farM = 0;      // [m] along the ray; 0: derived from the scene
    int width = 1280, height = 720;  // pixels

    // Throws hc::Error naming the first bad value (non-finite numbers, fov outside (0, 179), sizes,
    // negative near or far, far not beyond near).
    void validate() const;
    // Camera at `eye` looking at `target` (world, metres); throws if they coincide.
    static Camera lookAt(const glm::dvec3& eye, const glm::dvec3& target, double fovYDeg, int width, int height);
};

// The camera's orthonormal basis in the world frame (x east, y north, z up): unit vectors, double (GLM, the
// vocabulary the shaders share).
struct CameraBasis {
    glm::dvec3 forward, right, up;
    double tanHalfY, tanHalfX;  // image plane half extents at unit distance
};
CameraBasis basisOf(const Camera& c);

// Frame k of a flight from `start`: stepM metres a frame forward, horizontally along its yaw (height and angles kept).
// What hc-render --fly and hc-bench --fly-frames render.
Camera flightFrame(const Camera& start, double stepM, unsigned k);

}  // namespace hc::render
