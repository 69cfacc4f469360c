// hc-bench: how fast does the CPU renderer draw the report's four flood scenes, and in how much memory?
//
// The technical report (its performance table) renders four real flood simulations on a GTX 1080:
//   Marchfeld      82.9 x 57.1 km, cells 3 - 96 m,    7.46 M cells: approximation 15.1 ms, ray casting 5.1 ms
//   Petzenkirchen  15.4 x 16.0 km, cells 0.75 - 96 m, 1.81 M cells:                20.8 ms,              4.3 ms
//   Wachau         24.1 x 16.5 km, cells 3 - 96 m,    1.95 M cells:                 5.3 ms,              4.3 ms
//   Florence       44.6 x 28.2 km, cells 3 - 96 m,    4.53 M cells:                 1.5 ms,              2.8 ms
// We do not have those data sets, so this program generates synthetic stand-ins with the same extents, cell
// sizes and cell counts, deterministically (fixed seeds, no input files):
//   terrain   a smooth landscape: large-scale relief (a few sinusoids of 6-30 km wavelength) rising from a
//             meandering river valley (a flat floodplain with a gentle downstream slope and low undulations,
//             smooth valley sides, a parabolic channel), with smaller hills (plane waves of 150-900 m) on the
//             uplands; hundreds of metres of relief in Wachau and Florence, tens in Marchfeld.
//   water     layer water_depth: a flood level a few metres above the floodplain; depth = level - terrain where
//             positive, 0 where dry. The channel is always wet; the floodplain's undulations make the flood's
//             edge irregular.
//   grid      a quadtree built top-down in Morton order (Grid::appendCell): a node of the domain is split while
//             it is larger than the finest size and (it is coarser than 96 m, or it straddles a wet/dry edge
//             or a channel bank, or the terrain or the water depth varies over it by more than a threshold T,
//             measured at its 3 x 3 corner / edge / centre points). A leaf's values are terrain and depth at its
//             centre. T is calibrated per scenario by bisection, counting the cells of a fixed sample of 1/8 of
//             the 768 m tiles (all tiles of a small domain); one count over every tile then measures the sample's
//             bias (the river crosses few sample tiles) and the bisection repeats with it (at most 3 rounds), so
//             the cell count lands within a few % of the report's count divided by --scale; the actual count is
//             printed beside the target. If even T = infinity gives
//             too many cells (the forced wet-edge and bank cells alone exceed the target: large --scale), the
//             finest size doubles until it fits, and the table says so through its cell sizes.
// Each scenario then runs in its own forked child (so getrusage's peak RSS is that scenario's alone, and
// its memory is returned before the next): generate the grid, build the influence lists (sigma 1, R 3.5;
// timed), and render --repeat frames (default 3) at 1920 x 1080 with three 1024^2 cascades from a fixed
// oblique camera a user would pick over the flood: 1.5 km above the river, 10 % of the way downstream,
// looking 4.1 km along it (where the centre ray meets the valley floor) at pitch -20 degrees, 50 degree
// vertical field of view. Stage times are the best over the repeats; Gaussians/s = the cascades' kernel
// evaluations / approximation time; rays/s = pixels / ray casting time.
// Targets on this 2-core machine: approximation >= 2 G Gaussians/s; ray casting of 1920 x 1080 within 250 ms
// (>= 8.29 M rays/s at other sizes).
// Why a program and not a test: the figures depend on the machine; tests never time anything.
#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdarg>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <numbers>
#include <random>
#include <string>
#include <thread>
#include <type_traits>
#include <vector>

#include <sys/wait.h>
#include <unistd.h>

#include "bench_common.h"
#include "svg_plot.h"
#include "backend_choice.h"
#include "cli.h"
#include "heightcast/core/error.h"
#include "heightcast/grid/grid.h"
#include "heightcast/grid/morton.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/progress.h"
#include "heightcast/influence/influence.h"
#include "heightcast/render/gl/gl_renderer.h"
#include "heightcast/render/image_io.h"
#include "heightcast/render/renderer.h"

namespace fs = std::filesystem;
using hc::Grid;

namespace {

using namespace hc::bench;

// Targets (2 cores).
constexpr double kTargetGaussiansPerS = 2e9;  // approximation: kernel evaluations per second
constexpr double kTargetRaycastMs = 250.0;    // ray casting of a 1920 x 1080 frame
constexpr double kTargetRaysPerS = 1920.0 * 1080.0 / (kTargetRaycastMs / 1e3);  // the same as a rate (other sizes)
constexpr double kTargetGlFrameMs = 8.0;  // GL backend on a GPU (issue 5): a whole 1920 x 1080 frame

constexpr double kCoarsestM = 96.0;   // every scenario's coarsest cell
constexpr int kTileLevelsAboveCoarsest = 3;  // generation tiles: 8 x 8 coarsest cells (768 m)
constexpr int kMaxLevels = 24;        // cells-per-level slots sent back from a child

// ---------------- the scenarios ----------------

// One wave of a sum of sinusoids: amp * sin(kx x + ky y + phase).
struct Wave {
    double kx, ky, phase, amp;
};

// Everything that shapes one synthetic scenario. Lengths in metres, heights in metres above sea level.
struct Landscape {
    double z0;                  // floodplain floor at the upstream (west) edge
    double riverSlope;          // floor drop per metre downstream (+x)
    double riverYFraction;      // mean centreline, as a fraction of the extent in y
    double meanderAmp[2], meanderLen[2];
    double floorHalfWidth;      // flat floodplain each side of the centreline
    double sideWidth;           // valley sides, from the floodplain up to the uplands
    double channelHalfWidth, channelDepth;
    double floodHeight;         // water level above the floodplain floor
    double microAmp;            // floodplain undulations (max amplitude)
    double reliefAmp;           // uplands above the floor (mean); large-scale waves add +-50 %
    double hillAmp;             // small-scale hills on the uplands (max amplitude)
    uint64_t seed;
};

struct Scenario {
    const char* name;
    double extentXKm, extentYKm, finestM;
    double reportCellsM;        // the report's cell count, millions
    double gpuApproxMs, gpuRaycastMs;  // the report's GTX 1080 times
    double originX, originY;    // world position of the south-west corner (UTM-like, to exercise the camera maths)
    Landscape land;
};

const Scenario kScenarios[] = {
    {"Marchfeld", 82.9, 57.1, 3.0, 7.46, 15.1, 5.1, 580000, 5330000,
     {160, 0.0004, 0.42, {2600, 700}, {32000, 7000}, 2600, 1800, 150, 6, 2.4, 1.2, 45, 8, 11}},
    {"Petzenkirchen", 15.4, 16.0, 0.75, 1.81, 20.8, 4.3, 510000, 5330000,
     {300, 0.002, 0.5, {700, 160}, {9000, 1800}, 110, 700, 4, 1.5, 0.8, 0.4, 90, 12, 22}},
    {"Wachau", 24.1, 16.5, 3.0, 1.95, 5.3, 4.3, 530000, 5360000,
     {205, 0.0003, 0.5, {1600, 400}, {19000, 5200}, 450, 2600, 140, 5, 3.0, 1.0, 430, 35, 33}},
    {"Florence", 44.6, 28.2, 3.0, 4.53, 1.5, 2.8, 660000, 4840000,
     {55, 0.0005, 0.45, {1300, 320}, {21000, 4300}, 1900, 3200, 60, 4, 2.5, 0.9, 330, 28, 44}},
};

// The terrain and water of one scenario as smooth functions of the local position.
class Terrain {
public:
    Terrain(const Landscape& l, double extentY) : l_(l), extentY_(extentY) {
        std::mt19937_64 rng(l.seed);
        std::uniform_real_distribution<double> unit(0.0, 1.0);
        auto waves = [&](int count, double minLen, double maxLen, std::vector<Wave>& out) {
            double total = 0;
            for (int k = 0; k < count; ++k) {
                const double len = minLen * std::pow(maxLen / minLen, unit(rng));
                const double dir = 2 * std::numbers::pi * unit(rng), kk = 2 * std::numbers::pi / len;
                const double amp = 0.5 + unit(rng);
                out.push_back({kk * std::cos(dir), kk * std::sin(dir), 2 * std::numbers::pi * unit(rng), amp});
                total += amp;
            }
            for (Wave& w : out) w.amp /= total;  // the sum stays within [-1, 1]
        };
        waves(4, 6000, 30000, large_);
        waves(6, 150, 900, hills_);
        waves(3, 200, 900, micro_);
        for (int k = 0; k < 2; ++k) meanderPhase_[k] = 2 * std::numbers::pi * unit(rng);
    }

