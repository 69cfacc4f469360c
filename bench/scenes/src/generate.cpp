// bench/scenes/src/generate.cpp: the scenes' quadtree (heightcast/scenes/scenes.h says how): the top-down refinement,
// the calibration of its threshold, and the grid built in memory or streamed into a grid file.
#include <algorithm>
#include <array>
#include <atomic>
#include <cassert>
#include <cmath>
#include <limits>
#include <optional>

#include "heightcast/core/error.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/timer.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/grid/morton.h"
#include "heightcast/scenes/scenes.h"

namespace hc::scenes {

namespace {

constexpr int kTileLevelsAboveCoarsest = 3;  // generation tiles: 8 x 8 coarsest cells (768 m)
// The finest size halves until the domain holds this many times the target at it: the calibration needs its lowest
// threshold (1 mm, nearly every cell at the finest size) to give more cells than the target.
constexpr double kFinestHeadroom = 1.5;
constexpr float kInf = std::numeric_limits<float>::infinity();

// The thresholds T the calibration chooses from [m]: 1 mm to 10 km, 0.2 % apart. Float, as the refinement compares.
const std::vector<float>& thresholdEdges() {
    static const std::vector<float> edges = [] {
        std::vector<float> e;
        for (double t = 1e-3; t < 1e4; t *= 1.002) e.push_back(float(t));
        e.push_back(1e4f);
        return e;
    }();
    return edges;
}
// Edges per factor 8 in T: how far each of the sample's walks goes down.
const size_t kEdgesPerOctave = size_t(std::lround(std::log(8.0) / std::log(1.002)));

constexpr size_t kMaxWindow = 1024;  // edges a walk over every tile counts per tile

// Leaf counts at many thresholds from one walk. A node splits at T iff its split value v > T (v = +inf where it must
// split, -inf where it cannot), so it is a leaf at T iff v <= T < m, m the least split value of its ancestors: each
// visited node adds 1 to the edges in [v, m). A walk at threshold T0 visits every node that is a leaf at some T >= T0,
// so the sums are exact at every edge from T0 up.
struct Curves {
    int64_t* whole = nullptr;   // difference array over every edge (edges + 1 entries)
    int64_t* window = nullptr;  // difference array over edges [first, first + width) (width + 1 entries), or null
    size_t first = 0, width = 0;

    void add(float v, float m) const {
        const auto& e = thresholdEdges();
        const size_t k0 = size_t(std::lower_bound(e.begin(), e.end(), v) - e.begin());
        const size_t k1 = size_t(std::lower_bound(e.begin(), e.end(), m) - e.begin());
        if (k0 >= k1) return;
        ++whole[k0], --whole[k1];
        if (window) {
            const size_t a = std::clamp(k0, first, first + width) - first,
                         b = std::clamp(k1, first, first + width) - first;
            if (a < b) ++window[a], --window[b];
        }
    }
};

// Where a tile's cells go: straight into arrays from index `at` on (each tile's range is known from an exact count
// first, so tiles fill them in parallel and nothing is held twice).
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

    // Visits the tree under node (ix, iy, level) with threshold T; writes the leaves when `out` is given, adds every
    // visited node to `curves` when given, and returns the leaf count. Stops early (returning what it has) once the
    // count passes `cap`.
    uint64_t run(uint32_t ix, uint32_t iy, int level, float T, CellSink* out, const Curves* curves,
                 uint64_t cap) const {
        std::array<Terrain::Sample, 9> s;
        const double size = f_ * double(uint64_t{1} << level);
        for (int b = 0; b < 3; ++b)
            for (int a = 0; a < 3; ++a) s[size_t(b * 3 + a)] = t_.at(ix * f_ + a * size / 2, iy * f_ + b * size / 2);
        uint64_t count = 0;
        visit(ix, iy, level, s, T, kInf, out, curves, count, cap);
        return count;
    }

private:
    // A node's split value (see Curves): s its samples at its corners, edge midpoints and centre.
    float splitValue(int level, double size, const std::array<Terrain::Sample, 9>& s) const {
        if (level > maxLevel_) return kInf;
        if (level == 0) return -kInf;
        int wet = 0;
        float zLo = s[0].z, zHi = s[0].z, dLo = s[0].depth, dHi = s[0].depth;
        for (const Terrain::Sample& p : s) {
            wet += p.depth > 0;
            zLo = std::min(zLo, p.z), zHi = std::max(zHi, p.z);
            dLo = std::min(dLo, p.depth), dHi = std::max(dHi, p.depth);
        }
        if ((wet > 0 && wet < 9) || std::abs(s[4].bank) < 0.7072f * float(size)) return kInf;
        return std::max(zHi - zLo, dHi - dLo);
    }

