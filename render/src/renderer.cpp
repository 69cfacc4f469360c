// render/src/renderer.cpp: the per-frame set-up both backends share, and the CPU renderer's frame as a list of stages
// (fitting, approximation and mipmaps, ray casting, shading). The Scene is in scene.cpp, the shading stage and the
// legend in shading.cpp, Timings' output in timings.cpp, the frame's error bound in error_bound.cpp.
#include "heightcast/render/renderer.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <optional>

#include <glm/geometric.hpp>

#include "heightcast/core/error.h"
#include "heightcast/core/heap.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/timer.h"
#include "heightcast/influence/region.h"
#include "heightcast/render/detail/frame.h"
#include "heightcast/render/gpu_layout.h"
#include "renderer_internal.h"

namespace hc::render {

std::string RenderOptions::validate() const {
    if (cascades < 1 || cascades > 4) return "--cascades " + std::to_string(cascades) + " is outside 1..4";
    if (texelsPerSide < 16 || texelsPerSide > 8192)
        return "--texels " + std::to_string(texelsPerSide) + " is outside 16..8192";
    if (!(waterMinDepthM >= 0)) return "the minimum water depth must be >= 0";
    if (pyramidInterpolateLevels < 0 || pyramidInterpolateLevels > 8)
        return "--pyramid-interpolate " + std::to_string(pyramidInterpolateLevels) + " is outside 0..8";
    if (beamTilePx < 0 || beamTilePx > 64) return "--beam-tile " + std::to_string(beamTilePx) + " is outside 0..64";
    if (!(maxErrorM >= 0) || !std::isfinite(maxErrorM)) return "--max-error must be a finite number >= 0 (metres)";
    if (!(maxErrorPx >= 0) || !std::isfinite(maxErrorPx)) return "--max-error-px must be a finite number >= 0 (pixels)";
    return {};
}

namespace detail {

Camera localCamera(const Grid& grid, const Camera& camera) {
    Camera c = camera;
    grid.worldToLocal(camera.xWorld, camera.yWorld, c.xWorld, c.yWorld);
    // Yaw turns clockwise from north, the rotation counterclockwise from east: a local yaw is the world's plus it.
    if (grid.rotationDeg != 0) c.yawDeg = camera.yawDeg + grid.rotationDeg;
    return c;
}

void frameToWorldAxes(const Grid& grid, Frame& f) {
    if (grid.rotationDeg == 0) return;
    for (size_t i = 0; i < f.posX.size(); ++i) {
        double x = 0, y = 0;
        grid.localToWorldDir(f.posX[i], f.posY[i], x, y);
        f.posX[i] = float(x), f.posY[i] = float(y);
        grid.localToWorldDir(f.nX[i], f.nY[i], x, y);
        f.nX[i] = float(x), f.nY[i] = float(y);
    }
}

FrameSetup setUpFrame(const Scene& scene, const Camera& worldCamera) {
    const Camera camera = localCamera(scene.grid(), worldCamera);
    FrameSetup s;
    s.basis = basisOf(camera);
    s.eyeLocal = {camera.xWorld, camera.yWorld, camera.zWorld};
    const glm::dvec3& eye = s.eyeLocal;
    // Near and far as the camera gives them, else from the scene: far reaches the farthest corner of the
    // bounds, near is far / 1e7 (at least 1 mm).
    double far = 0;
    for (double x : {scene.xMin, scene.xMax})
        for (double y : {scene.yMin, scene.yMax})
            for (double z : {scene.zMin, scene.zMax}) far = std::max(far, std::hypot(x - eye.x, y - eye.y, z - eye.z));
    far = far * 1.01 + 1.0;
    s.farM = camera.farM > 0 ? camera.farM : far;
    s.nearM = camera.nearM > 0 ? camera.nearM : std::max(1e-3, s.farM * 1e-7);
    if (s.nearM >= s.farM) s.farM = s.nearM * (1 + 1e-9);  // a given near beyond the scene: nothing to see
    ViewVolume& view = s.view;
    view.eyeLocal = eye;
    view.forward = s.basis.forward;
    view.right = s.basis.right;
    view.up = s.basis.up;
    view.tanHalfX = s.basis.tanHalfX;
    view.tanHalfY = s.basis.tanHalfY;
    // The view volume clips along forward: a ray's near point lies at least near / |corner ray| along it.
    view.nearM = s.nearM / std::sqrt(1.0 + s.basis.tanHalfX * s.basis.tanHalfX + s.basis.tanHalfY * s.basis.tanHalfY);
    view.farM = s.farM;
    view.yawRad = camera.yawDeg * M_PI / 180.0;
    view.boxMin = {scene.xMin, scene.yMin, scene.zMin};
    view.boxMax = {scene.xMax, scene.yMax, scene.zMax};
    view.finestCellM = scene.grid().finestCellM;
    if (scene.pyramid()) view.ladderStepsPerOctave = 1;
    view.pixelRad = 2 * s.basis.tanHalfY / std::max(1, camera.height);
    if (!scene.boundFromTexels())
        view.levelErrorIn = [&scene](double x0, double y0, double x1, double y1) {
            return scene.levelErrorM(x0, y0, x1, y1);
        };
    return s;
}

CascadeFit fitFrame(const Scene& scene, const Camera& camera, const FrameSetup& setup, const RenderOptions& options,
                    Timings& timings) {
    const Stopwatch clock;
    // A camera inside the terrain sees nothing (raycast.cpp): no cascade to fit or fill.
    ViewVolume view = setup.view;
    view.coarserTexels = options.pyramidCoarseTexels;
    view.maxErrorM = options.maxErrorM, view.maxErrorPx = options.maxErrorPx;
    view.maxTexelsPerSide = 2 * options.texelsPerSide;
    if (scene.boundFromTexels() && (options.maxErrorM > 0 || options.maxErrorPx > 0))
        view.levelErrorIn = [&scene, &options](double x0, double y0, double x1, double y1) {
            return predictLevelErrorM(scene, x0, y0, x1, y1, options.waterMinDepthM, options.threads);
        };
    timings.maxErrorM = options.maxErrorM, timings.maxErrorPx = options.maxErrorPx;
    const CascadeFit fit = cameraBelowTerrainM(scene, camera) > 0
                               ? CascadeFit{}
                               : fitCascades(view, options.cascades, options.texelsPerSide);
    timings.fittingMs = clock.milliseconds();
    timings.viewDirX = fit.dir.x;
    timings.viewDirY = fit.dir.y;
    return fit;
}

CascadeStats statsOf(const Cascade& c) {
    CascadeStats cs;
    cs.nearM = c.splitNear;
    cs.farM = c.farWithOverlap;
    cs.splitFarM = c.splitFar;
    cs.texelM = c.texelM;
    cs.visibleTexels = c.visibleTexels();
    return cs;
}

}  // namespace detail

struct CascadeCache::Impl {
    struct Entry {
        Cascade cascade;
        detail::CascadeTextures tex;
        size_t index = 0;  // the cascade's in its frame's fit
    };
    const Scene* scene = nullptr;  // what the entries were evaluated for
    size_t cells = 0;
    double waterMinDepthM = 0;
    std::vector<Entry> entries;
};
CascadeCache::CascadeCache() : impl_(std::make_unique<Impl>()) {}
CascadeCache::~CascadeCache() = default;
void CascadeCache::clear() { impl_->entries.clear(); }

namespace {

// The cache's entries, emptied when they were evaluated for another scene or water threshold.
CascadeCache::Impl* keptFor(CascadeCache::Impl& kept, const Scene& scene, const RenderOptions& options) {
    if (kept.scene != &scene || kept.cells != scene.cellCount() || kept.waterMinDepthM != options.waterMinDepthM)
        kept.entries.clear();
    return &kept;
}

// The last frame's cascade of the same texel size as c, if its lattice is c's (stable fitting), among those not yet
// taken (its side may differ: a far cascade grows and shrinks by 64 texels as the camera moves, and keeps what it
// still sees): its index in kept.entries and the texel offset. Two cascades of a frame may share a texel
// size (a camera high above the terrain): the one placed nearest to c is taken, as the nearer holds more of c's
// texels (the first one found copied 10 % of a far cascade in render_frames_test's
// MovingCameraVisitsCellsUnderTheNewTexelsOnly).
struct Reusable {
    size_t entry;
    int di, dj;
};
std::optional<Reusable> reusableCascade(const CascadeCache::Impl& kept, const std::vector<bool>& taken,
                                        const Cascade& c) {
    std::optional<Reusable> best;
    for (size_t e = 0; e < kept.entries.size(); ++e) {
        const Cascade& old = kept.entries[e].cascade;
        if (taken[e] || old.texelM != c.texelM) continue;
        const double fi = (c.x0 - old.x0) / c.texelM, fj = (c.y0 - old.y0) / c.texelM;
        if (std::abs(fi) > 1e9 || std::abs(fj) > 1e9) continue;
        const double ri = std::round(fi), rj = std::round(fj);
        if (std::abs(fi - ri) >= 1e-6 || std::abs(fj - rj) >= 1e-6) continue;
        const Reusable r{e, int(ri), int(rj)};
        if (!best || std::max(std::abs(r.di), std::abs(r.dj)) < std::max(std::abs(best->di), std::abs(best->dj)))
            best = r;
    }
    return best;
}

// reusableCascade's pick for c, marked taken, and recorded in `fill` (for a backend that keeps the texels itself) if
// given: the last frame's cascade by its index in that frame's fit.
std::optional<Reusable> takeReusable(const CascadeCache::Impl& kept, std::vector<bool>& taken, const Cascade& c,
                                     detail::CascadeFill* fill) {
    const std::optional<Reusable> r = reusableCascade(kept, taken, c);
    if (!r) return r;
    taken[r->entry] = true;
    if (fill) fill->from = int(kept.entries[r->entry].index), fill->di = r->di, fill->dj = r->dj;
    return r;
}

// Stages 2 and 3: each cascade's textures (copying what `kept` holds of the last frame) and max mipmaps, with
// their statistics in timings.cascades. With `fills` (detail::approximateOnCpu), what `kept` holds is not copied: each
// cascade's spans and the last frame's cascade they keep go there (and with pyramidTiles the texels left to copy from
// the pyramid).
std::vector<detail::CascadeTextures> approximateCascades(const Scene& scene, const CascadeFit& fit,
                                                         const RenderOptions& options, CascadeCache::Impl* kept,
                                                         Timings& timings, bool mipmaps = true,
                                                         std::vector<detail::CascadeFill>* fills = nullptr,
                                                         bool pyramidTiles = false) {
    std::vector<detail::CascadeTextures> tex(fit.cascades.size());
    if (fills) fills->assign(fit.cascades.size(), detail::CascadeFill{});
    std::vector<bool> taken(kept ? kept->entries.size() : 0, false);
    for (size_t k = 0; k < fit.cascades.size(); ++k) {
        const Cascade& c = fit.cascades[k];
        // A reused cascade's textures are updated in place (approximate() copies within them): allocating them afresh
        // while the last frame's were held cost far more than in a fresh frame (which reuses the heap its predecessor
        // freed): most likely page faults as the heap grew and shrank every frame.
        std::optional<detail::TexelReuse> reuse;
        // A cascade of another side copies its kept texels from the last frame's storage into new storage.
        if (const std::optional<Reusable> r =
                kept ? takeReusable(*kept, taken, c, fills ? &(*fills)[k] : nullptr) : std::nullopt) {
            CascadeCache::Impl::Entry& from = kept->entries[r->entry];
            if (from.cascade.n == c.n) tex[k] = std::move(from.tex);
            reuse = detail::TexelReuse{&from.cascade, from.cascade.n == c.n ? &tex[k] : &from.tex, r->di, r->dj};
        }
        CascadeStats cs = detail::statsOf(c);
        Stopwatch clock;
        if (!c.empty()) {
            const detail::ApproximationWork work = detail::approximate(
                scene, c, tex[k], options.waterMinDepthM, options.threads, reuse ? &*reuse : nullptr,
                c.interpolateLevels >= 0 ? std::min(c.interpolateLevels, options.pyramidInterpolateLevels)
                                         : options.pyramidInterpolateLevels,
                fills ? &(*fills)[k].rows : nullptr, fills && pyramidTiles ? &(*fills)[k].tiles : nullptr);
            cs.gaussians = work.gaussians, cs.cellsVisited = work.cellsVisited, cs.reusedTexels = work.reusedTexels;
            cs.cellsRead = work.cellsRead, cs.regionsRead = work.regionsRead;
            cs.pyramidTexels = work.pyramidTexels, cs.pyramidLevel = work.pyramidLevel;
            cs.pyramidInterpolated = work.pyramidInterpolated, cs.pyramidInterpolatedUp = work.pyramidInterpolatedUp;
        }
        cs.approximationMs = clock.milliseconds();
        timings.approximationMs += cs.approximationMs;
        clock.restart();
        if (!c.empty() && mipmaps) {
            tex[k].extendWaterToShores(options.threads);
            tex[k].terrain.buildMip(options.threads);
            if (tex[k].hasWater) tex[k].water.buildMip(options.threads), tex[k].buildBothMip(options.threads);
            if (scene.boundFromTexels()) cs.texelEstimateM = tex[k].errorEstimateM(options.threads);
        }
        timings.mipmapMs += clock.milliseconds();
        timings.cascades.push_back(cs);
    }
    return tex;
}

// Hits whose unit normal is still to be computed from their slope (detail::Hit::slopeOnly): a worker's, 256 at a time,
// in vector registers. One at a time, the square root and divisions at the end of every ray that hit were 4-6 % of
// ray casting (docs/benchmarks.md). The same operations either way (detail::normalOfSlope).
struct PendingNormals {
    static constexpr size_t kMax = 256;
    std::array<double, kMax> gx, gy, texelM, nx, ny, nz;  // Hit's gx, gy, texelM; the normal
    std::array<size_t, kMax> at;                          // the pixel
    size_t n = 0;
    void add(size_t pixel, const detail::Hit& h, Frame& f) {
        if (n == kMax) flush(f);
        at[n] = pixel, gx[n] = h.gx, gy[n] = h.gy, texelM[n] = h.texelM, ++n;
    }
    void flush(Frame& f) {
        const size_t count = n;  // a local: the stores below could change a member, for all the compiler knows
        for (size_t k = 0; k < count; ++k) detail::normalOfSlope(gx[k], gy[k], texelM[k], nx[k], ny[k], nz[k]);
        for (size_t k = 0; k < count; ++k)
            f.nX[at[k]] = float(nx[k]), f.nY[at[k]] = float(ny[k]), f.nZ[at[k]] = float(nz[k]);
        n = 0;
    }
};

// The rays of a rectangle of pixels: unit directions and their lengths before normalising, computed at once in vector
// registers (a square root and three divisions a ray) in the operations each ray used one at a time (glm's d = forward
// + sx right + sy up, length(d), d / length component by component). The compiler fuses the multiply-adds of this loop
// differently from glm's: a direction's y moved by its last bit in 280 of 921,600 rays of one render
// (docs/benchmarks.md).
struct RayDirections {
    int x0 = 0, y0 = 0, width = 0;
    std::vector<double> sx, sy, x, y, z, length;
    detail::RaySetups setups;  // and each ray's set-up in each cascade (detail::setUpRays)
    size_t at(int px, int py) const { return size_t(py - y0) * size_t(width) + size_t(px - x0); }
    void compute(const detail::RayContext& ctx, const CameraBasis& basis, const double* sxAt, const double* syAt,
                 int px0, int px1, int py0, int py1) {
        x0 = px0, y0 = py0, width = px1 - px0;
        const size_t n = size_t(width) * size_t(py1 - py0);
        for (std::vector<double>* v : {&sx, &sy, &x, &y, &z, &length}) v->resize(n);
        for (int py = py0; py < py1; ++py)
            for (int px = px0; px < px1; ++px) sx[at(px, py)] = sxAt[px], sy[at(px, py)] = syAt[py];
        unitDirections(basis, n, sx.data(), sy.data(), x.data(), y.data(), z.data(), length.data());
        detail::setUpRays(ctx, n, x.data(), y.data(), z.data(), setups);
    }
    // Six arrays of their own (restrict: the compiler would otherwise check every pair for overlap before vectorising).
    static void unitDirections(const CameraBasis& basis, size_t n, const double* __restrict sx,
                               const double* __restrict sy, double* __restrict dx, double* __restrict dy,
                               double* __restrict dz, double* __restrict len) {
        const glm::dvec3 f = basis.forward, r = basis.right, u = basis.up;
        for (size_t k = 0; k < n; ++k) {
            const double vx = f.x + sx[k] * r.x + sy[k] * u.x, vy = f.y + sx[k] * r.y + sy[k] * u.y,
                         vz = f.z + sx[k] * r.z + sy[k] * u.z;
            const double l = std::sqrt(vx * vx + vy * vy + vz * vz);
            dx[k] = vx / l, dy[k] = vy / l, dz[k] = vz / l, len[k] = l;
        }
    }
};

// Stage 4: one ray per pixel through the cascades; fills the frame's ray layers (every pixel a miss to start).
detail::PixelRays castRays(const Scene& scene, const detail::FrameSetup& setup, const CascadeFit& fit,
                           const std::vector<detail::CascadeTextures>& tex, const RenderOptions& options, Frame& f,
                           Timings& timings) {
    const int W = f.width, H = f.height;
    const size_t pixels = size_t(W) * size_t(H);
    // The layers, every pixel a miss; a layer a worker (each is width x height floats: zeroing them, and faulting their
    // pages in on a first frame, is too much for one core).
    detail::PixelRays rays;
    const std::pair<std::vector<float>*, float> layers[] = {{&f.distanceM, std::numeric_limits<float>::infinity()},
                                                            {&f.posX, 0.0f},
                                                            {&f.posY, 0.0f},
                                                            {&f.posZ, 0.0f},
                                                            {&f.nX, 0.0f},
                                                            {&f.nY, 0.0f},
                                                            {&f.nZ, 0.0f},
                                                            {&f.waterDepthM, 0.0f},
                                                            {&f.cascade, -1.0f},
                                                            {&f.wall, 0.0f}};
    constexpr size_t kLayers = std::size(layers);
    for (const auto& [layer, value] : layers) reserveOnHugePages(*layer, pixels);  // here, not on a worker (heap.h)
    reserveOnHugePages(rays.dirZ, pixels);
    reserveOnHugePages(rays.isWater, pixels);
    parallelFor(kLayers + 2, 1, options.threads, [&](size_t b, size_t e, unsigned) {
        for (size_t i = b; i < e; ++i) {
            if (i < kLayers)
                layers[i].first->assign(pixels, layers[i].second);
            else if (i == kLayers)
                rays.dirZ.assign(pixels, 0.0f);
            else
                rays.isWater.assign(pixels, uint8_t(0));
        }
    });
    const CameraBasis& basis = setup.basis;
    const glm::dvec3& eye = setup.eyeLocal;
    const detail::RayContext ctx{&fit, &tex, eye, setup.nearM, setup.farM, scene.elevationMin};
    auto sxOf = [&](int px) { return (2.0 * (px + 0.5) / W - 1.0) * basis.tanHalfX; };
    auto syOf = [&](int py) { return (1.0 - 2.0 * (double(py) + 0.5) / H) * basis.tanHalfY; };
    std::vector<double> sxAt(static_cast<size_t>(W)), syAt(static_cast<size_t>(H));  // each pixel column's and row's
    for (int px = 0; px < W; ++px) sxAt[size_t(px)] = sxOf(px);
    for (int py = 0; py < H; ++py) syAt[size_t(py)] = syOf(py);
    // Each worker's nearest hit of each cascade (CascadeStats::nearestHitM), counted as the rays land: a scan of the
    // frame after them (detail::measureNearestHits, which the tests compare) read 16 MB more a frame.
    constexpr size_t kMaxCascades = gpu::kMaxCascades;
    using Nearest = std::array<float, kMaxCascades>;
    Nearest none;
    none.fill(std::numeric_limits<float>::infinity());
    std::vector<Nearest> nearest(resolveThreads(options.threads), none);
    // Pixel (px, py) of the rectangle `dirs` holds (RayDirections::compute).
    auto cast = [&](int px, int py, const RayDirections& dirs, detail::Beam* beam, PendingNormals& normals,
                    Nearest& near) {
        const size_t k = dirs.at(px, py);
        const glm::dvec3 d{dirs.x[k], dirs.y[k], dirs.z[k]};
        const double length = dirs.length[k];
        const size_t i = size_t(py) * size_t(W) + size_t(px);
        rays.dirZ[i] = float(d.z);
        if (fit.hull.size() < 3) return;
        const detail::Hit h = detail::castRay(ctx, d, dirs.setups, k, beam, length);
        if (!h.hit) return;
        f.distanceM[i] = float(h.t);
        if (size_t(h.cascade) < kMaxCascades) near[size_t(h.cascade)] = std::min(near[size_t(h.cascade)], float(h.t));
        f.posX[i] = float(eye.x + d.x * h.t);
        f.posY[i] = float(eye.y + d.y * h.t);
        f.posZ[i] = float(eye.z + d.z * h.t);
        if (h.slopeOnly)
            normals.add(i, h, f);
        else
            f.nX[i] = float(h.nx), f.nY[i] = float(h.ny), f.nZ[i] = float(h.nz);
        f.cascade[i] = float(h.cascade);
        f.waterDepthM[i] = float(h.depth);
        f.wall[i] = h.wall ? 1.0f : 0.0f;
        rays.isWater[i] = h.water;
    };
    const Stopwatch clock;
    const int tile = options.beamTilePx;
    if (tile <= 1) {
        parallelFor(size_t(H), 4, options.threads, [&](size_t b, size_t e, unsigned worker) {
            PendingNormals normals;
            RayDirections dirs;
            for (size_t py = b; py < e; ++py) {
                dirs.compute(ctx, basis, sxAt.data(), syAt.data(), 0, W, int(py), int(py) + 1);
                for (int px = 0; px < W; ++px) cast(px, int(py), dirs, nullptr, normals, nearest[worker]);
            }
            normals.flush(f);
        });
    } else {  // a row of blocks of 4 x 4 tiles a task; each tile's rays with their beam (detail::Beam), inside its
              // block's
        const int block = 4 * tile;
        parallelFor(size_t((H + block - 1) / block), 1, options.threads, [&](size_t b, size_t e, unsigned worker) {
            PendingNormals normals;
            RayDirections dirs;
            for (size_t by = b; by < e; ++by) {
                const int qy0 = int(by) * block, qy1 = std::min(H, qy0 + block);
                for (int qx0 = 0; qx0 < W; qx0 += block) {
                    const int qx1 = std::min(W, qx0 + block);
                    dirs.compute(ctx, basis, sxAt.data(), syAt.data(), qx0, qx1, qy0, qy1);
                    detail::Beam outer(ctx, basis, sxOf(qx0), syOf(qy0), sxOf(qx1 - 1), syOf(qy1 - 1));
                    for (int py0 = qy0; py0 < qy1; py0 += tile)
                        for (int px0 = qx0; px0 < qx1; px0 += tile) {
                            const int py1 = std::min(qy1, py0 + tile), px1 = std::min(qx1, px0 + tile);
                            detail::Beam beam(ctx, basis, sxOf(px0), syOf(py0), sxOf(px1 - 1), syOf(py1 - 1), &outer);
                            for (int py = py0; py < py1; ++py)
                                for (int px = px0; px < px1; ++px) cast(px, py, dirs, &beam, normals, nearest[worker]);
                        }
                }
            }
            normals.flush(f);
        });
    }
    timings.raycastMs = clock.milliseconds();
    timings.rays = pixels;
    for (size_t k = 0; k < std::min(timings.cascades.size(), kMaxCascades); ++k) {  // RenderOptions: at most 4
        timings.cascades[k].nearestHitM = HUGE_VAL;                                 // +inf: no hit
        for (const Nearest& mine : nearest)
            timings.cascades[k].nearestHitM = std::min(timings.cascades[k].nearestHitM, double(mine[k]));
    }
    return rays;
}

// This frame's textures into the cache, for the next.
void keepCascades(CascadeCache::Impl& kept, const Scene& scene, const RenderOptions& options, const CascadeFit& fit,
                  std::vector<detail::CascadeTextures>& tex) {
    kept.scene = &scene, kept.cells = scene.cellCount(), kept.waterMinDepthM = options.waterMinDepthM;
    kept.entries.clear();
    for (size_t k = 0; k < fit.cascades.size(); ++k)
        if (!fit.cascades[k].empty()) kept.entries.push_back({fit.cascades[k], std::move(tex[k]), k});
}

}  // namespace

struct detail::CacheAccess {
    static CascadeCache::Impl& of(CascadeCache& cache) { return *cache.impl_; }
};

void detail::approximateOnCpu(const Scene& scene, const CascadeFit& fit, const RenderOptions& options,
                              CascadeCache& cache, Timings& timings,
                              const std::function<void(size_t, CascadeTextures&, CascadeFill&)>& use,
                              bool pyramidTiles) {
    CascadeCache::Impl* kept = keptFor(CacheAccess::of(cache), scene, options);
    std::vector<CascadeFill> fills;
    std::vector<CascadeTextures> tex =
        approximateCascades(scene, fit, options, kept, timings, false, &fills, pyramidTiles);
    for (size_t k = 0; k < fit.cascades.size(); ++k)
        if (!fit.cascades[k].empty()) use(k, tex[k], fills[k]);
    keepCascades(*kept, scene, options, fit, tex);  // their storage, for the next frame's spans
}

std::vector<detail::CascadeFill> detail::planCascades(const Scene& scene, const CascadeFit& fit,
                                                      const RenderOptions& options, CascadeCache& cache,
                                                      Timings& timings) {
    CascadeCache::Impl& kept = *keptFor(CacheAccess::of(cache), scene, options);
    std::vector<CascadeFill> fills(fit.cascades.size());
    std::vector<bool> taken(kept.entries.size(), false);
    for (size_t k = 0; k < fit.cascades.size(); ++k) {
        const Cascade& c = fit.cascades[k];
        if (c.empty()) continue;
        std::optional<TexelReuse> reuse;
        if (const std::optional<Reusable> r = takeReusable(kept, taken, c, &fills[k]))
            reuse = TexelReuse{&kept.entries[r->entry].cascade, nullptr, r->di, r->dj};
        uint64_t reused = 0;
        fills[k].rows = rowFills(c, reuse ? &*reuse : nullptr, reused);
        if (k < timings.cascades.size()) timings.cascades[k].reusedTexels = reused;
    }
    std::vector<CascadeTextures> none(fit.cascades.size());  // the shapes only
    keepCascades(kept, scene, options, fit, none);
    return fills;
}

Frame renderFrame(const Scene& scene, const Camera& camera, const RenderOptions& options, Timings& timings,
                  CascadeCache* cache) {
    camera.validate();
    if (std::string why = options.validate(); !why.empty()) throw Error(why);
    if (!options.colorLayer.empty()) {  // before any work: the layer exists, and the evaluator can be had
        influence::Layer::byName(scene.grid(), options.colorLayer);
        scene.evaluator();
    }
    const Stopwatch total;
    timings = Timings{};
    const detail::FrameSetup setup = detail::setUpFrame(scene, camera);
    const CascadeFit fit = detail::fitFrame(scene, camera, setup, options, timings);
    CascadeCache::Impl* kept = cache ? keptFor(*cache->impl_, scene, options) : nullptr;
    std::vector<detail::CascadeTextures> tex = approximateCascades(scene, fit, options, kept, timings);
    Frame f;
    f.width = camera.width;
    f.height = camera.height;
    f.originWorldX = scene.grid().originWorldX;
    f.originWorldY = scene.grid().originWorldY;
    const detail::PixelRays rays = castRays(scene, setup, fit, tex, options, f, timings);
    detail::shadePixels(scene, options, setup.basis, rays, f, timings);
    detail::frameToWorldAxes(scene.grid(), f);
    if (kept) keepCascades(*kept, scene, options, fit, tex);
    detail::boundFrame(scene, setup, fit, timings);
    timings.totalMs = total.milliseconds();
    return f;
}

}  // namespace hc::render