    struct Sample {
        float z, depth;   // terrain [m]; water depth [m], 0 where dry
        float bank;       // distance to the nearest channel bank [m] (centreline distance - half width)
    };

    // Centreline y of the river at x, and its slope dy/dx.
    void centreline(double x, double& y, double& dydx) const {
        y = l_.riverYFraction * extentY_;
        dydx = 0;
        for (int k = 0; k < 2; ++k) {
            const double w = 2 * std::numbers::pi / l_.meanderLen[k], a = w * x + meanderPhase_[k];
            y += l_.meanderAmp[k] * std::sin(a);
            dydx += l_.meanderAmp[k] * w * std::cos(a);
        }
    }
    double floorAt(double x) const { return l_.z0 - l_.riverSlope * x; }
    double waterLevelAt(double x) const { return floorAt(x) + l_.floodHeight; }

    Sample at(double x, double y) const {
        double yc, dydx;
        centreline(x, yc, dydx);
        const double d = std::abs(y - yc) / std::sqrt(1 + dydx * dydx);  // distance to the centreline, nearly
        const double floor = floorAt(x);
        // 0 on the floodplain, 1 on the uplands, smooth in between.
        double t = std::clamp((d - l_.floorHalfWidth) / l_.sideWidth, 0.0, 1.0);
        t = t * t * (3 - 2 * t);
        double z = floor;
        if (t < 1) z += (1 - t) * l_.microAmp * sum(micro_, x, y);
        if (t > 0) {
            const double large = sum(large_, x, y);  // [-1, 1]
            const double relief = l_.reliefAmp * (1 + 0.5 * large);
            const double hills = l_.hillAmp * (0.5 + 0.5 * large) * sum(hills_, x, y);
            z += t * (relief + hills);
        }
        if (d < l_.channelHalfWidth) {
            const double r = d / l_.channelHalfWidth;
            z -= l_.channelDepth * (1 - r * r);
        }
        const double depth = std::max(0.0, waterLevelAt(x) - z);
        return {static_cast<float>(z), static_cast<float>(depth), static_cast<float>(d - l_.channelHalfWidth)};
    }

private:
    static double sum(const std::vector<Wave>& waves, double x, double y) {
        double s = 0;
        for (const Wave& w : waves) s += w.amp * std::sin(w.kx * x + w.ky * y + w.phase);
        return s;
    }
    Landscape l_;
    double extentY_;
    double meanderPhase_[2] = {};
    std::vector<Wave> large_, hills_, micro_;
};

// ---------------- the quadtree ----------------

struct Leaf {
    uint32_t ix, iy;
    int level;
    float z, depth;
};

// Top-down refinement of one scenario's domain (see the top of the file).
class Refiner {
public:
    Refiner(const Terrain& t, double finestM, int maxLevel, uint32_t extentX, uint32_t extentY)
        : t_(t), f_(finestM), maxLevel_(maxLevel), ex_(extentX), ey_(extentY) {}

    // Visits the tree under node (ix, iy, level) with threshold T; appends leaves when `out` is given,
    // and returns the leaf count. Stops early (returning what it has) once the count passes `cap`.
    uint64_t run(uint32_t ix, uint32_t iy, int level, double T, std::vector<Leaf>* out, uint64_t cap) const {
        std::array<Terrain::Sample, 9> s;
        const double size = f_ * double(uint64_t{1} << level);
        for (int b = 0; b < 3; ++b)
            for (int a = 0; a < 3; ++a) s[size_t(b * 3 + a)] = t_.at(ix * f_ + a * size / 2, iy * f_ + b * size / 2);
        uint64_t count = 0;
        visit(ix, iy, level, s, float(T), out, count, cap);
        return count;
    }

private:
    // s: the node's samples at its corners, edge midpoints and centre, row-major from the south-west.
    void visit(uint32_t ix, uint32_t iy, int level, const std::array<Terrain::Sample, 9>& s, float T, std::vector<Leaf>* out,
               uint64_t& count, uint64_t cap) const {
        if (count > cap) return;
        const uint32_t span = uint32_t{1} << level;
        if (ix >= ex_ || iy >= ey_) return;  // outside the extent: a hole (the extent is whole coarsest cells)
        const double size = f_ * double(span);
        bool split = level > maxLevel_;
        if (!split && level > 0) {
            int wet = 0;
            float zLo = s[0].z, zHi = s[0].z, dLo = s[0].depth, dHi = s[0].depth;
            for (const Terrain::Sample& p : s) {
                wet += p.depth > 0;
                zLo = std::min(zLo, p.z), zHi = std::max(zHi, p.z);
                dLo = std::min(dLo, p.depth), dHi = std::max(dHi, p.depth);
            }
            split = (wet > 0 && wet < 9) || zHi - zLo > T || dHi - dLo > T || std::abs(s[4].bank) < 0.7072f * float(size);
        }
        if (!split) {
            ++count;
            if (out) out->push_back({ix, iy, level, s[4].z, s[4].depth});
            return;
        }
        // The 5 x 5 lattice of the four children's samples: the parent's at even positions.
        std::array<Terrain::Sample, 25> q;
        const double step = size / 4;
        for (int b = 0; b < 5; ++b)
            for (int a = 0; a < 5; ++a)
                q[size_t(b * 5 + a)] = (a % 2 == 0 && b % 2 == 0) ? s[size_t(b / 2 * 3 + a / 2)]
                                                                   : t_.at(ix * f_ + a * step, iy * f_ + b * step);
        const uint32_t half = span / 2;
        for (int c = 0; c < 4; ++c) {  // Morton order: south-west, south-east, north-west, north-east
            const int cx = c & 1, cy = c >> 1;
            std::array<Terrain::Sample, 9> cs;
            for (int b = 0; b < 3; ++b)
                for (int a = 0; a < 3; ++a) cs[size_t(b * 3 + a)] = q[size_t((2 * cy + b) * 5 + 2 * cx + a)];
            visit(ix + uint32_t(cx) * half, iy + uint32_t(cy) * half, level - 1, cs, T, out, count, cap);
        }
    }

