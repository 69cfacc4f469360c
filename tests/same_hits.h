// tests/same_hits.h: two frames of one camera compared pixel by pixel, as the beam tests of both backends do
// (Render.BeamsGiveTheSameHits, RenderGl.BeamsGiveTheSameHits): the same hit bit for bit, the same hit rounded
// differently, or a different one.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <cstddef>
#include <initializer_list>
#include <random>
#include <string>
#include <vector>

#include "heightcast/grid/grid.h"
#include "heightcast/render/renderer.h"

namespace hc::test {

// "camera X Y Z yaw Y pitch P roll R" for a failure message.
inline std::string cameraText(const render::Camera& c) {
    return "camera " + std::to_string(c.xWorld) + " " + std::to_string(c.yWorld) + " " + std::to_string(c.zWorld) +
           " yaw " + std::to_string(c.yawDeg) + " pitch " + std::to_string(c.pitchDeg) + " roll " +
           std::to_string(c.rollDeg);
}

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
            const bool same = f.distanceM[i] == ref.distanceM[i] && f.cascade[i] == ref.cascade[i] &&
                              f.nX[i] == ref.nX[i] && f.nY[i] == ref.nY[i] && f.nZ[i] == ref.nZ[i] &&
                              f.wall[i] == ref.wall[i] && f.waterDepthM[i] == ref.waterDepthM[i] &&
                              f.posZ[i] == ref.posZ[i];
            if (same) continue;
            const bool close =
                hit && std::abs(double(f.distanceM[i]) - ref.distanceM[i]) <= relTol * ref.distanceM[i] + absTol &&
                f.cascade[i] == ref.cascade[i] && f.wall[i] == ref.wall[i];
            (close ? rounded : different) += 1;
            if (!close && different < 5)
                ADD_FAILURE() << where << ", pixel " << i << ": distance " << f.distanceM[i] << " against "
                              << ref.distanceM[i] << ", cascade " << f.cascade[i] << " against " << ref.cascade[i];
        }
    }

    // Camera c's frames with beams of each tile size in `tiles` against its frame without (beamTilePx 0), as
    // draw(c, options) makes them (one backend or the other), each compared by add().
    template <class Draw>
    void addTiles(Draw&& draw, const render::Camera& c, render::RenderOptions o, std::initializer_list<int> tiles,
                  double relTol, double absTol) {
        o.beamTilePx = 0;
        const render::Frame ref = draw(c, o);
        for (int tile : tiles) {
            o.beamTilePx = tile;
            add(ref, draw(c, o), relTol, absTol, "tile " + std::to_string(tile) + ", " + cameraText(c));
        }
    }

    std::string summary() const {
        return std::to_string(pixels) + " pixels compared: " + std::to_string(hits) + " hits (" +
               std::to_string(walls) + " on walls, " + std::to_string(water) + " on water), " +
               std::to_string(rounded) + " rounded differently, " + std::to_string(different) + " different";
    }
};

// The cameras the beam tests look through: `count` of randomCamera(rng), of every four one as it is, one rolled, one
// with a near plane and one looking straight down; then one outside the domain (west of it, at 30 % of its relief)
// looking east across it.
template <class RandomCamera>
std::vector<render::Camera> beamTestCameras(const render::Scene& s, const Grid& g, int count, std::mt19937_64& rng,
                                            RandomCamera&& randomCamera) {
    std::uniform_real_distribution<double> u(0, 1);
    std::vector<render::Camera> cameras;
    for (int i = 0; i < count; ++i) {
        render::Camera c = randomCamera(rng);
        if (i % 4 == 1) c.rollDeg = 360 * u(rng);
        if (i % 4 == 2) c.nearM = 5 + 200 * u(rng);
        if (i % 4 == 3) c.pitchDeg = -90 + 1e-3 * u(rng);  // straight down
        cameras.push_back(c);
    }
    render::Camera outside = cameras.at(0);
    outside.xWorld = g.originWorldX + s.xMin - 0.3 * (s.xMax - s.xMin),
    outside.yWorld = g.originWorldY + 0.5 * (s.yMin + s.yMax);
    outside.zWorld = s.elevationMin + 0.3 * (s.zMax - s.elevationMin), outside.yawDeg = 90, outside.pitchDeg = -4,
    outside.rollDeg = 0;
    cameras.push_back(outside);
    return cameras;
}

}  // namespace hc::test
