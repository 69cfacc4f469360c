// tests/same_hits.h: two frames of one camera compared pixel by pixel, as the beam tests of both backends do
// (Render.BeamsGiveTheSameHits, RenderGl.BeamsGiveTheSameHits): the same hit bit for bit, the same hit rounded
// differently, or a different one.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <cstddef>
#include <string>

#include "heightcast/render/renderer.h"

namespace hc::test {

struct SameHits {
    size_t pixels = 0, hits = 0, walls = 0, water = 0;  // of the reference frames
    size_t rounded = 0;    // the same hit (cascade, wall) at a distance within the tolerance, not bit for bit
    size_t different = 0;  // anything else

    // Adds frame f against the reference ref. A pixel is rounded differently when both hit, on the same cascade and
    // kind, with distances within relTol of ref's plus absTol [m]. The first few different pixels are reported as
    // failures, with `where` (the camera, the option compared).
    void add(const render::Frame& ref, const render::Frame& f, double relTol, double absTol, const std::string& where) {
        ASSERT_EQ(f.distanceM.size(), ref.distanceM.size()) << where;
        for (size_t i = 0; i < f.distanceM.size(); ++i) {
            ++pixels;
            const bool hit = std::isfinite(ref.distanceM[i]);
            hits += hit, walls += ref.wall[i] > 0, water += ref.waterDepthM[i] > 0;
            const bool same = f.distanceM[i] == ref.distanceM[i] && f.cascade[i] == ref.cascade[i] && f.nX[i] == ref.nX[i] &&
                              f.nY[i] == ref.nY[i] && f.nZ[i] == ref.nZ[i] && f.wall[i] == ref.wall[i] &&
                              f.waterDepthM[i] == ref.waterDepthM[i] && f.posZ[i] == ref.posZ[i];
            if (same) continue;
            const bool close = hit && std::abs(double(f.distanceM[i]) - ref.distanceM[i]) <= relTol * ref.distanceM[i] + absTol &&
                               f.cascade[i] == ref.cascade[i] && f.wall[i] == ref.wall[i];
            (close ? rounded : different) += 1;
            if (!close && different < 5)
                ADD_FAILURE() << where << ", pixel " << i << ": distance " << f.distanceM[i] << " against " << ref.distanceM[i] << ", cascade "
                              << f.cascade[i] << " against " << ref.cascade[i];
        }
    }

    std::string summary() const {
        return std::to_string(pixels) + " pixels compared: " + std::to_string(hits) + " hits (" + std::to_string(walls) + " on walls, " +
               std::to_string(water) + " on water), " + std::to_string(rounded) + " rounded differently, " + std::to_string(different) +
               " different";
    }
};

// "camera X Y Z yaw Y pitch P roll R" for a failure message.
inline std::string cameraText(const render::Camera& c) {
    return "camera " + std::to_string(c.xWorld) + " " + std::to_string(c.yWorld) + " " + std::to_string(c.zWorld) + " yaw " +
           std::to_string(c.yawDeg) + " pitch " + std::to_string(c.pitchDeg) + " roll " + std::to_string(c.rollDeg);
}

}  // namespace hc::test