    const Terrain& t_;
    double f_;
    int maxLevel_;
    uint32_t ex_, ey_;  // extent in finest units
};

struct Generated {
    Grid grid;
    double thresholdM = 0;   // the calibrated T
    double calibrationS = 0, buildS = 0;
    uint64_t sampleTiles = 0, tiles = 0;
    bool finestRaised = false;
};

uint64_t hash64(uint64_t x) {  // splitmix64's finaliser: a fixed, well-spread tile sample
    x += 0x9e3779b97f4a7c15ull;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    return x ^ (x >> 31);
}

Generated generate(const Scenario& sc, double scale, unsigned threads) {
    Generated gen;
    const double extentX = std::round(sc.extentXKm * 1000 / kCoarsestM) * kCoarsestM;  // whole coarsest cells
    const double extentY = std::round(sc.extentYKm * 1000 / kCoarsestM) * kCoarsestM;
    const Terrain terrain(sc.land, extentY);
    const double target = sc.reportCellsM * 1e6 / scale;
    double finest = sc.finestM;
    for (;;) {
        const int maxLevel = int(std::lround(std::log2(kCoarsestM / finest)));
        const int tileLevel = maxLevel + kTileLevelsAboveCoarsest;
        const uint32_t ex = uint32_t(std::lround(extentX / finest)), ey = uint32_t(std::lround(extentY / finest));
        int rootLevel = tileLevel;
        while ((uint64_t{1} << rootLevel) < std::max(ex, ey)) ++rootLevel;
        // Tiles in Morton order.
        const uint32_t ntx = (ex + (1u << tileLevel) - 1) >> tileLevel, nty = (ey + (1u << tileLevel) - 1) >> tileLevel;
        std::vector<std::array<uint32_t, 2>> tiles;
        for (uint32_t ty = 0; ty < nty; ++ty)
            for (uint32_t tx = 0; tx < ntx; ++tx) tiles.push_back({tx, ty});
        std::sort(tiles.begin(), tiles.end(), [](const auto& a, const auto& b) { return hc::mortonEncode(a[0], a[1]) < hc::mortonEncode(b[0], b[1]); });
        std::vector<size_t> sample;
        for (size_t k = 0; k < tiles.size(); ++k)
            if (tiles.size() < 256 || hash64(uint64_t(tiles[k][0]) << 32 | tiles[k][1]) % 8 == 0) sample.push_back(k);
        const double sampleScale = double(tiles.size()) / double(sample.size());
        const Refiner refiner(terrain, finest, maxLevel, ex, ey);

        // Cells for threshold T over a list of tiles, scaled by `factor` (capped: past the cap is only "too many").
        auto count = [&](double T, const std::vector<size_t>& which, double factor) {
            const uint64_t cap = uint64_t(4 * target / factor) + 1000;
            std::atomic<uint64_t> total{0};
            hc::parallelFor(which.size(), 1, threads, [&](size_t b, size_t e, unsigned) {
                for (size_t k = b; k < e; ++k) {
                    if (total.load(std::memory_order_relaxed) > cap) return;
                    const auto& tl = tiles[which[k]];
                    total += refiner.run(tl[0] << tileLevel, tl[1] << tileLevel, tileLevel, T, nullptr, cap);
                }
            });
            return double(total.load()) * factor;
        };
        std::vector<size_t> all(tiles.size());
        for (size_t k = 0; k < all.size(); ++k) all[k] = k;
        auto t0 = Clock::now();
        const double fewest = count(1e4, sample, sampleScale);
        if (fewest > target && finest * 2 < kCoarsestM) {
            finest *= 2;  // the forced cells alone are too many: coarser finest cells
            gen.finestRaised = true;
            continue;
        }
        // Bisection in log T on the sample's estimate, aiming at target / bias; then one full count at the
        // result measures the sample's bias (the river crosses few sample tiles), and the bisection repeats.
        gen.thresholdM = 1e4;  // fewest >= target: as coarse as it gets (the table shows the miss)
        double bias = 1;
        for (int round = 0; round < 3 && fewest < target; ++round) {
            double lo = 1e-3, hi = 1e4;  // estimate(lo) >= target >= estimate(hi)
            for (int it = 0; it < 40; ++it) {
                const double mid = std::sqrt(lo * hi);
                const double n = count(mid, sample, sampleScale) * bias;
                (n > target ? lo : hi) = mid;
                gen.thresholdM = mid;
                if (std::abs(n / target - 1) < 0.01 || hi / lo < 1.001) break;
            }
            if (sample.size() == all.size()) break;  // the sample is every tile: exact already
            const double full = count(gen.thresholdM, all, 1.0);
            if (std::abs(full / target - 1) < 0.03) break;
            bias *= full / target;
        }
        gen.calibrationS = secondsSince(t0);
        gen.sampleTiles = sample.size();
        gen.tiles = tiles.size();

        // The grid: every tile in parallel into its own list, then appended in order.
        t0 = Clock::now();
        std::vector<std::vector<Leaf>> leaves(tiles.size());
        hc::parallelFor(tiles.size(), 1, threads, [&](size_t b, size_t e, unsigned) {
            for (size_t k = b; k < e; ++k)
                refiner.run(tiles[k][0] << tileLevel, tiles[k][1] << tileLevel, tileLevel, gen.thresholdM, &leaves[k], UINT64_MAX);
        });
        Grid& g = gen.grid;
        g.originWorldX = sc.originX;
        g.originWorldY = sc.originY;
        g.finestCellM = finest;
        g.rootLevel = rootLevel;
        g.minLevel = 0;
        g.maxLevel = maxLevel;
        g.layers.push_back({"water_depth", "m"});
        g.values.emplace_back();
        size_t total = 0;
        for (const auto& l : leaves) total += l.size();
        g.codes.reserve(total);
        for (auto& v : g.values) v.reserve(total);
        for (auto& l : leaves) {
            for (const Leaf& c : l) {
                const float values[2] = {c.z, c.depth};
                g.appendCell(c.ix, c.iy, c.level, values);
            }
            std::vector<Leaf>().swap(l);  // free as we go
        }
        gen.buildS = secondsSince(t0);
        return gen;
    }
}

// ---------------- one scenario, in a child ----------------

struct CascadeOut {
    double nearM, farM, texelM, approximationMs;
    uint64_t visibleTexels, gaussians;
};

// What a scenario's child reports. Plain bytes through a pipe, so trivially copyable.
struct RunResult {
    double extentXM = 0, extentYM = 0, finestM = 0, coarsestM = 0;
    uint64_t cells = 0, wetCells = 0;
    uint64_t cellsPerLevel[kMaxLevels] = {};
    double thresholdM = 0, calibrationS = 0, generationS = 0;
    uint64_t sampleTiles = 0, tiles = 0;
    bool finestRaised = false;
    double listsMs = 0, listMean = 0;
    uint64_t listP99 = 0, listMax = 0, listBytes = 0;
    double camera[6] = {};  // x, y, z (world), yaw, pitch, fov
    int width = 0, height = 0, repeats = 0;
    // Best over the repeats, per stage.
    double fittingMs = 1e300, approximationMs = 1e300, mipmapMs = 1e300, raycastMs = 1e300, shadingMs = 1e300, totalMs = 1e300;
    double worstApproximationMs = 0, worstRaycastMs = 0;
    double gpuMs = 1e300, readbackMs = 0;  // GL: best GPU span; one read-back of the frame to host memory
    uint64_t gaussians = 0, rays = 0, hits = 0, wetHits = 0;
    int cascadeCount = 0;
    CascadeOut cascades[4] = {};  // of the run with the best approximation time
    uint64_t baselineRss = 0, gridRss = 0, peakRss = 0;  // bytes: before generating; after the grid; at the end
    char image[512] = {};         // the PNG written, or empty
    char device[256] = {};        // what rendered: "CPU" or the GL renderer and version
    // --fly-frames (CPU): means over frames 2..N of a camera flying forward, without and with a CascadeCache.
    double flyApproxFreshMs = 0, flyApproxCachedMs = 0, flyTotalFreshMs = 0, flyTotalCachedMs = 0, flyKept = 0;
};

struct Settings {
    double scale = 1;
    int width = 1920, height = 1080, repeat = 3;
    hc::render::RenderOptions options;
    std::string imagesDir;
    bool interactive = false;
    hc::cli::Backend backend = hc::cli::Backend::Cpu;  // Cpu or Gl (Auto is resolved in main)
    int flyFrames = 0;      // after the timed frames: a fly-through of this many frames, fresh and incremental (CPU)
    double flyStepM = 10;   // metres forward per fly-through frame
};

// The fixed camera: 1.5 km above the river 10 % of the way downstream, looking along it at pitch -20.
hc::render::Camera floodCamera(const Scenario& sc, const Grid& g, int width, int height) {
    const double extentY = std::round(sc.extentYKm * 1000 / kCoarsestM) * kCoarsestM;
    const double extentX = std::round(sc.extentXKm * 1000 / kCoarsestM) * kCoarsestM;
    const Terrain terrain(sc.land, extentY);
    const double aboveM = 1500, pitch = -20;
    double ey, ey2, dydx;
    const double ex = 0.1 * extentX;
    terrain.centreline(ex, ey, dydx);
    const double ex2 = ex + aboveM / std::tan(-pitch * std::numbers::pi / 180);  // where the centre ray meets the floor
    terrain.centreline(ex2, ey2, dydx);
    hc::render::Camera c;
    c.xWorld = g.originWorldX + ex;
    c.yWorld = g.originWorldY + ey;
    c.zWorld = terrain.waterLevelAt(ex) + aboveM;
    c.yawDeg = std::atan2(ex2 - ex, ey2 - ey) * 180 / std::numbers::pi;
    c.pitchDeg = pitch;
    c.fovYDeg = 50;
    c.width = width;
    c.height = height;
    return c;
}

RunResult runScenario(const Scenario& sc, const Settings& set) {
    return inChild<RunResult>(sc.name, [&](RunResult& r) {
        auto say = [&](const char* what) {
            if (set.interactive) std::fprintf(stderr, "\r%-14s %-40s", sc.name, what);
        };
        r.baselineRss = hc::currentRssBytes();
        say("generating the grid ...");
        auto t0 = Clock::now();
        Generated gen = generate(sc, set.scale, set.options.threads);
        r.generationS = secondsSince(t0);
        const Grid& g = gen.grid;
        if (std::string why = g.validate(); !why.empty()) throw hc::Error("generated grid is invalid: " + why);
        r.gridRss = hc::currentRssBytes();
        r.extentXM = std::round(sc.extentXKm * 1000 / kCoarsestM) * kCoarsestM;
        r.extentYM = std::round(sc.extentYKm * 1000 / kCoarsestM) * kCoarsestM;
        r.finestM = g.finestCellM;
        r.coarsestM = g.levelSizeM(g.maxLevel);
        r.cells = g.cellCount();
        for (float d : g.values[1]) r.wetCells += d > 0;
        const auto per = g.cellsPerLevel();
        for (size_t l = 0; l < per.size() && l < size_t(kMaxLevels); ++l) r.cellsPerLevel[l] = per[l];
        r.thresholdM = gen.thresholdM;
        r.calibrationS = gen.calibrationS;
        r.sampleTiles = gen.sampleTiles;
        r.tiles = gen.tiles;
        r.finestRaised = gen.finestRaised;

        say("building influence lists ...");
        t0 = Clock::now();
        const hc::influence::InfluenceLists lists = hc::influence::buildInfluenceLists(g, hc::influence::KernelParams{}, set.options.threads);
        r.listsMs = secondsSince(t0) * 1e3;
        const auto st = lists.stats();
        r.listMean = st.meanLength;
        r.listP99 = st.p99Length;
        r.listMax = st.maxLength;
        r.listBytes = st.bytes;

        const hc::render::Scene scene(g, lists);
        const hc::render::Camera cam = floodCamera(sc, g, set.width, set.height);
        r.camera[0] = cam.xWorld, r.camera[1] = cam.yWorld, r.camera[2] = cam.zWorld;
        r.camera[3] = cam.yawDeg, r.camera[4] = cam.pitchDeg, r.camera[5] = cam.fovYDeg;
        r.width = set.width;
        r.height = set.height;
        r.repeats = set.repeat;
        hc::render::Frame frame;
        // The GL backend: a headless context in this child; one unmeasured warm-up frame first, since
        // drivers (llvmpipe among them) compile shaders at their first dispatch.
        std::unique_ptr<hc::render::GlRenderer> gl;
        std::snprintf(r.device, sizeof r.device, "CPU, %u threads", hc::resolveThreads(set.options.threads));
        if (set.backend == hc::cli::Backend::Gl) {
            // Warm-up frames, unmeasured, for at least a second: drivers compile shaders at the first dispatch, and an
            // idle GPU takes a moment to leave its idle clocks (on an H100 the first scene's stages ran 2-3x slower
            // after a single warm-up frame).
            say("GL warm-up frames ...");
            gl = hc::render::GlRenderer::headless(scene);
            std::snprintf(r.device, sizeof r.device, "%s", gl->deviceName().c_str());
            const auto warmStart = Clock::now();
            do {
                hc::render::Timings warm;
                gl->renderToTexture(cam, set.options, warm);
            } while (secondsSince(warmStart) < 1.0);
        }
        for (int k = 0; k < set.repeat; ++k) {
            say(fmt("rendering, frame %d of %d ...", k + 1, set.repeat).c_str());
            hc::render::Timings tm;
            // GL: the measured frames end in the texture, as the viewer draws them; the picture is read back once below.
            if (gl) gl->renderToTexture(cam, set.options, tm);
            else frame = hc::render::renderFrame(scene, cam, set.options, tm);
            r.gpuMs = std::min(r.gpuMs, tm.gpuMs);
            r.fittingMs = std::min(r.fittingMs, tm.fittingMs);
            r.mipmapMs = std::min(r.mipmapMs, tm.mipmapMs);
            r.raycastMs = std::min(r.raycastMs, tm.raycastMs);
            r.shadingMs = std::min(r.shadingMs, tm.shadingMs);
            r.totalMs = std::min(r.totalMs, tm.totalMs);
            r.worstApproximationMs = std::max(r.worstApproximationMs, tm.approximationMs);
            r.worstRaycastMs = std::max(r.worstRaycastMs, tm.raycastMs);
            if (tm.approximationMs < r.approximationMs) {
                r.approximationMs = tm.approximationMs;
                r.gaussians = 0;
                r.cascadeCount = int(std::min<size_t>(tm.cascades.size(), 4));
                for (size_t c = 0; c < tm.cascades.size(); ++c) {
                    const auto& cs = tm.cascades[c];
                    r.gaussians += cs.gaussians;
                    if (c < 4) r.cascades[c] = {cs.nearM, cs.farM, cs.texelM, cs.approximationMs, cs.visibleTexels, cs.gaussians};
                }
            }
            r.rays = tm.rays;
            r.hits = tm.hits;
        }
        if (!gl && set.flyFrames > 1) {
            // The camera flies forward (horizontally, along its yaw) flyStepM a frame: every frame evaluated afresh,
            // then the same frames through a CascadeCache (incremental cascades). Means over frames 2..N (the
            // first has nothing to reuse).
            for (int cached = 0; cached < 2; ++cached) {
                hc::render::CascadeCache cache;
                double approx = 0, total = 0;
                uint64_t kept = 0, visible = 0;
                for (int k = 0; k < set.flyFrames; ++k) {
                    say(fmt("fly-through %s, frame %d of %d ...", cached ? "with the cache" : "fresh", k + 1, set.flyFrames).c_str());
                    hc::render::Camera c = cam;
                    const double yaw = cam.yawDeg * std::numbers::pi / 180;
                    c.xWorld += std::sin(yaw) * set.flyStepM * k, c.yWorld += std::cos(yaw) * set.flyStepM * k;
                    hc::render::Timings tm;
                    (void)hc::render::renderFrame(scene, c, set.options, tm, cached ? &cache : nullptr);
                    if (k == 0) continue;
                    approx += tm.approximationMs, total += tm.totalMs;
                    for (const auto& cs : tm.cascades) kept += cs.reusedTexels, visible += cs.visibleTexels;
                }
                const double frames = set.flyFrames - 1;
                (cached ? r.flyApproxCachedMs : r.flyApproxFreshMs) = approx / frames;
                (cached ? r.flyTotalCachedMs : r.flyTotalFreshMs) = total / frames;
                if (cached) r.flyKept = visible ? double(kept) / double(visible) : 0;
            }
        }
        if (gl) {
            say("reading the frame back ...");
            hc::render::Timings tm;
            frame = gl->render(cam, set.options, tm);
            r.readbackMs = tm.readbackMs;
        }
        for (size_t i = 0; i < frame.waterDepthM.size(); ++i) r.wetHits += frame.waterDepthM[i] > 0;
        if (!set.imagesDir.empty()) {
            const std::string path = (fs::path(set.imagesDir) / (std::string(sc.name) + ".png")).string();
            hc::render::writePng(frame, path);
            std::snprintf(r.image, sizeof r.image, "%s", path.c_str());
        }
        r.peakRss = hc::peakRssBytes();
        say("");
    });
}

// ---------------- output ----------------

double mb(uint64_t bytes) { return double(bytes) / 1e6; }

std::string sizesText(const RunResult& r) { return fmt("%g - %g", r.finestM, r.coarsestM); }
std::string extentText(const RunResult& r) { return fmt("%.1f x %.1f", r.extentXM / 1e3, r.extentYM / 1e3); }
double gaussiansPerS(const RunResult& r) { return double(r.gaussians) / (r.approximationMs / 1e3); }
double raysPerS(const RunResult& r) { return double(r.rays) / (r.raycastMs / 1e3); }
bool approximationMet(const RunResult& r) { return gaussiansPerS(r) >= kTargetGaussiansPerS; }
bool glFrameMet(const RunResult& r) { return r.gpuMs < 1e300 && r.totalMs <= kTargetGlFrameMs; }
bool raycastMet(const RunResult& r) {
    return (r.width == 1920 && r.height == 1080) ? r.raycastMs <= kTargetRaycastMs : raysPerS(r) >= kTargetRaysPerS;
}

std::string jsonString(const std::string& s) {
    std::string o = "\"";
    for (char c : s) {
        if (c == '"' || c == '\\') o += '\\';
        if (static_cast<unsigned char>(c) < 0x20) {
            o += fmt("\\u%04x", c);
            continue;
        }
        o += c;
    }
    return o + "\"";
}

void writeJson(const std::vector<const Scenario*>& scs, const std::vector<RunResult>& rs, const Settings& set, const std::string& path) {
    std::ofstream f(path);
    if (!f) throw hc::Error(path + ": cannot open for writing (--json)");
    f << "[";
    for (size_t k = 0; k < rs.size(); ++k) {
        const Scenario& sc = *scs[k];
        const RunResult& r = rs[k];
        f << (k ? ",\n" : "\n") << "  {\"scenario\": " << jsonString(sc.name);
        f << fmt(", \"cells\": %llu, \"approximation_ms\": %.3f, \"raycast_ms\": %.3f, \"gaussians_per_s\": %.6g, \"rays_per_s\": %.6g, "
                 "\"peak_rss_mb\": %.1f,\n",
                 (unsigned long long)r.cells, r.approximationMs, r.raycastMs, gaussiansPerS(r), raysPerS(r), mb(r.peakRss));
        f << fmt("   \"scale\": %g, \"target_cells\": %.0f, \"extent_x_m\": %.0f, \"extent_y_m\": %.0f, \"finest_m\": %g, \"coarsest_m\": %g, "
                 "\"wet_cells\": %llu, \"threshold_m\": %.6g, \"generation_s\": %.3f, \"calibration_s\": %.3f,\n",
                 set.scale, sc.reportCellsM * 1e6 / set.scale, r.extentXM, r.extentYM, r.finestM, r.coarsestM,
                 (unsigned long long)r.wetCells, r.thresholdM, r.generationS, r.calibrationS);
        f << "   \"cells_per_level\": [";
        for (int l = 0; l <= int(std::lround(std::log2(r.coarsestM / r.finestM))) && l < kMaxLevels; ++l)
            f << (l ? ", " : "") << r.cellsPerLevel[l];
        f << "],\n";
        f << fmt("   \"lists_ms\": %.3f, \"list_mean\": %.3f, \"list_p99\": %llu, \"list_max\": %llu, \"lists_mb\": %.3f,\n", r.listsMs,
                 r.listMean, (unsigned long long)r.listP99, (unsigned long long)r.listMax, mb(r.listBytes));
        f << fmt("   \"camera\": {\"x\": %.3f, \"y\": %.3f, \"z\": %.3f, \"yaw_deg\": %.4f, \"pitch_deg\": %.4f, \"fov_y_deg\": %.4f}, "
                 "\"width\": %d, \"height\": %d, \"cascades_requested\": %d, \"texels\": %d, \"repeat\": %d,\n",
                 r.camera[0], r.camera[1], r.camera[2], r.camera[3], r.camera[4], r.camera[5], r.width, r.height, set.options.cascades,
                 set.options.texelsPerSide, r.repeats);
        f << fmt("   \"fitting_ms\": %.3f, \"mipmap_ms\": %.3f, \"shading_ms\": %.3f, \"total_ms\": %.3f, \"worst_approximation_ms\": %.3f, "
                 "\"worst_raycast_ms\": %.3f, \"gaussians\": %llu, \"rays\": %llu, \"hits\": %llu, \"water_hits\": %llu,\n",
                 r.fittingMs, r.mipmapMs, r.shadingMs, r.totalMs, r.worstApproximationMs, r.worstRaycastMs, (unsigned long long)r.gaussians,
                 (unsigned long long)r.rays, (unsigned long long)r.hits, (unsigned long long)r.wetHits);
        f << fmt("   \"backend\": \"%s\", \"device\": %s, \"gpu_ms\": %.3f, \"readback_ms\": %.3f", hc::cli::backendName(set.backend),
                 jsonString(r.device).c_str(), r.gpuMs < 1e300 ? r.gpuMs : 0.0, r.readbackMs);
        if (set.backend == hc::cli::Backend::Gl) f << fmt(", \"gl_frame_target\": \"%s\"", glFrameMet(r) ? "met" : "MISSED");
        f << ",\n";
        f << "   \"cascades\": [";
        for (int c = 0; c < r.cascadeCount; ++c) {
            const CascadeOut& cs = r.cascades[c];
            f << fmt("%s{\"near_m\": %.3f, \"far_m\": %.3f, \"texel_m\": %.6g, \"visible_texels\": %llu, \"gaussians\": %llu, \"approximation_ms\": %.3f}",
                     c ? ", " : "", cs.nearM, cs.farM, cs.texelM, (unsigned long long)cs.visibleTexels, (unsigned long long)cs.gaussians,
                     cs.approximationMs);
        }
        f << "],\n";
        f << fmt("   \"report_gtx1080_approximation_ms\": %.1f, \"report_gtx1080_raycast_ms\": %.1f, \"baseline_rss_mb\": %.1f, "
                 "\"grid_rss_mb\": %.1f, \"approximation_target\": \"%s\", \"raycast_target\": \"%s\"",
                 sc.gpuApproxMs, sc.gpuRaycastMs, mb(r.baselineRss), mb(r.gridRss), approximationMet(r) ? "met" : "MISSED",
                 raycastMet(r) ? "met" : "MISSED");
        if (r.image[0]) f << ", \"image\": " << jsonString(r.image);
        if (set.flyFrames > 1 && set.backend == hc::cli::Backend::Cpu)
            f << fmt(",\n   \"fly_frames\": %d, \"fly_step_m\": %g, \"fly_approximation_ms_fresh\": %.3f, \"fly_approximation_ms_cached\": %.3f, "
                     "\"fly_total_ms_fresh\": %.3f, \"fly_total_ms_cached\": %.3f, \"fly_texels_kept\": %.4f",
                     set.flyFrames, set.flyStepM, r.flyApproxFreshMs, r.flyApproxCachedMs, r.flyTotalFreshMs, r.flyTotalCachedMs, r.flyKept);
        f << "}";
    }
    f << "\n]\n";
    if (!f.flush()) throw hc::Error(path + ": write failed (--json)");
}

void writeCsv(const std::vector<const Scenario*>& scs, const std::vector<RunResult>& rs, const Settings& set, const std::string& path) {
    std::ofstream f(path);
    if (!f) throw hc::Error(path + ": cannot open for writing (--csv)");
    f << "scenario,scale,extent_x_m,extent_y_m,finest_m,coarsest_m,target_cells,cells,wet_cells,threshold_m,generation_s,lists_ms,list_mean,"
         "lists_mb,width,height,cascades,texels,fitting_ms,approximation_ms,mipmap_ms,raycast_ms,shading_ms,total_ms,gaussians,"
         "gaussians_per_s,rays,rays_per_s,peak_rss_mb,gtx1080_approximation_ms,gtx1080_raycast_ms,approximation_target,raycast_target,"
         "gpu_ms,readback_ms\n";
    for (size_t k = 0; k < rs.size(); ++k) {
        const Scenario& sc = *scs[k];
        const RunResult& r = rs[k];
        f << fmt("%s,%g,%.0f,%.0f,%g,%g,%.0f,%llu,%llu,%.6g,%.3f,%.3f,%.3f,%.3f,%d,%d,%d,%d,%.3f,%.3f,%.3f,%.3f,%.3f,%.3f,%llu,%.6g,%llu,%.6g,"
                 "%.1f,%.1f,%.1f,%s,%s,%.3f,%.3f\n",
                 sc.name, set.scale, r.extentXM, r.extentYM, r.finestM, r.coarsestM, sc.reportCellsM * 1e6 / set.scale,
                 (unsigned long long)r.cells, (unsigned long long)r.wetCells, r.thresholdM, r.generationS, r.listsMs, r.listMean,
                 mb(r.listBytes), r.width, r.height, set.options.cascades, set.options.texelsPerSide, r.fittingMs, r.approximationMs,
                 r.mipmapMs, r.raycastMs, r.shadingMs, r.totalMs, (unsigned long long)r.gaussians, gaussiansPerS(r),
                 (unsigned long long)r.rays, raysPerS(r), mb(r.peakRss), sc.gpuApproxMs, sc.gpuRaycastMs,
                 approximationMet(r) ? "met" : "MISSED", raycastMet(r) ? "met" : "MISSED", r.gpuMs < 1e300 ? r.gpuMs : 0.0, r.readbackMs);
    }
    if (!f.flush()) throw hc::Error(path + ": write failed (--csv)");
}

}  // namespace

