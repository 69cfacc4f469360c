// The CPU renderer's hits against the exact surface (split from render_test, see render_world.h): 200+ random
// cameras on real DEMs, beams and the rays' set-up against the walk's own, no gap across cascade splits, and issue
// 11's hits that are not on the surface: blends floating where cascades overlap, walls at holes and the domain's edge,
// a camera below the terrain.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>

#include "heightcast/render/gpu_layout.h"
#include "heightcast/render/image_io.h"
#include "render_world.h"
#include "same_hits.h"

#include <glm/geometric.hpp>

namespace {

namespace fs = std::filesystem;
using hc::Grid;
using namespace hc::render;
using namespace hc::test;

// Pixels whose ray misses are background: the sky, each channel between its horizon and zenith
// colours (sRGB bytes, +-1 for rounding), with no position, normal, cascade or water. Returns the misses.
size_t expectMissesAreSky(const Frame& f) {
    size_t misses = 0, bad = 0;
    for (size_t i = 0; i < f.distanceM.size(); ++i) {
        if (std::isfinite(f.distanceM[i])) continue;
        ++misses;
        bool sky =
            std::isinf(f.distanceM[i]) && f.distanceM[i] > 0 && f.cascade[i] == -1.0f && f.waterDepthM[i] == 0.0f;
        for (int ch = 0; ch < 3; ++ch) {
            const double lo = 255 * std::min(hc::render::gpu::kSkyHorizon[ch], hc::render::gpu::kSkyZenith[ch]) - 1.0;
            const double hi = 255 * std::max(hc::render::gpu::kSkyHorizon[ch], hc::render::gpu::kSkyZenith[ch]) + 1.0;
            const double v = f.rgb[i * 3 + size_t(ch)];
            sky = sky && v >= lo && v <= hi;
        }
        if (!sky && bad++ < 3) ADD_FAILURE() << "pixel " << i << " missed but is not background";
    }
    return misses;
}

TEST_F(Render, HitsLieOnTheExactSurfaceFrom200RandomCameras) {
    std::mt19937_64 rng(2024);
    size_t frames = 0, checked = 0, bad = 0, misses = 0;
    double worst = 0;
    for (World* w : {&lidar(), &hef()}) {
        for (int i = 0; i < 110; ++i) {
            Camera c = randomCamera(*w, rng);
            RenderOptions o;
            o.texelsPerSide = 256;
            o.legend = false;  // every pixel is surface or background
            Timings t;
            Frame f = renderFrame(*w->scene, c, o, t);
            HitCheck h = checkHits(*w, f, t, 3);
            misses += expectMissesAreSky(f);
            if (h.worstRatio > 3 && std::getenv("HC_DEBUG_RENDER"))
                std::printf("camera %.3f %.3f %.3f yaw %.3f pitch %.3f fov %.3f frame %zu\n", c.xWorld, c.yWorld,
                            c.zWorld, c.yawDeg, c.pitchDeg, c.fovYDeg, frames);
            ++frames;
            checked += h.checked;
            bad += h.bad;
            worst = std::max(worst, h.worstRatio);
        }
    }
    EXPECT_GE(frames, 200u);
    EXPECT_GT(checked, 50000u);
    EXPECT_GT(misses, 10000u) << "the cameras also look past the grid's edges";
    // Rays grazing a surface within a fraction of a texel can land on either side of a kink of the
    // kernel's truncation circles; allow one in a thousand beyond the bound, none beyond 3x.
    EXPECT_LE(bad, checked / 1000) << bad << " of " << checked << " hits beyond the bound; worst ratio " << worst;
    EXPECT_LT(worst, 3.0);
}

// The rays of a tile walked from their beam's bound (RenderOptions::beamTilePx, raycast.cpp's Beam) meet what they meet
// walked from their cascades' starts: the bound only skips nodes that every walk would skip, and the patch there is
// entered at the same parameter. Every pixel's every layer is compared, bit for bit, over random cameras (rolled
// too, some with a near plane) on the flooded alpine DEM, the flooded LiDAR tile (shores everywhere: the water
// rules), and the gully with holes (walls), and from a camera outside the domain looking across it, for tiles
// of 2, 5 (the image's edge cuts tiles), 8 and 64 pixels. A ray whose path runs exactly through a patch corner may
// step across it by the other edge and round its hit differently: allowed in one pixel in 10^4, within 1e-9 of its
// distance; anything else is a wrong bound.
TEST_F(Render, BeamsGiveTheSameHits) {
    static World gully = fromFile("west_bijou_gully_3m.asc", 0.25);
    std::mt19937_64 rng(31);
    hc::test::SameHits n;
    for (World* w : {&hef(), &lidarFlood(), &gully}) {
        const Scene& s = *w->scene;
        const std::vector<Camera> cameras =
            hc::test::beamTestCameras(s, w->grid, 16, rng, [&](std::mt19937_64& r) { return randomCamera(*w, r); });
        auto draw = [&](const Camera& c, const RenderOptions& o) {
            Timings t;
            return renderFrame(s, c, o, t);
        };
        for (const Camera& c : cameras) {
            RenderOptions o;
            o.texelsPerSide = 256;
            n.addTiles(draw, c, o, {2, 5, 8, 64}, 1e-9, 1e-6);
        }
    }
    std::printf("%s\n", n.summary().c_str());
    EXPECT_GT(n.hits, n.pixels / 4);
    EXPECT_GT(n.walls, 1000u) << "the comparison covers walls";
    EXPECT_GT(n.water, 1000u) << "the comparison covers water";
    EXPECT_EQ(n.different, 0u);
    EXPECT_LE(n.rounded, n.pixels / 10000);
}

// detail::setUpRays computes each ray's span, texel steps and crossings for a block of rays at once in vector
// registers, with selects where the walk used to return early. Against the walk's own scalar set-up as it was before
// (offsetInterval, the clips to the texture, texelRay, the reciprocals and clipToHeights' crossings, written out here):
// the same values wherever the ray has something in the cascade, and an empty span wherever that code gave up.
// Tolerance 4 ulps: the same operations on the same operands, but the compiler may fuse a multiplication and an
// addition into one rounding (GCC's -ffp-contract=fast) in one translation unit and not in another; a wrong clip,
// swap or select is off by far more. (The frames themselves were compared byte for byte with the build before, in
// docs/benchmarks.md.) The directions include rays with components that are exactly 0 or tiny, level rays, one straight
// down and rays along the cascades' slabs.
TEST_F(Render, RaySetupsAreTheWalksOwnClips) {
    World& w = hef();
    const auto [setup, fit] = overviewFit(w);
    ASSERT_EQ(fit.cascades.size(), 3u);
    std::vector<detail::CascadeTextures> tex(fit.cascades.size());
    for (size_t k = 0; k < fit.cascades.size(); ++k) {
        detail::approximate(*w.scene, fit.cascades[k], tex[k], 0.01, 0);
        tex[k].terrain.buildMip(0);
        if (tex[k].hasWater) tex[k].water.buildMip(0), tex[k].buildBothMip(0);
    }
    const glm::dvec3 o = setup.eyeLocal;
    // The fitted cascades lie in front of the eye; moved so that it is over cascade 0's texture (rays with no motion
    // in x or y walk there), over cascade 2's though outside its slab, and over cascade 1's in y (at the edge behind it
    // along the view) but not in x, they give rays that only the slab, or only the x clip, leaves empty.
    CascadeFit moved = fit;
    for (size_t k : {0, 1, 2}) {
        Cascade& m = moved.cascades[k];
        const double side = (m.n - 1) * m.texelM;
        if (k != 1)
            m.x0 = o.x - 0.5 * side, m.y0 = o.y - 0.5 * side;
        else
            m.x0 = o.x + 10 * m.texelM, m.y0 = fit.dir.y >= 0 ? o.y - 10 * m.texelM : o.y - side + 10 * m.texelM;
    }
    std::vector<glm::dvec3> dirs = {{0, 0, -1},       {1, 0, 0},         {0, 1, 0},
                                    {0, -1, -1e-300}, {1e-310, 1, -0.2}, {-1, 1e-320, 0}};
    const glm::dvec2 v = fit.dir;
    dirs.push_back({-v.y, v.x, 0}), dirs.push_back({v.y, -v.x, -0.3}), dirs.push_back({v.x, v.y, 0});
    std::mt19937_64 rng(5);
    std::normal_distribution<double> g;
    for (int i = 0; i < 20000; ++i) dirs.push_back({g(rng), g(rng), -std::abs(g(rng))});
    for (int i = 0; i < 2000; ++i) dirs.push_back({g(rng), g(rng), g(rng)});
    for (int i = 0; i < 500; ++i)
        dirs.push_back({0, g(rng), -std::abs(g(rng))}), dirs.push_back({g(rng), 0, -std::abs(g(rng))});
    for (int i = 0; i < 500; ++i) dirs.push_back({-v.y * (1 + 1e-3 * g(rng)), v.x, -std::abs(g(rng))});  // along a slab
    for (glm::dvec3& d : dirs) d /= glm::length(d);
    std::vector<double> dx, dy, dz;
    for (const glm::dvec3& d : dirs) dx.push_back(d.x), dy.push_back(d.y), dz.push_back(d.z);
    auto near = [](double a, double b) {  // within 4 ulps; an infinity only equals itself
        if (a == b) return true;
        if (!std::isfinite(a) || !std::isfinite(b)) return false;
        return std::abs(a - b) <= 4 * std::numeric_limits<double>::epsilon() * std::max(std::abs(a), std::abs(b));
    };
    size_t compared = 0, empty = 0, edge = 0;
    const CascadeFit* fits[] = {&fit, &moved};
    for (const CascadeFit* f : fits) {
        for (size_t k = 0; k < fit.cascades.size(); ++k) {
            const detail::RayContext ctx{f, &tex, o, setup.nearM, setup.farM, w.scene->elevationMin};
            detail::RaySetups rs;
            detail::setUpRays(ctx, dirs.size(), dx.data(), dy.data(), dz.data(), rs);
            const Cascade& ck = f->cascades[k];
            const detail::RaySetups::Cascade& r = rs.cascades[k];
            const detail::Heightfield& hf = tex[k].terrain;
            const size_t top = hf.mip.size() - 1;
            const double zDry = hf.mip[top][0];
            double zWet = zDry;
            if (tex[k].hasWater)
                zWet = tex[k].bothMip.empty() ? std::max(hf.mip[top][0], tex[k].water.mip[top][0])
                                              : tex[k].bothMip[top][0];
            const double lo = k == 0 ? -HUGE_VAL : ck.splitNear, hi = ck.farWithOverlap;
            for (size_t i = 0; i < dirs.size(); ++i) {
                const glm::dvec3 d = dirs[i];
                // hitIn's clips as they were: none left means the walk returned before it began.
                double t0 = setup.nearM, t1 = setup.farM;
                bool none = false;
                const double eyeOffset = glm::dot(glm::dvec2(o), v);
                const double rate = glm::dot(glm::dvec2(d), v), at0 = glm::dot(glm::dvec2(o), v) - eyeOffset;
                if (std::abs(rate) < 1e-15) {
                    none = !(at0 >= lo && at0 <= hi);
                } else {
                    double a = (lo - at0) / rate, b = (hi - at0) / rate;
                    if (a > b) std::swap(a, b);
                    t0 = std::max(t0, a), t1 = std::min(t1, b);
                }
                const double ext = (ck.n - 1) * ck.texelM;
                for (int axis = 0; axis < 2 && !none; ++axis) {
                    const double lo0 = axis == 0 ? ck.x0 : ck.y0;
                    if (std::abs(d[axis]) < 1e-300) {
                        none = o[axis] < lo0 || o[axis] > lo0 + ext;
                        continue;
                    }
                    double a = (lo0 - o[axis]) / d[axis], b = (lo0 + ext - o[axis]) / d[axis];
                    if (a > b) std::swap(a, b);
                    t0 = std::max(t0, a), t1 = std::min(t1, b);
                }
                if (!none && near(t0, t1)) {  // a span of a few ulps: empty or not by rounding alone
                    ++edge;
                    continue;
                }
                if (none || !(t0 < t1)) {
                    ++empty;
                    EXPECT_FALSE(r.t0[i] < r.t1[i])
                        << "cascade " << k << ", ray " << i << ": a span where the walk had none";
                    continue;
                }
                ++compared;
                EXPECT_TRUE(near(r.t0[i], t0))
                    << "cascade " << k << ", ray " << i << ": " << r.t0[i] << " against " << t0;
                EXPECT_TRUE(near(r.t1[i], t1))
                    << "cascade " << k << ", ray " << i << ": " << r.t1[i] << " against " << t1;
                const double du = d.x / ck.texelM, dv = d.y / ck.texelM;
                EXPECT_TRUE(near(r.du[i], du) && near(r.dv[i], dv)) << "cascade " << k << ", ray " << i;
                EXPECT_TRUE(near(r.invDu[i], du != 0 ? 1.0 / du : 0.0)) << "cascade " << k << ", ray " << i;
                EXPECT_TRUE(near(r.invDv[i], dv != 0 ? 1.0 / dv : 0.0)) << "cascade " << k << ", ray " << i;
                EXPECT_TRUE(near(r.u0, (o.x - ck.x0) / ck.texelM) && near(r.v0, (o.y - ck.y0) / ck.texelM));
                if (d.z != 0) {
                    EXPECT_TRUE(near(r.tTopDry[i], (zDry - o.z) / d.z)) << "cascade " << k << ", ray " << i;
                    EXPECT_TRUE(near(r.tTopWet[i], (zWet - o.z) / d.z)) << "cascade " << k << ", ray " << i;
                    EXPECT_TRUE(near(rs.tFloor[i], (w.scene->elevationMin - o.z) / d.z)) << "ray " << i;
                }
            }
        }
    }
    std::printf("%zu spans compared, %zu empty, %zu of a few ulps\n", compared, empty, edge);
    EXPECT_GT(compared, 8000u);
    EXPECT_GT(empty, 1000u) << "rays with nothing in a cascade are compared too";
    EXPECT_LE(edge, 10u);
}

TEST_F(Render, NoGapAcrossCascadeSplits) {
    // A camera 300 m above the LiDAR-like field swept north across the split distances: every ray
    // points at least 20 degrees down and lands inside the grid, so every pixel must hit, in every
    // frame, with depths that change smoothly from row to row (no gap, no double surface).
    World& w = lidar();
    size_t overlapHits = 0;
    double worstJump = 0;
    for (int step = 0; step < 8; ++step) {
        Camera c;
        c.xWorld = w.grid.originWorldX + 200;
        c.yWorld = w.grid.originWorldY + 150 + step * 7.3;
        c.zWorld = 480;
        c.pitchDeg = -55;
        c.fovYDeg = 40;
        c.width = 160;
        c.height = 120;
        RenderOptions o;
        o.texelsPerSide = 128;  // small textures: many splits fall inside the view
        Timings t;
        Frame f = renderFrame(*w.scene, c, o, t);
        ASSERT_EQ(t.hits, t.rays) << "step " << step << ": a ray fell through a gap";
        HitCheck h = checkHits(w, f, t, 1);
        EXPECT_LE(h.bad, h.checked / 1000) << "step " << step;
        // The overlaps are in the picture: hits whose offset along the view direction lies in a blend zone.
        const double ex = c.xWorld - w.grid.originWorldX, ey = c.yWorld - w.grid.originWorldY;
        size_t blended = 0;
        for (size_t i = 0; i < f.posX.size(); ++i) {
            const double off = (f.posX[i] - ex) * t.viewDirX + (f.posY[i] - ey) * t.viewDirY;
            for (size_t k = 0; k + 1 < t.cascades.size(); ++k)
                if (off > t.cascades[k].splitFarM && off < t.cascades[k].farM) ++blended;
        }
        overlapHits += blended;
        // No step at a seam: down each column the distance changes little from one row to the next (rows
        // 0.33 degrees apart, 35-75 degrees down: on flat ground at most cot(35 deg) * 0.33 deg = 0.8 %; the
        // LiDAR's own relief makes the worst measured 6.1 %). A ray falling through a seam would land tens of
        // per cent farther on; the bound is 10 %.
        for (int x = 0; x < f.width; ++x)
            for (int y = 0; y + 1 < f.height; ++y) {
                const double a = f.distanceM[size_t(y) * size_t(f.width) + size_t(x)],
                             b = f.distanceM[size_t(y + 1) * size_t(f.width) + size_t(x)];
                worstJump = std::max(worstJump, std::abs(a - b) / std::min(a, b));
            }
    }
    EXPECT_GT(overlapHits, 1000u) << "the sweep must put cascade overlaps on screen";
    EXPECT_LT(worstJump, 0.10) << "a step between neighbouring rows";
    std::printf("%zu hits in blend zones; worst row-to-row distance change %.2f %%\n", overlapHits, 100 * worstJump);
}

// ---- issue 11: ray casting hits that are not on the surface ----

// Is pixel i a hit on a cut face of the terrain block (a hole or domain edge wall, or its bottom)?
bool wallAt(const Frame& f, size_t i) { return f.wall[i] != 0; }

// Hits far above the exact surface at their x, y: more than 3x the discretisation bound of checkHits (the
// random-camera test's worst ratio) and more than 1 m. A blend of two hits on different surfaces (a ridge in
// one cascade, the slope behind it in the next) lands in the air between them, tens of metres up.
struct Floating {
    size_t checked = 0, floating = 0;
    double worstM = 0;
};
Floating countFloating(const World& w, const Frame& f, const Timings& t) {
    Floating r;
    for (size_t i = 0; i < f.distanceM.size(); ++i) {
        if (!std::isfinite(f.distanceM[i]) || wallAt(f, i) || f.waterDepthM[i] > 0) continue;
        const double x = f.posX[i], y = f.posY[i], z = f.posZ[i];
        const auto exact = w.eval->value(x, y, {});
        if (!exact) continue;
        const size_t k = size_t(f.cascade[i]);
        const double s =
            k + 1 < t.cascades.size() ? std::max(t.cascades[k].texelM, t.cascades[k + 1].texelM) : t.cascades[k].texelM;
        const std::optional<double> claim = bilinearBound(*w.eval, {}, x, y, s);
        if (!claim) continue;  // next to a hole or the edge: no claim, not counted as checked
        const double bound = 2 * *claim;
        ++r.checked;
        const double above = z - *exact;
        if (above > std::max(3 * bound, 1.0)) {
            ++r.floating;
            r.worstM = std::max(r.worstM, above);
        }
    }
    return r;
}

// Low cameras over the alpine DEM looking across its ridges, so that silhouettes fall into the cascades'
// overlaps (issue 11: "2-21 pixels a frame up to 190 m above the terrain").
std::vector<Camera> ridgeCameras(const World& w) {
    std::vector<Camera> cams;
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<double> u(0, 1);
    const Scene& s = *w.scene;
    while (cams.size() < 24) {
        const double x = s.xMin + (0.2 + 0.6 * u(rng)) * (s.xMax - s.xMin),
                     y = s.yMin + (0.2 + 0.6 * u(rng)) * (s.yMax - s.yMin);
        const auto ground = exactAt(w, x, y);
        if (!ground) continue;
        Camera c;
        c.xWorld = w.grid.originWorldX + x, c.yWorld = w.grid.originWorldY + y;
        c.zWorld = *ground + 30 + 400 * u(rng);
        c.yawDeg = 360 * u(rng), c.pitchDeg = -2 - 12 * u(rng), c.fovYDeg = 50;
        c.width = 240, c.height = 160;
        cams.push_back(c);
    }
    return cams;
}

TEST_F(RenderHits, NoFloatingPixelsWhereCascadesOverlap) {
    World& w = hef();
    size_t checked = 0, floating = 0;
    double worst = 0;
    for (const Camera& c : ridgeCameras(w)) {
        RenderOptions o;
        o.texelsPerSide = 256;
        o.legend = false;
        Timings t;
        const Frame f = renderFrame(*w.scene, c, o, t);
        const Floating r = countFloating(w, f, t);
        checked += r.checked, floating += r.floating, worst = std::max(worst, r.worstM);
    }
    std::printf("%zu hits checked, %zu floating (worst %.1f m above the exact surface)\n", checked, floating, worst);
    EXPECT_GT(checked, 200000u);
    EXPECT_EQ(floating, 0u) << "worst " << worst << " m above the exact surface";
}

// A wall hit lies where the defined surface ends: on a texel-centre line of its cascade (texel centres are
// multiples of the texel size s in the local frame: stable fitting), one of the two corner texels one texel
// outwards along its normal lies outside every cell, and its height lies between the grid's lowest elevation
// and the surface at that edge (the patch edge is the straight line between the two inner corner texels, each
// equal to the exact surface within 1 mm: 1 cm allowed, with the float32 position). A bottom-face hit lies at
// the lowest elevation. Counts the hits that do not, over the wall hits it counts in `walls`.
size_t badWalls(const World& w, const Frame& f, const Timings& t, size_t& walls) {
    size_t bad = 0;
    const double zFloor = w.scene->elevationMin, tol = 0.01;
    auto outside = [&](double x, double y) {  // within a hair (texel centres on cell edges: rounding)
        for (auto [dx, dy] : {std::pair{0.0, 0.0}, {1e-6, 0.0}, {-1e-6, 0.0}, {0.0, 1e-6}, {0.0, -1e-6}})
            if (!w.grid.locate(x + dx, y + dy)) return true;
        return false;
    };
    for (size_t i = 0; i < f.distanceM.size(); ++i) {
        if (!std::isfinite(f.distanceM[i]) || !wallAt(f, i)) continue;
        ++walls;
        const double x = f.posX[i], y = f.posY[i], z = f.posZ[i];
        if (f.nZ[i] == -1.0f) {  // the bottom face
            if (std::abs(z - zFloor) > tol && bad++ < 5)
                ADD_FAILURE() << "bottom hit " << i << " at z " << z << ", not " << zFloor;
            continue;
        }
        const double s = t.cascades[size_t(f.cascade[i])].texelM;
        const bool alongX = std::abs(f.nX[i]) == 1.0f;
        if (!(f.nZ[i] == 0.0f && (alongX || std::abs(f.nY[i]) == 1.0f))) {
            if (bad++ < 5)
                ADD_FAILURE() << "wall hit " << i << ": normal " << f.nX[i] << "," << f.nY[i] << "," << f.nZ[i]
                              << " is not horizontal along an axis";
            continue;
        }
        const double across = alongX ? x : y, along = alongX ? y : x, n = alongX ? f.nX[i] : f.nY[i];
        const double line = std::round(across / s) * s, lo = std::floor(along / s) * s, hi = lo + s;
        auto at = [&](double a, double b) { return alongX ? std::pair{a, b} : std::pair{b, a}; };
        const auto [ox0, oy0] = at(line + n * s, lo);
        const auto [ox1, oy1] = at(line + n * s, hi);
        const auto [ix0, iy0] = at(line, lo);
        const auto [ix1, iy1] = at(line, hi);
        const auto z0 = w.eval->value(ix0, iy0, {}), z1 = w.eval->value(ix1, iy1, {});
        const bool onLine = std::abs(across - line) <= tol;
        const bool edge = outside(ox0, oy0) || outside(ox1, oy1);
        const bool height = z0 && z1 && z >= zFloor - tol && z <= std::max(*z0, *z1) + tol;
        if (!(onLine && edge && height) && bad++ < 5)
            ADD_FAILURE() << "wall hit " << i << " at " << x << "," << y << "," << z << " (s " << s << ", normal " << n
                          << (alongX ? " x" : " y") << "): on the texel line " << onLine
                          << ", beside a hole or the domain's edge " << edge << ", between " << zFloor
                          << " and the edge's top " << height;
    }
    return bad;
}

// Non-wall hits off the exact surface by more than max(3x the bound, 1 m). Next to a hole, where checkHits
// makes no claim, a surface hit is still on a patch with four defined corners: there the bound is 1 m plus
// a tenth of the texel (the patch's relief between corners equal to the surface within 1 mm).
size_t offSurface(const World& w, const Frame& f, const Timings& t, double& worst) {
    size_t off = 0;
    for (size_t i = 0; i < f.distanceM.size(); ++i) {
        if (!std::isfinite(f.distanceM[i]) || wallAt(f, i) || f.waterDepthM[i] > 0) continue;
        const auto exact = w.eval->value(f.posX[i], f.posY[i], {});
        if (!exact) continue;
        const size_t k = size_t(f.cascade[i]);
        const double s =
            k + 1 < t.cascades.size() ? std::max(t.cascades[k].texelM, t.cascades[k + 1].texelM) : t.cascades[k].texelM;
        const std::optional<double> claim = bilinearBound(*w.eval, {}, f.posX[i], f.posY[i], s);
        const double bound = claim ? 2 * *claim : 1.0 + 0.1 * s;  // no claim next to a hole: a looser fixed bound
        const double err = std::abs(f.posZ[i] - *exact);
        if (err > std::max(3 * bound, 1.0)) ++off, worst = std::max(worst, err);
    }
    return off;
}

// Issue 11: a camera 25 m outside the domain's west edge, below the edge's surface, looking east: it sees the
// domain's edge as a wall (before: the rays' first contact was the side, taken as starting inside the terrain,
// and the lower half of the picture was sky).
TEST_F(RenderHits, CameraOutsideTheDomainSeesTheEdgeWall) {
    World& w = lidar();
    const Scene& s = *w.scene;
    const double y = 0.5 * (s.yMin + s.yMax);
    const auto edgeTop = exactAt(w, s.xMin + 0.5, y);
    ASSERT_TRUE(edgeTop);
    Camera c;
    c.xWorld = w.grid.originWorldX + s.xMin - 25;
    c.yWorld = w.grid.originWorldY + y;
    c.zWorld = 0.5 * (s.elevationMin + *edgeTop);
    c.yawDeg = 90, c.pitchDeg = 0, c.fovYDeg = 50, c.width = 96, c.height = 64;
    Timings t;
    const Frame f = renderWith(w, c, t);
    size_t walls = 0;
    EXPECT_EQ(badWalls(w, f, t, walls), 0u);
    std::printf(
        "camera 25 m west of the domain, %.1f m below the edge's top: %llu hits of %llu rays, %zu on the wall\n",
        *edgeTop - c.zWorld, (unsigned long long)t.hits, (unsigned long long)t.rays, walls);
    EXPECT_GT(walls, t.rays / 4) << "the edge wall fills the lower part of the picture";
    double worst = 0;
    EXPECT_EQ(offSurface(w, f, t, worst), 0u) << "worst " << worst << " m";
    EXPECT_EQ(checkHits(w, f, t, 1).bad, 0u);
    // The EXR's wall channel, read back with OpenEXR: 1 on exactly these hits, 0 elsewhere.
    const fs::path path = dir_ / "walls.exr";
    writeFrameExr(f, path.string());
    Imf::InputFile in(path.c_str());
    ASSERT_NE(in.header().channels().findChannel("wall"), nullptr) << "no wall channel";
    const Imath::Box2i dw = in.header().dataWindow();
    std::vector<float> wall(f.wall.size(), -1.0f);
    Imf::FrameBuffer fb;
    fb.insert("wall", Imf::Slice(Imf::FLOAT,
                                 reinterpret_cast<char*>(wall.data()) -
                                     (dw.min.x + size_t(dw.min.y) * size_t(f.width)) * sizeof(float),
                                 sizeof(float), sizeof(float) * size_t(f.width)));
    in.setFrameBuffer(fb);
    in.readPixels(dw.min.y, dw.max.y);
    size_t ones = 0, others = 0;
    for (size_t i = 0; i < wall.size(); ++i) {
        ones += wall[i] == 1.0f && wallAt(f, i) && std::isfinite(f.distanceM[i]);
        others += !(wall[i] == 1.0f || wall[i] == 0.0f) || (wall[i] == 1.0f) != wallAt(f, i);
    }
    EXPECT_EQ(ones, walls);
    EXPECT_EQ(others, 0u);
}

// Issue 11: a camera in a hole of the gully (72 % nodata), below the surface of the valid cells beside it,
// looking at the hole's edge: it sees the edge as a wall (before: sky). And from random cameras over the
// gully, rays that cross a hole and meet its far side below the surface hit that side's wall, not a point
// up to kilometres under the surface shaded as if flat: every non-wall hit is on the surface, every wall hit
// on an edge.
TEST_F(RenderHits, HoleEdgesAreWalls) {
    World w = fromFile("west_bijou_gully_3m.asc", 0.25);
    const Scene& s = *w.scene;
    const double y = 0.5 * (s.yMin + s.yMax);
    double xEdge = s.xMin + 2;
    while (xEdge < s.xMax && !w.grid.locate(xEdge, y)) xEdge += 0.5;
    ASSERT_LT(xEdge, s.xMax);
    ASSERT_FALSE(w.grid.locate(xEdge - 20, y)) << "the camera stands in the hole";
    const auto top = exactAt(w, xEdge + 3, y);
    ASSERT_TRUE(top);
    Camera c;
    c.xWorld = w.grid.originWorldX + xEdge - 20;
    c.yWorld = w.grid.originWorldY + y;
    c.zWorld = std::max(*top - 3, s.elevationMin + 0.5 * (*top - s.elevationMin));
    c.yawDeg = 90, c.pitchDeg = -5, c.fovYDeg = 40, c.width = 96, c.height = 64;
    Timings t;
    Frame f = renderWith(w, c, t);
    size_t walls = 0;
    EXPECT_EQ(badWalls(w, f, t, walls), 0u);
    std::printf("camera in a hole %.1f m below the edge's top: %llu hits of %llu rays, %zu on walls\n", *top - c.zWorld,
                (unsigned long long)t.hits, (unsigned long long)t.rays, walls);
    EXPECT_GT(walls, t.rays / 10) << "the hole's edge stands in front of the camera";

    std::mt19937_64 rng(7);
    size_t off = 0, bad = 0, allWalls = 0, hits = 0;
    double worst = 0;
    for (int i = 0; i < 30; ++i) {
        Camera r = randomCamera(w, rng);
        r.pitchDeg = -3 - 25 * std::uniform_real_distribution<double>(0, 1)(rng);  // low: across holes
        f = renderWith(w, r, t);
        hits += t.hits;
        off += offSurface(w, f, t, worst);
        bad += badWalls(w, f, t, allWalls);
    }
    std::printf("30 random cameras over the gully: %zu hits, %zu on walls, %zu off the surface (worst %.1f m)\n", hits,
                allWalls, off, worst);
    EXPECT_EQ(off, 0u) << "worst " << worst << " m";
    EXPECT_EQ(bad, 0u);
    EXPECT_GT(allWalls, 100u);
}

// Issue 11: a camera below the terrain sees nothing (every ray starts inside the solid block), and the renderer
// says so before any work: cameraBelowTerrainM is how far under the surface it is (1 mm: the exact evaluator
// against the renderer's double sum over float kernel constants, 1e-7 relative), and no cascade is fitted or
// evaluated (before: 3.6 M Gaussians for an all-sky frame). Above the surface, with a near plane, or over a hole
// it is not below.
TEST_F(RenderHits, CameraBelowTheTerrainEvaluatesNothing) {
    World& w = hef();
    Camera c = above(w, -50, -10);
    EXPECT_NEAR(cameraBelowTerrainM(*w.scene, c), 50.0, 1e-3);
    Timings t;
    RenderOptions o;
    o.legend = false;  // every pixel is background
    Frame f = renderFrame(*w.scene, c, o, t);
    EXPECT_EQ(t.hits, 0u);
    EXPECT_TRUE(t.cascades.empty()) << "a cascade was fitted for a camera inside the terrain";
    EXPECT_EQ(expectMissesAreSky(f), t.rays);
    EXPECT_NEAR(cameraBelowTerrainM(*w.scene, above(w, 2, -10)), -2.0, 1e-3);
    c.nearM = 60;  // rays start 60 m out: a cut through the terrain, which the renderer draws
    EXPECT_EQ(cameraBelowTerrainM(*w.scene, c), 0.0);
    f = renderWith(w, c, t);
    EXPECT_EQ(t.cascades.size(), 3u);
    World gully = fromFile("west_bijou_gully_3m.asc", 0.25);
    Camera h;
    h.xWorld = gully.grid.originWorldX + gully.scene->xMin + 2;  // in the hole west of the gully's cells
    h.yWorld = gully.grid.originWorldY + 0.5 * (gully.scene->yMin + gully.scene->yMax);
    h.zWorld = gully.scene->elevationMin - 10;
    ASSERT_FALSE(gully.grid.locate(gully.scene->xMin + 2, 0.5 * (gully.scene->yMin + gully.scene->yMax)));
    EXPECT_EQ(cameraBelowTerrainM(*gully.scene, h), 0.0);
}

}  // namespace