    // s: the node's samples, row-major from the south-west; m: the least split value of its ancestors.
    void visit(uint32_t ix, uint32_t iy, int level, const std::array<Terrain::Sample, 9>& s, float T, float m,
               CellSink* out, const Curves* curves, uint64_t& count, uint64_t cap) const {
        if (count > cap) return;
        const uint32_t span = uint32_t{1} << level;
        if (ix >= ex_ || iy >= ey_) return;  // outside the extent: a hole (the extent is whole coarsest cells)
        const double size = f_ * double(span);
        const float v = splitValue(level, size, s);
        if (curves) curves->add(v, m);
        if (!(v > T)) {
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
            visit(ix + uint32_t(cx) * half, iy + uint32_t(cy) * half, level - 1, cs, T, std::min(m, v), out, curves,
                  count, cap);
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

// The quadtree's shape and threshold, calibrated: what both builders need.
struct Plan {
    Calibration calibration;
    double finest = 0;
    int maxLevel = 0, tileLevel = 0, rootLevel = 0;
    uint32_t ex = 0, ey = 0;                     // extent in finest cells
    std::vector<std::array<uint32_t, 2>> tiles;  // in Morton order
    std::vector<uint64_t> perTile;               // cells of each tile at the threshold
};

// One calibration at a fixed finest size: the tiles, their sample, and walks over them.
class Calibrator {
public:
    Calibrator(const Terrain& terrain, Plan& p, double target, unsigned threads)
        : p_(p),
          target_(target),
          threads_(hc::resolveThreads(threads)),
          refiner_(terrain, p.finest, p.maxLevel, p.ex, p.ey) {
        for (size_t k = 0; k < p.tiles.size(); ++k)
            if (p.tiles.size() < 256 || hash64(uint64_t(p.tiles[k][0]) << 32 | p.tiles[k][1]) % 8 == 0)
                sample_.push_back(k);
        all_.resize(p.tiles.size());
        for (size_t k = 0; k < all_.size(); ++k) all_[k] = k;
        sampleScale_ = double(p.tiles.size()) / double(sample_.size());
        p.calibration.sampleTiles = sample_.size();
        p.calibration.tiles = p.tiles.size();
    }

    // The sample's estimate of the cells at the coarsest threshold (10 km).
    double fewest() {
        return double(walk(sample_, thresholdEdges().size() - 1, cap(sampleScale_), 0, 0).leaves) * sampleScale_;
    }

    // The threshold edge whose cell count over every tile is nearest the target; p.perTile filled there.
    void calibrate(bool coarsestOnly) {
        const size_t top = thresholdEdges().size() - 1;
        size_t lo = top, hi = top;
        if (!coarsestOnly) std::tie(lo, hi) = sampleWindow();
        for (int round = 0; round < 8; ++round) {
            const Walk w = walk(all_, lo, cap(1.0), lo, hi - lo + 1);
            if (w.capped) {  // the sample's estimate was far too low there: a coarser start
                lo = std::min(hi, lo + kEdgesPerOctave / 2);
                continue;
            }
            if (double(w.counts[lo]) < target_ && lo > 0) {  // the target lies below the window
                hi = lo, lo = lo > kEdgesPerOctave / 2 ? lo - kEdgesPerOctave / 2 : 0;
                continue;
            }
            size_t best = lo;  // exact from lo up
            for (size_t k = lo; k <= top; ++k)
                if (std::abs(double(w.counts[k]) - target_) < std::abs(double(w.counts[best]) - target_)) best = k;
            if (best > hi) {  // beyond the window: count the tiles there
                lo = hi = best;
                continue;
            }
            for (size_t t = 0; t < p_.tiles.size(); ++t) {
                int64_t n = 0;
                for (size_t k = 0; k <= best - lo; ++k) n += w.tileDiffs[t * (hi - lo + 2) + k];
                p_.perTile[t] = uint64_t(n);
            }
            p_.calibration.thresholdM = thresholdEdges()[best];
            return;
        }
        throw hc::Error("scene generation: the threshold calibration did not converge");
    }

private:
    struct Walk {
        bool capped = false;
        uint64_t leaves = 0;
        std::vector<int64_t> counts;     // cells at every edge from the walk's up (exact there)
        std::vector<int64_t> tileDiffs;  // per tile, the window's difference array (width + 1 each)
    };

    // A walk stops past 4x the target (the sample's estimate far too low: a runaway walk), but never below about a
    // million leaves (a second's walk): at small targets the count can jump 4x within half an octave of T, and a cap
    // that small made the calibration step back and forth between capped and too few until it gave up.
    uint64_t cap(double factor) const { return uint64_t((4 * target_ + double(1 << 20)) / factor); }

    // Walks tiles `which` at edge k0 (stops past `cap` leaves: capped); tile windows of `width` edges from `first`.
    Walk walk(const std::vector<size_t>& which, size_t k0, uint64_t cap, size_t first, size_t width) {
        const auto& e = thresholdEdges();
        Walk w;
        std::vector<std::vector<int64_t>> diffs(threads_, std::vector<int64_t>(e.size() + 1, 0));
        if (width) w.tileDiffs.assign(p_.tiles.size() * (width + 1), 0);
        std::atomic<uint64_t> total{0};
        std::atomic<bool> capped{false};
        hc::parallelFor(which.size(), 1, threads_, [&](size_t b, size_t end, unsigned worker) {
            for (size_t k = b; k < end && !capped.load(std::memory_order_relaxed); ++k) {
                const size_t t = which[k];
                Curves curves{diffs[worker].data(), width ? &w.tileDiffs[t * (width + 1)] : nullptr, first, width};
                const auto& tl = p_.tiles[t];
                const uint64_t n = refiner_.run(tl[0] << p_.tileLevel, tl[1] << p_.tileLevel, p_.tileLevel, e[k0],
                                                nullptr, &curves, cap);
                if (total.fetch_add(n) + n > cap) capped = true;
            }
        });
        w.capped = capped.load(), w.leaves = total.load();
        w.counts.assign(e.size(), 0);
        int64_t run = 0;
        for (size_t k = 0; k < e.size(); ++k) {
            for (const auto& d : diffs) run += d[k];
            w.counts[k] = run;
        }
        return w;
    }

    // The sample walked down in T, 8x at a time, until its estimate passes 1.3 x the target: the edges whose estimate
    // lies within [0.77, 1.3] x the target, where the count over every tile is looked for (the sample's bias: a few %).
    std::pair<size_t, size_t> sampleWindow() {
        const size_t top = thresholdEdges().size() - 1;
        size_t at = top, step = kEdgesPerOctave;
        std::vector<int64_t> counts;
        while (at > 0 && step > 0) {
            const size_t next = at > step ? at - step : 0;
            Walk w = walk(sample_, next, cap(sampleScale_), 0, 0);
            if (w.capped) {  // past 4x the target: a shorter step
                step /= 2;
                continue;
            }
            at = next, counts = std::move(w.counts);
            if (double(counts[at]) * sampleScale_ >= 1.3 * target_) break;
        }
        if (counts.empty()) return {top, top};
        size_t lo = at;
        while (lo < top && double(counts[lo + 1]) * sampleScale_ >= 1.3 * target_) ++lo;
        size_t hi = lo;  // at most kMaxWindow edges: each tile holds a count per edge of the window
        while (hi < top && hi - lo + 1 < kMaxWindow && double(counts[hi]) * sampleScale_ > 0.77 * target_) ++hi;
        return {lo, hi};
    }

    Plan& p_;
    double target_;
    unsigned threads_;
    Refiner refiner_;
    std::vector<size_t> sample_, all_;
    double sampleScale_ = 1;
};

// The scenario's quadtree for about `target` cells: the finest size, the tiles and the calibrated threshold.
Plan planFor(const Scenario& sc, double target, unsigned threads) {
    Plan p;
    const double extentX = extentXM(sc), extentY = extentYM(sc);  // whole coarsest cells
    const Terrain terrain(sc);
    p.finest = sc.finestM;
    // More cells than the domain holds at the finest size (with headroom, see kFinestHeadroom): halve it.
    while (extentX / p.finest * (extentY / p.finest) < kFinestHeadroom * target) {
        p.finest /= 2;
        p.calibration.finestLowered = true;
    }
    for (;;) {
        const Stopwatch clock;
        p.maxLevel = int(std::lround(std::log2(kCoarsestM / p.finest)));
        p.tileLevel = p.maxLevel + kTileLevelsAboveCoarsest;
        p.ex = uint32_t(std::lround(extentX / p.finest)), p.ey = uint32_t(std::lround(extentY / p.finest));
        p.rootLevel = p.tileLevel;
        while ((uint64_t{1} << p.rootLevel) < std::max(p.ex, p.ey)) ++p.rootLevel;
        const uint32_t side = 1u << p.tileLevel;
        const uint32_t ntx = (p.ex + side - 1) >> p.tileLevel, nty = (p.ey + side - 1) >> p.tileLevel;
        p.tiles.clear();
        for (uint32_t ty = 0; ty < nty; ++ty)
            for (uint32_t tx = 0; tx < ntx; ++tx) p.tiles.push_back({tx, ty});
        std::sort(p.tiles.begin(), p.tiles.end(), [](const auto& a, const auto& b) {
            return hc::mortonEncode(a[0], a[1]) < hc::mortonEncode(b[0], b[1]);
        });
        p.perTile.assign(p.tiles.size(), 0);
        Calibrator cal(terrain, p, target, threads);
        const double fewest = cal.fewest();
        if (fewest > target && p.finest * 2 < kCoarsestM && !p.calibration.finestLowered) {
            p.finest *= 2;  // the forced cells alone are too many: coarser finest cells
            p.calibration.finestRaised = true;
            continue;
        }
        cal.calibrate(fewest >= target);  // fewest >= target: as coarse as it gets (the table shows the miss)
        p.calibration.calibrationS = clock.seconds();
        return p;
    }
}

Grid shapeOf(const Scenario& sc, const Plan& p) {
    Grid g;
    g.originWorldX = sc.originX;
    g.originWorldY = sc.originY;
    g.finestCellM = p.finest;
    g.rootLevel = p.rootLevel;
    g.minLevel = 0;
    g.maxLevel = p.maxLevel;
    g.layers.push_back({"water_depth", "m"});
    g.values.resize(g.layers.size());
    return g;
}

// Tiles [t0, t1) of the plan written into arrays from their first cell on (firstCell: per tile, cumulative), in
// parallel; `base` is the first cell of tile t0 in the arrays' frame.
void fillTiles(const Scenario& sc, const Plan& p, const std::vector<size_t>& firstCell, size_t t0, size_t t1,
               size_t base, uint64_t* codes, float* z, float* depth, unsigned threads) {
    const Terrain terrain(sc);
    const Refiner refiner(terrain, p.finest, p.maxLevel, p.ex, p.ey);
    const float T = float(p.calibration.thresholdM);
    hc::parallelFor(t1 - t0, 1, threads, [&](size_t b, size_t e, unsigned) {
        for (size_t k = t0 + b; k < t0 + e; ++k) {
            CellSink sink{codes, z, depth, firstCell[k] - base};
            refiner.run(p.tiles[k][0] << p.tileLevel, p.tiles[k][1] << p.tileLevel, p.tileLevel, T, &sink, nullptr,
                        UINT64_MAX);
            assert(sink.at == firstCell[k + 1] - base);  // the same T visits the same tree
        }
    });
}

std::vector<size_t> firstCells(const Plan& p) {
    std::vector<size_t> first(p.tiles.size() + 1, 0);
    for (size_t k = 0; k < p.tiles.size(); ++k) first[k + 1] = first[k] + p.perTile[k];
    return first;
}

}  // namespace

double targetCells(const Scenario& sc, double scale) { return sc.reportCellsM * 1e6 / scale; }

Generated generate(const Scenario& sc, double scale, unsigned threads) {
    return generateCells(sc, targetCells(sc, scale), threads);
}

Generated generateCells(const Scenario& sc, double target, unsigned threads) {
    const Plan p = planFor(sc, target, threads);
    const Stopwatch clock;
    Generated gen;
    static_cast<Calibration&>(gen) = p.calibration;
    // The grid: sized once, each tile written at its own offset, in parallel (16 bytes a cell in all).
    Grid& g = gen.grid;
    g = shapeOf(sc, p);
    const std::vector<size_t> first = firstCells(p);
    g.codes.resize(first.back());
    for (auto& v : g.values) v.resize(first.back());
    fillTiles(sc, p, first, 0, p.tiles.size(), 0, g.codes.data(), g.values[0].data(), g.values[1].data(), threads);
    gen.buildS = clock.seconds();
    return gen;
}

GeneratedFile generateToFile(const Scenario& sc, double target, unsigned threads, const std::string& path,
                             size_t batchCells) {
    const Plan p = planFor(sc, target, threads);
    const Stopwatch clock;
    GeneratedFile gen;
    static_cast<Calibration&>(gen) = p.calibration;
    gen.shape = shapeOf(sc, p);
    const std::vector<size_t> first = firstCells(p);
    gen.cells = first.back();
    GridFileWriter out(path, gen.shape, gen.cells, 1);
    WaterStepData water;
    water.values.resize(1);
    std::vector<uint64_t> codes;
    std::vector<float> z, depth;
    // Batches of whole tiles, each built in parallel and appended in order: memory follows the batch.
    for (size_t t0 = 0; t0 < p.tiles.size();) {
        size_t t1 = t0 + 1;
        while (t1 < p.tiles.size() && first[t1 + 1] - first[t0] <= batchCells) ++t1;
        const size_t n = first[t1] - first[t0];
        codes.resize(n), z.resize(n), depth.resize(n);
        fillTiles(sc, p, first, t0, t1, first[t0], codes.data(), z.data(), depth.data(), threads);
        out.append(codes, {std::span<const float>(z)});
        for (size_t i = 0; i < n; ++i) {
            const int level = hc::codeLevel(codes[i]);
            if (size_t(level) >= gen.cellsPerLevel.size()) gen.cellsPerLevel.resize(size_t(level) + 1);
            ++gen.cellsPerLevel[size_t(level)];
            gen.topM = std::max(gen.topM, double(z[i]) + std::max(0.0, double(depth[i])));
            if (depth[i] > 0) water.wet.push_back(uint32_t(first[t0] + i)), water.values[0].push_back(depth[i]);
        }
        t0 = t1;
    }
    gen.wetCells = water.wet.size();
    out.appendStep(water);
    out.commit(IngestStats{});
    gen.buildS = clock.seconds();
    return gen;
}

}  // namespace hc::scenes