int main(int argc, char** argv) {
    return hc::cli::run("hc-bench", [&] {
        Settings set;
        std::string size = "1920x1080", scenarios = "Marchfeld,Petzenkirchen,Wachau,Florence", csv, json, plot, backendText = "cpu";
        hc::cli::Parser p("hc-bench", "[options]",
                          "Benchmarks the CPU renderer on synthetic stand-ins for the technical report's four flood scenes\n"
                          "(Marchfeld 82.9 x 57.1 km, 3-96 m cells, 7.46 M cells; Petzenkirchen 15.4 x 16.0 km, 0.75-96 m, 1.81 M;\n"
                          "Wachau 24.1 x 16.5 km, 3-96 m, 1.95 M; Florence 44.6 x 28.2 km, 3-96 m, 4.53 M): terrain with a meandering\n"
                          "river valley and a flood (water_depth), generated deterministically as an adaptive quadtree with about\n"
                          "the report's cell count. Each scenario runs in its own process: generate, build the influence lists\n"
                          "(sigma 1, R 3.5), render --repeat frames from a fixed oblique camera over the flood; it prints the best\n"
                          "stage times beside the report's GTX 1080 times, Gaussians/s, rays/s and peak RSS, then checks the\n"
                          "targets (approximation >= 2 G Gaussians/s; ray casting of 1920x1080 within 250 ms). MB = 10^6 bytes.");
        p.option("--scale", "F", "divide every scenario's cell count by F >= 1 (a weaker refinement threshold; the finest size\n"
                 "      doubles only where the forced wet-edge and bank cells alone exceed the count) (default 1)", set.scale);
        p.option("--scenarios", "LIST", "comma-separated subset, in the order given (default Marchfeld,Petzenkirchen,Wachau,Florence)", scenarios);
        p.option("--size", "WxH", "image size in pixels (default 1920x1080)", size);
        p.option("--cascades", "K", "cascades per frame, 1..4 (default 3)", set.options.cascades);
        p.option("--texels", "N", "texels per cascade side, 16..8192 (default 1024)", set.options.texelsPerSide);
        p.option("--repeat", "N", "frames rendered per scenario; each stage's time is the best frame's (default 3)", set.repeat);
        p.option("--threads", "N", "worker threads for generation, lists and rendering (default 0 = all cores)", set.options.threads);
        p.option("--images", "DIR", "also write each scenario's last frame as DIR/SCENARIO.png; DIR is created if missing\n"
                 "      (default: none)", set.imagesDir);
        p.option("--backend", "B", "cpu or gl: the OpenGL 4.3 compute backend in a headless context, stage times from GPU timer\n"
                 "      queries, after one unmeasured warm-up frame (default cpu)", backendText);
        p.option("--csv", "OUT.csv", "also write one row per scenario as CSV with a header line (default: none)", csv);
        p.option("--json", "OUT.json", "also write a JSON array, one object per scenario (scenario, cells, approximation_ms,\n"
                 "      raycast_ms, gaussians_per_s, rays_per_s, peak_rss_mb, and more) (default: none)", json);
        p.option("--fly-frames", "N", "CPU: after the timed frames, fly the camera forward for N frames, each evaluated afresh and\n"
                 "      then with incremental cascades (texels kept from the last frame); prints both (default 0: off)", set.flyFrames);
        p.option("--fly-step", "M", "metres the camera moves forward per fly-through frame (default 10)", set.flyStepM);
        p.option("--plot", "OUT.svg", "also draw each scenario's best stage times as stacked bars with the targets, SVG\n"
                 "      (default: none)", plot);
        if (!p.parse(argc, argv)) return 0;
        if (!(set.scale >= 1)) throw hc::Error("--scale " + fmt("%g", set.scale) + ": must be at least 1");
        if (set.repeat < 1) throw hc::Error("--repeat " + std::to_string(set.repeat) + ": must be at least 1");
        set.backend = hc::cli::parseBackend(backendText);
        if (set.backend == hc::cli::Backend::Auto) throw hc::Error("--backend auto: a benchmark names its backend, cpu or gl");
        if (set.flyFrames < 0 || set.flyFrames == 1) throw hc::Error("--fly-frames " + std::to_string(set.flyFrames) + ": 0 (off) or at least 2");
        if (set.flyFrames > 0 && set.backend != hc::cli::Backend::Cpu) throw hc::Error("--fly-frames: the CPU backend's (incremental cascades)");
        if (!(set.flyStepM >= 0) || !std::isfinite(set.flyStepM)) throw hc::Error("--fly-step " + fmt("%g", set.flyStepM) + ": metres >= 0");
        if (std::string why = set.options.validate(); !why.empty()) throw hc::Error(why);
        {
            auto x = size.find('x');
            if (x == std::string::npos) throw hc::Error("--size " + size + ": expected WxH, e.g. 1920x1080");
            const double w = hc::cli::parseNumber(size.substr(0, x), "--size"), h = hc::cli::parseNumber(size.substr(x + 1), "--size");
            if (w != std::floor(w) || h != std::floor(h) || w < 1 || h < 1 || w > 16384 || h > 16384)
                throw hc::Error("--size " + size + ": width and height must be whole numbers in 1..16384");
            set.width = int(w), set.height = int(h);
        }
        std::vector<const Scenario*> chosen;
        for (const std::string& name : splitList(scenarios, "--scenarios")) {
            const Scenario* found = nullptr;
            for (const Scenario& sc : kScenarios)
                if (name == sc.name) found = &sc;
            if (!found) throw hc::Error("--scenarios " + name + ": not a scenario (Marchfeld, Petzenkirchen, Wachau or Florence)");
            chosen.push_back(found);
        }
        for (const std::string* o : {&csv, &json, &plot})
            if (!o->empty()) hc::cli::checkWritable(*o, o == &csv ? "--csv" : o == &json ? "--json" : "--plot");
        if (!set.imagesDir.empty()) {
            std::error_code ec;
            fs::create_directories(set.imagesDir, ec);
            if (!fs::is_directory(set.imagesDir)) throw hc::Error(set.imagesDir + ": cannot create the image folder (--images)");
        }
        set.interactive = isatty(STDERR_FILENO);
        const unsigned threads = hc::resolveThreads(set.options.threads);

        std::printf("hc-bench: %u worker thread%s (hardware threads: %u), scale %g, %dx%d, %d cascade%s of %d^2 texels, best of %d\n",
                    threads, threads == 1 ? "" : "s", std::thread::hardware_concurrency(), set.scale, set.width, set.height,
                    set.options.cascades, set.options.cascades == 1 ? "" : "s", set.options.texelsPerSide, set.repeat);
        std::printf("load average (1 min) at start: %s\n", loadAverage().c_str());
        const auto wall = Clock::now();
        std::vector<RunResult> results;
        for (const Scenario* sc : chosen) results.push_back(runScenario(*sc, set));
        if (set.interactive) std::fprintf(stderr, "\r%60s\r", "");
        const double wallS = secondsSince(wall);

        // ---- table 1: the grids ----
        std::printf("\n1. grids: synthetic, deterministic; extent rounded to whole 96 m cells; target = the report's cells / scale;\n"
                    "T = calibrated refinement threshold [m]; wet = cells with water; calib s = finding T, build s = building the\n"
                    "grid (neither is part of a frame); lists = buildInfluenceLists (sigma 1, R 3.5, all threads, one run): time,\n"
                    "mean / p99 / max entries per cell, offsets + indices\n\n");
        std::printf("%-14s %13s %10s %10s %10s %7s %8s %6s %7s %7s %9s %6s %5s %5s %8s\n", "scenario", "extents km", "cells m", "target",
                    "cells", "diff %", "T m", "wet %", "calib s", "build s", "lists ms", "mean", "p99", "max", "lists MB");
        for (size_t k = 0; k < results.size(); ++k) {
            const RunResult& r = results[k];
            const double target = chosen[k]->reportCellsM * 1e6 / set.scale;
            std::printf("%-14s %13s %10s %10.0f %10llu %+7.1f %8.3g %6.1f %7.1f %7.1f %9.1f %6.1f %5llu %5llu %8.1f\n", chosen[k]->name,
                        extentText(r).c_str(), sizesText(r).c_str(), target, (unsigned long long)r.cells, (double(r.cells) / target - 1) * 100,
                        r.thresholdM, 100.0 * double(r.wetCells) / double(r.cells), r.calibrationS, r.generationS - r.calibrationS,
                        r.listsMs, r.listMean,
                        (unsigned long long)r.listP99, (unsigned long long)r.listMax, mb(r.listBytes));
        }
        for (size_t k = 0; k < results.size(); ++k) {
            const RunResult& r = results[k];
            std::string counts;
            const int levels = int(std::lround(std::log2(r.coarsestM / r.finestM)));
            for (int l = 0; l <= levels && l < kMaxLevels; ++l)
                counts += fmt("%s%g m: %llu", l ? ", " : "", r.finestM * double(1 << l), (unsigned long long)r.cellsPerLevel[l]);
            std::printf("%-14s cells per size: %s%s\n", chosen[k]->name, counts.c_str(),
                        r.finestRaised ? " (finest size raised: the forced cells alone exceeded the scaled count)" : "");
        }

        // ---- table 2: the renderer, in the report's form ----
        std::printf("\n2. rendering with the %s backend (%s): %dx%d, %d cascade%s of %d^2 texels, best of %d frames per stage (worst in brackets); camera 1.5 km\n"
                    "above the river 10 %% downstream, looking along it, pitch -20, fov 50; G Gauss/s = kernel evaluations in\n"
                    "the approximation / its time; M rays/s = pixels / ray casting time; peak RSS = the scenario's process\n"
                    "(getrusage) at the end; GTX 1080 = the report's times for the real data\n\n",
                    hc::cli::backendName(set.backend), results.empty() ? "-" : results[0].device, set.width, set.height, set.options.cascades, set.options.cascades == 1 ? "" : "s", set.options.texelsPerSide,
                    set.repeat);
        std::printf("%-14s %13s %10s %7s %19s %19s %8s %7s %8s %8s %11s %10s %8s %11s %11s\n", "scenario", "extents km", "cells m",
                    "cells M", "approximation ms", "ray casting ms", "fit ms", "mip ms", "shade ms", "total ms", "G Gauss/s",
                    "M rays/s", "peak MB", "GTX appr ms", "GTX ray ms");
        for (size_t k = 0; k < results.size(); ++k) {
            const RunResult& r = results[k];
            std::printf("%-14s %13s %10s %7.2f %8.1f (%8.1f) %8.1f (%8.1f) %8.2f %7.1f %8.1f %8.1f %11.3f %10.2f %8.0f %11.1f %11.1f\n",
                        chosen[k]->name, extentText(r).c_str(), sizesText(r).c_str(), double(r.cells) / 1e6, r.approximationMs,
                        r.worstApproximationMs, r.raycastMs, r.worstRaycastMs, r.fittingMs, r.mipmapMs, r.shadingMs, r.totalMs,
                        gaussiansPerS(r) / 1e9, raysPerS(r) / 1e6, mb(r.peakRss), chosen[k]->gpuApproxMs, chosen[k]->gpuRaycastMs);
        }
        if (set.backend == hc::cli::Backend::Gl) {
            std::printf("\nGL frames: total = wall time of a frame ending in the texture, as hc-view draws it (fitting and visible spans on\n"
                        "the CPU, uploads, the GPU's stages, waiting for its timers); GPU = its span from the first stage's start to\n"
                        "shading's end; read back = copying one finished frame to host memory (hc-render's path, not the viewer's)\n");
            for (size_t k = 0; k < results.size(); ++k)
                std::printf("  %-14s total %7.2f ms   GPU %7.2f ms   CPU and waiting %7.2f ms   read back %7.2f ms\n", chosen[k]->name,
                            results[k].totalMs, results[k].gpuMs, results[k].totalMs - results[k].gpuMs, results[k].readbackMs);
        }
        std::printf("\ncascades (best approximation frame): offsets along the view [m], texel [m], visible texels, Gaussians, ms\n");
        for (size_t k = 0; k < results.size(); ++k) {
            const RunResult& r = results[k];
            for (int c = 0; c < r.cascadeCount; ++c) {
                const CascadeOut& cs = r.cascades[c];
                std::printf("  %-14s %d  %8.0f..%-8.0f %8.3g %9llu %11llu %8.1f\n", chosen[k]->name, c, cs.nearM, cs.farM, cs.texelM,
                            (unsigned long long)cs.visibleTexels, (unsigned long long)cs.gaussians, cs.approximationMs);
            }
            std::printf("  %-14s    hits %.1f %% of pixels, water %.1f %%; camera %.0f, %.0f, %.0f yaw %.1f\n", chosen[k]->name,
                        100.0 * double(r.hits) / double(r.rays), 100.0 * double(r.wetHits) / double(r.rays), r.camera[0], r.camera[1],
                        r.camera[2], r.camera[3]);
        }

        if (set.flyFrames > 1 && set.backend == hc::cli::Backend::Cpu) {
            std::printf("\nincremental cascades: the camera flies forward %g m a frame for %d frames; means over frames 2..%d,\n"
                        "every frame evaluated afresh against frames through a CascadeCache (texels kept from the last frame)\n\n",
                        set.flyStepM, set.flyFrames, set.flyFrames);
            std::printf("%-14s %16s %16s %6s %14s %14s %14s\n", "scenario", "approx ms fresh", "approx ms cache", "x", "frame ms fresh",
                        "frame ms cache", "texels kept %");
            for (size_t k = 0; k < results.size(); ++k) {
                const RunResult& r = results[k];
                std::printf("%-14s %16.1f %16.1f %6.1f %14.1f %14.1f %14.1f\n", chosen[k]->name, r.flyApproxFreshMs, r.flyApproxCachedMs,
                            r.flyApproxCachedMs > 0 ? r.flyApproxFreshMs / r.flyApproxCachedMs : 0.0, r.flyTotalFreshMs, r.flyTotalCachedMs,
                            100 * r.flyKept);
            }
        }

        // ---- targets ----
        const bool glRun = set.backend == hc::cli::Backend::Gl;
        std::printf("\ntargets%s\n", glRun ? "" : " (2 cores)");
        if (glRun) {
            std::printf("  GL whole frame (issue 5, on a GPU): 1920x1080, 3 x 1024^2 cascades, within %.0f ms%s\n", kTargetGlFrameMs,
                        set.width == 1920 && set.height == 1080 ? "" : " (this run is another size)");
            for (size_t k = 0; k < results.size(); ++k)
                std::printf("    %-14s %8.2f ms   %s\n", chosen[k]->name, results[k].totalMs, glFrameMet(results[k]) ? "met" : "MISSED");
        }
        std::printf("  approximation: >= %.0f G Gaussians/s\n", kTargetGaussiansPerS / 1e9);
        for (size_t k = 0; k < results.size(); ++k)
            std::printf("    %-14s %7.3f G Gaussians/s (%5.1f %% of the target), %8.1f ms vs GTX 1080 %5.1f ms   %s\n", chosen[k]->name,
                        gaussiansPerS(results[k]) / 1e9, 100 * gaussiansPerS(results[k]) / kTargetGaussiansPerS,
                        results[k].approximationMs, chosen[k]->gpuApproxMs, approximationMet(results[k]) ? "met" : "MISSED");
        if (set.width == 1920 && set.height == 1080)
            std::printf("  ray casting: 1920x1080 within %.0f ms\n", kTargetRaycastMs);
        else
            std::printf("  ray casting: >= %.2f M rays/s (1920x1080 within %.0f ms; this run is %dx%d)\n", kTargetRaysPerS / 1e6,
                        kTargetRaycastMs, set.width, set.height);
        for (size_t k = 0; k < results.size(); ++k)
            std::printf("    %-14s %8.1f ms, %6.2f M rays/s (%5.1f %% of the target rate), vs GTX 1080 %4.1f ms   %s\n", chosen[k]->name,
                        results[k].raycastMs, raysPerS(results[k]) / 1e6, 100 * raysPerS(results[k]) / kTargetRaysPerS,
                        chosen[k]->gpuRaycastMs, raycastMet(results[k]) ? "met" : "MISSED");

        for (size_t k = 0; k < results.size(); ++k)
            if (results[k].image[0]) std::printf("\nimage: %s", results[k].image);
        std::printf("%swall time %.1f s; load average (1 min) at the end: %s\n", set.imagesDir.empty() ? "\n" : "\n\n", wallS,
                    loadAverage().c_str());
        if (!csv.empty()) {
            writeCsv(chosen, results, set, csv);
            std::printf("rows written to %s\n", csv.c_str());
        }
        if (!json.empty()) {
            writeJson(chosen, results, set, json);
            std::printf("objects written to %s\n", json.c_str());
        }
        if (!plot.empty()) {
            const bool gl = set.backend == hc::cli::Backend::Gl;
            hc::bench::BarPlot bp;
            bp.title = std::string("hc-bench, ") + (gl ? "GL" : "CPU") + " backend: best stage times of a " + std::to_string(set.width) + "x" +
                       std::to_string(set.height) + " frame, " + std::to_string(set.options.cascades) + " cascades of " +
                       std::to_string(set.options.texelsPerSide) + "^2" + (set.scale != 1 ? ", scale " + fmt("%g", set.scale) : "");
            bp.xLabel = "milliseconds";
            // Ray casting first, so its bar ends where the ray casting target's line can meet it.
            bp.segmentNames = {"ray casting", "approximation", "mipmaps", "shading", "fitting"};
            for (size_t k = 0; k < results.size(); ++k) {
                const RunResult& r = results[k];
                if (r.totalMs >= 1e300) continue;  // the scenario failed
                bp.rows.push_back({chosen[k]->name, {r.raycastMs, r.approximationMs, r.mipmapMs, r.shadingMs, r.fittingMs}});
            }
            if (gl) bp.markers.push_back({"whole-frame target " + fmt("%g", kTargetGlFrameMs) + " ms", kTargetGlFrameMs});
            else if (set.width == 1920 && set.height == 1080) bp.markers.push_back({"ray casting target " + fmt("%g", kTargetRaycastMs) + " ms (first segment)", kTargetRaycastMs});
            if (!bp.rows.empty()) {
                hc::bench::writeSvg(plot, bp.svg());
                std::printf("plot written to %s\n", plot.c_str());
            }
        }
        return 0;
    });
}
