// render/src/camera.cpp: the camera's checks, look-at and orthonormal basis.
#include <cmath>

#include <glm/geometric.hpp>

#include "heightcast/core/error.h"
#include "heightcast/render/camera.h"

namespace hc::render {

namespace {
constexpr double kDeg = M_PI / 180.0;
std::string num(double v) {
    char b[32];
    std::snprintf(b, sizeof b, "%g", v);
    return b;
}
}  // namespace

void Camera::validate() const {
    for (auto [v, name] : {std::pair{xWorld, "x"},
                           {yWorld, "y"},
                           {zWorld, "z"},
                           {yawDeg, "yaw"},
                           {pitchDeg, "pitch"},
                           {rollDeg, "roll"},
                           {nearM, "near"},
                           {farM, "far"}})
        if (!std::isfinite(v)) throw Error(std::string("camera ") + name + " is not a finite number");
    if (!(fovYDeg > 0 && fovYDeg < 179.0))
        throw Error("camera field of view " + num(fovYDeg) + " degrees is outside (0, 179)");
    if (pitchDeg < -90 || pitchDeg > 90) throw Error("camera pitch " + num(pitchDeg) + " degrees is outside [-90, 90]");
    if (nearM < 0) throw Error("camera near plane " + num(nearM) + " m is negative");
    if (farM < 0) throw Error("camera far plane " + num(farM) + " m is negative");
    if (farM > 0 && nearM >= farM)
        throw Error("camera far plane " + num(farM) + " m is not beyond the near plane " + num(nearM) + " m");
    if (width < 1 || height < 1 || width > 16384 || height > 16384)
        throw Error("image size " + std::to_string(width) + " x " + std::to_string(height) +
                    " is outside 1..16384 per side");
}

Camera Camera::lookAt(const glm::dvec3& eye, const glm::dvec3& target, double fovYDeg, int width, int height) {
    const glm::dvec3 d = target - eye;
    const double horizontal = std::hypot(d.x, d.y);
    if (horizontal == 0 && d.z == 0) throw Error("--look-at: the eye and the target are the same point");
    Camera c;
    c.xWorld = eye.x;
    c.yWorld = eye.y;
    c.zWorld = eye.z;
    c.yawDeg = horizontal > 0 ? std::atan2(d.x, d.y) / kDeg : 0.0;  // straight up or down: face north
    c.pitchDeg = std::atan2(d.z, horizontal) / kDeg;
    c.fovYDeg = fovYDeg;
    c.width = width;
    c.height = height;
    return c;
}

CameraBasis basisOf(const Camera& c) {
    const double yaw = c.yawDeg * kDeg, pitch = c.pitchDeg * kDeg, roll = c.rollDeg * kDeg;
    CameraBasis b;
    b.forward = {std::sin(yaw) * std::cos(pitch), std::cos(yaw) * std::cos(pitch), std::sin(pitch)};
    // Right stays horizontal (defined by the yaw even looking straight down or up), then roll.
    const glm::dvec3 r{std::cos(yaw), -std::sin(yaw), 0.0};
    const glm::dvec3 u = glm::cross(r, b.forward);
    const double cr = std::cos(roll), sr = std::sin(roll);
    b.right = cr * r - sr * u;
    b.up = sr * r + cr * u;
    b.tanHalfY = std::tan(0.5 * c.fovYDeg * kDeg);
    b.tanHalfX = b.tanHalfY * double(c.width) / double(c.height);
    return b;
}

Camera flightFrame(const Camera& start, double stepM, unsigned k) {
    Camera c = start;
    const double yaw = start.yawDeg * kDeg;
    c.xWorld += std::sin(yaw) * stepM * k;
    c.yWorld += std::cos(yaw) * stepM * k;
    return c;
}

}  // namespace hc::render
