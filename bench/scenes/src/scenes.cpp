// bench/scenes/src/scenes.cpp: the four synthetic flood scenes: landscape functions, the calibrated
// top-down quadtree and the fixed camera (heightcast/scenes/scenes.h says what each is).
#include "heightcast/scenes/scenes.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cassert>
#include <cmath>
#include <numbers>
#include <random>

#include "heightcast/core/parallel.h"
#include "heightcast/core/timer.h"
#include "heightcast/grid/morton.h"

namespace hc::scenes {

namespace {

constexpr int kTileLevelsAboveCoarsest = 3;  // generation tiles: 8 x 8 coarsest cells (768 m)
// The finest size halves until the domain holds this many times the target at it: the calibration's bisection
// needs its lower end (T = 1 mm, nearly every cell at the finest size) to give more cells than the target.
constexpr double kFinestHeadroom = 1.5;

const Scenario kScenarios[] = {
    {"Marchfeld",
     82.9,
     57.1,
     3.0,
     7.46,
     15.1,
     5.1,
     580000,
     5330000,
     {160, 0.0004, 0.42, {2600, 700}, {32000, 7000}, 2600, 1800, 150, 6, 2.4, 1.2, 45, 8, 11}},
    {"Petzenkirchen",
     15.4,
     16.0,
     0.75,
     1.81,
     20.8,
     4.3,
     510000,
     5330000,
     {300, 0.002, 0.5, {700, 160}, {9000, 1800}, 110, 700, 4, 1.5, 0.8, 0.4, 90, 12, 22}},
    {"Wachau",
     24.1,
     16.5,
     3.0,
     1.95,
     5.3,
     4.3,
     530000,
     5360000,
     {205, 0.0003, 0.5, {1600, 400}, {19000, 5200}, 450, 2600, 140, 5, 3.0, 1.0, 430, 35, 33}},
    {"Florence",
     44.6,
     28.2,
     3.0,
     4.53,
     1.5,
     2.8,
     660000,
     4840000,
     {55, 0.0005, 0.45, {1300, 320}, {21000, 4300}, 1900, 3200, 60, 4, 2.5, 0.9, 330, 28, 44}},
};

}  // namespace

std::span<const Scenario> scenarios() { return kScenarios; }

const Scenario* findScenario(std::string_view name) {
    for (const Scenario& sc : kScenarios)
        if (name == sc.name) return &sc;
    return nullptr;
}

double extentXM(const Scenario& sc) { return std::round(sc.extentXKm * 1000 / kCoarsestM) * kCoarsestM; }
double extentYM(const Scenario& sc) { return std::round(sc.extentYKm * 1000 / kCoarsestM) * kCoarsestM; }

// ---------------- the landscape ----------------

Terrain::Terrain(const Scenario& sc) : l_(sc.land), extentY_(extentYM(sc)) {
    std::mt19937_64 rng(l_.seed);
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

void Terrain::centreline(double x, double& y, double& dydx) const {
    y = l_.riverYFraction * extentY_;
    dydx = 0;
    for (int k = 0; k < 2; ++k) {
        const double w = 2 * std::numbers::pi / l_.meanderLen[k], a = w * x + meanderPhase_[k];
        y += l_.meanderAmp[k] * std::sin(a);
        dydx += l_.meanderAmp[k] * w * std::cos(a);
    }
}

Terrain::Sample Terrain::at(double x, double y) const {
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

double Terrain::sum(const std::vector<Wave>& waves, double x, double y) {
    double s = 0;
    for (const Wave& w : waves) s += w.amp * std::sin(w.kx * x + w.ky * y + w.phase);
    return s;
}

// ---------------- the quadtree ----------------

namespace {

// Where a tile's cells go: straight into the grid's arrays from index `at` on (each tile's range is known
// from an exact count first, so tiles fill the grid in parallel and nothing is held twice).
struct CellSink {
    uint64_t* codes;
    float* z;
    float* depth;
    size_t at;
};

// Top-down refinement of one scenario's domain (see scenes.h).
class Refiner {
public:
    Refiner(const Terrain& t, double finestM, int maxLevel, uint32_t extentX, uint32_t extentY)
        : t_(t), f_(finestM), maxLevel_(maxLevel), ex_(extentX), ey_(extentY) {}

    // Visits the tree under node (ix, iy, level) with threshold T; writes the leaves when `out` is given,
    // and returns the leaf count. Stops early (returning what it has) once the count passes `cap`.
    uint64_t run(uint32_t ix, uint32_t iy, int level, double T, CellSink* out, uint64_t cap) const {
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
    void visit(uint32_t ix, uint32_t iy, int level, const std::array<Terrain::Sample, 9>& s, float T, CellSink* out,
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
            split =
                (wet > 0 && wet < 9) || zHi - zLo > T || dHi - dLo > T || std::abs(s[4].bank) < 0.7072f * float(size);
        }
        if (!split) {
            ++count;
            if (out) {
                out->codes[out->at] = hc::makeCellCode(hc::mortonEncode(ix, iy), level);
                out->z[out->at] = s[4].z;
                out->depth[out->at] = s[4].depth;
                ++out->at;
            }
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

uint64_t hash64(uint64_t x) {  // splitmix64's finaliser: a fixed, well-spread tile sample
    x += 0x9e3779b97f4a7c15ull;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    return x ^ (x >> 31);
}

}  // namespace

double targetCells(const Scenario& sc, double scale) { return sc.reportCellsM * 1e6 / scale; }

Generated generate(const Scenario& sc, double scale, unsigned threads) {
    return generateCells(sc, targetCells(sc, scale), threads);
}

Generated generateCells(const Scenario& sc, double target, unsigned threads) {
    Generated gen;
    const double extentX = extentXM(sc), extentY = extentYM(sc);  // whole coarsest cells
    const Terrain terrain(sc);
    double finest = sc.finestM;
    // More cells than the domain holds at the finest size (with headroom, see kFinestHeadroom): halve it.
    while (extentX / finest * (extentY / finest) < kFinestHeadroom * target) {
        finest /= 2;
        gen.finestLowered = true;
    }
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
        std::sort(tiles.begin(), tiles.end(), [](const auto& a, const auto& b) {
            return hc::mortonEncode(a[0], a[1]) < hc::mortonEncode(b[0], b[1]);
        });
        std::vector<size_t> sample;
        for (size_t k = 0; k < tiles.size(); ++k)
            if (tiles.size() < 256 || hash64(uint64_t(tiles[k][0]) << 32 | tiles[k][1]) % 8 == 0) sample.push_back(k);
        const double sampleScale = double(tiles.size()) / double(sample.size());
        const Refiner refiner(terrain, finest, maxLevel, ex, ey);

        // A count over every tile keeps its cells per tile: at the final T they place each tile in the grid.
        std::vector<uint64_t> perTile(tiles.size());
        double perTileT = -1;  // the T perTile was counted at (complete, under no cap), or -1
        // Cells for threshold T over a list of tiles, scaled by `factor` (capped: past the cap is only "too many").
        auto count = [&](double T, const std::vector<size_t>& which, double factor, uint64_t cap) {
            const bool every = which.size() == tiles.size();
            std::atomic<uint64_t> total{0};
            std::atomic<bool> capped{false};
            hc::parallelFor(which.size(), 1, threads, [&](size_t b, size_t e, unsigned) {
                for (size_t k = b; k < e; ++k) {
                    if (total.load(std::memory_order_relaxed) > cap) {
                        capped = true;
                        return;
                    }
                    const auto& tl = tiles[which[k]];
                    const uint64_t n = refiner.run(tl[0] << tileLevel, tl[1] << tileLevel, tileLevel, T, nullptr, cap);
                    if (every) perTile[which[k]] = n;
                    total += n;
                }
            });
            if (every) perTileT = capped || total.load() > cap ? -1 : T;
            return double(total.load()) * factor;
        };
        auto capFor = [&](double factor) { return uint64_t(4 * target / factor) + 1000; };
        std::vector<size_t> all(tiles.size());
        for (size_t k = 0; k < all.size(); ++k) all[k] = k;
        Stopwatch clock;
        const double fewest = count(1e4, sample, sampleScale, capFor(sampleScale));
        if (fewest > target && finest * 2 < kCoarsestM && !gen.finestLowered) {
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
                const double n = count(mid, sample, sampleScale, capFor(sampleScale)) * bias;
                (n > target ? lo : hi) = mid;
                gen.thresholdM = mid;
                if (std::abs(n / target - 1) < 0.01 || hi / lo < 1.001) break;
            }
            if (sample.size() == all.size()) break;  // the sample is every tile: exact already
            const double full = count(gen.thresholdM, all, 1.0, capFor(1.0));
            if (std::abs(full / target - 1) < 0.03) break;
            bias *= full / target;
        }
        // The exact count per tile at the final T, unless the calibration's last full count was that one.
        if (perTileT != gen.thresholdM) count(gen.thresholdM, all, 1.0, UINT64_MAX);
        gen.calibrationS = clock.lap();
        gen.sampleTiles = sample.size();
        gen.tiles = tiles.size();

        // The grid: sized once, each tile written at its own offset, in parallel (16 bytes a cell in all).
        Grid& g = gen.grid;
        g.originWorldX = sc.originX;
        g.originWorldY = sc.originY;
        g.finestCellM = finest;
        g.rootLevel = rootLevel;
        g.minLevel = 0;
        g.maxLevel = maxLevel;
        g.layers.push_back({"water_depth", "m"});
        g.values.emplace_back();
        std::vector<size_t> firstCell(tiles.size() + 1, 0);
        for (size_t k = 0; k < tiles.size(); ++k) firstCell[k + 1] = firstCell[k] + perTile[k];
        g.codes.resize(firstCell.back());
        for (auto& v : g.values) v.resize(firstCell.back());
        hc::parallelFor(tiles.size(), 1, threads, [&](size_t b, size_t e, unsigned) {
            for (size_t k = b; k < e; ++k) {
                CellSink sink{g.codes.data(), g.values[0].data(), g.values[1].data(), firstCell[k]};
                refiner.run(tiles[k][0] << tileLevel, tiles[k][1] << tileLevel, tileLevel, gen.thresholdM, &sink,
                            UINT64_MAX);
                assert(sink.at == firstCell[k + 1]);  // the same T visits the same tree
            }
        });
        gen.buildS = clock.seconds();
        return gen;
    }
}

// ---------------- the lists' size ----------------

ListsEstimate estimateInfluenceLists(const Grid& g, const influence::KernelParams& params, size_t sampleCells) {
    ListsEstimate est;
    const size_t n = g.cellCount();
    if (n == 0) return est;
    const size_t stride = std::max<size_t>(1, n / std::max<size_t>(1, sampleCells));
    uint64_t entries = 0, sampled = 0;
    std::vector<uint32_t> met;
    for (size_t i = stride / 2; i < n; i += stride, ++sampled) {
        double x, y;
        g.cellCenterLocal(i, x, y);
        met.clear();
        // The kernel is zero on its disk's rim, and R sigma = 3.5 cell sizes puts rims exactly on the edges of
        // cells of the same size: a disk only touching a square must not count, so the radius is a hair shorter.
        g.cellsInDisk(x, y, params.radiusM(g.cellSizeM(i)) * (1 - 1e-9), met);
        entries += met.size();
    }
    est.meanLength = double(entries) / double(sampled);
    est.bytes = uint64_t(8.0 * double(n + 1) + 4.0 * est.meanLength * double(n));
    return est;
}

// ---------------- the camera ----------------

render::Camera floodCamera(const Scenario& sc, const Grid& g, int width, int height) {
    const Terrain terrain(sc);
    const double aboveM = 1500, pitch = -20;
    double ey, ey2, dydx;
    const double ex = 0.1 * extentXM(sc);
    terrain.centreline(ex, ey, dydx);
    const double ex2 = ex + aboveM / std::tan(-pitch * std::numbers::pi / 180);  // where the centre ray meets the floor
    terrain.centreline(ex2, ey2, dydx);
    render::Camera c;
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

}  // namespace hc::scenes
