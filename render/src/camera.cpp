#include <cmath>

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
    for (auto [v, name] : {std::pair{xWorld, "x"}, {yWorld, "y"}, {zWorld, "z"}, {yawDeg, "yaw"}, {pitchDeg, "pitch"}, {rollDeg, "roll"}, {nearM, "near"}, {farM, "far"}})
        if (!std::isfinite(v)) throw Error(std::string("camera ") + name + " is not a finite number");
    if (!(fovYDeg > 0 && fovYDeg < 179.0)) throw Error("camera field of view " + num(fovYDeg) + " degrees is outside (0, 179)");
    if (pitchDeg < -90 || pitchDeg > 90) throw Error("camera pitch " + num(pitchDeg) + " degrees is outside [-90, 90]");
    if (nearM < 0) throw Error("camera near plane " + num(nearM) + " m is negative");
    if (farM < 0) throw Error("camera far plane " + num(farM) + " m is negative");
    if (farM > 0 && nearM >= farM) throw Error("camera far plane " + num(farM) + " m is not beyond the near plane " + num(nearM) + " m");
    if (width < 1 || height < 1 || width > 16384 || height > 16384)
        throw Error("image size " + std::to_string(width) + " x " + std::to_string(height) + " is outside 1..16384 per side");
}

Camera Camera::lookAt(const std::array<double, 3>& eye, const std::array<double, 3>& target, double fovYDeg, int width, int height) {
    const double dx = target[0] - eye[0], dy = target[1] - eye[1], dz = target[2] - eye[2];
    const double horizontal = std::hypot(dx, dy);
    if (horizontal == 0 && dz == 0) throw Error("--look-at: the eye and the target are the same point");
    Camera c;
    c.xWorld = eye[0];
    c.yWorld = eye[1];
    c.zWorld = eye[2];
    c.yawDeg = horizontal > 0 ? std::atan2(dx, dy) / kDeg : 0.0;  // straight up or down: face north
    c.pitchDeg = std::atan2(dz, horizontal) / kDeg;
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
    std::array<double, 3> r{std::cos(yaw), -std::sin(yaw), 0.0};
    std::array<double, 3> u{r[1] * b.forward[2] - r[2] * b.forward[1], r[2] * b.forward[0] - r[0] * b.forward[2],
                            r[0] * b.forward[1] - r[1] * b.forward[0]};
    const double cr = std::cos(roll), sr = std::sin(roll);
    for (int k = 0; k < 3; ++k) {
        b.right[k] = cr * r[k] - sr * u[k];
        b.up[k] = sr * r[k] + cr * u[k];
    }
    b.tanHalfY = std::tan(0.5 * c.fovYDeg * kDeg);
    b.tanHalfX = b.tanHalfY * double(c.width) / double(c.height);
    return b;
}

}  // namespace hc::render
