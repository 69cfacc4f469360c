// The approximation pass: the Gaussian RBF sum (DESIGN.md section 4) at every visible texel of a
// cascade, in float with a vectorised exponential.
//
// Texels are taken cell by cell: all texel centres inside cell k share k's influence list, and
// every quantity is relative to k's centre and value, so float keeps its precision however far the
// cascade lies from the grid origin (the exact evaluator does the same in double).
#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <optional>
#include <span>
#include <unordered_map>

#include "heightcast/core/error.h"
#include "heightcast/core/parallel.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/grid/morton.h"
#include "heightcast/influence/region.h"
#include "heightcast/influence/surface.h"
#include "textures.h"

namespace hc::render::detail {
namespace {

constexpr int kLanes = 8;  // candidates per vector step (AVX2: 8 floats)
static_assert(influence::kWetShareMin == 0.5, "render/gl/shaders/approximate.comp writes the wet share rule as denW >= 0.5 * den");

// exp(x) for x <= 0 in float: 2^(x log2 e) split into an integer power (exponent bits) and 2^f,
// f in [-0.5, 0.5], by its Taylor polynomial to degree 6 (relative error < 2e-7, float's epsilon).
// Branch-free, so loops over it vectorise.
inline float expNeg(float x) {
    x = std::max(x, -87.0f);
    const float y = x * 1.44269504088896341f;
    const float n = std::floor(y + 0.5f);
    const float f = y - n;
    const float p = 1.0f + f * (0.693147181f + f * (0.240226507f + f * (0.0555041087f + f * (0.00961812911f + f * (0.00133335581f + f * 0.000154035304f)))));
    const int32_t bits = (static_cast<int32_t>(n) + 127) << 23;
    return p * std::bit_cast<float>(bits);
}

struct Candidates {
    std::vector<float> ex, ey, a, r2, dz;  // relative to the cell's centre / value; padded to kLanes
    std::vector<float> dl, wet;            // water: level z + d relative to the level base (0 if dry), 1 if wet
    size_t count = 0;                          // real entries (before padding)
};

// The texels to evaluate, per row at most two spans: the row's visible span less the part copied from the
// last frame (visible there too: one span, as both rows' spans are intervals).
struct Todo {
    int a0 = 0, a1 = -1, b0 = 0, b1 = -1;  // inclusive; empty when the end is below the start
};

// The texels [f, l] of row j of c that were visible in `reuse` too (empty: l < f), and the row's spans left to evaluate.
Todo keptSpan(const Cascade& c, const TexelReuse* reuse, int j, int& f, int& l) {
    const Cascade::RowSpan& r = c.rows[size_t(j)];
    Todo t{r.first, r.last, 0, -1};
    f = 0, l = -1;
    const int jp = reuse ? j + reuse->dj : -1;
    if (reuse && r.first <= r.last && jp >= 0 && jp < reuse->cascade->n) {
        const Cascade::RowSpan& p = reuse->cascade->rows[size_t(jp)];
        f = std::max(r.first, p.first - reuse->di), l = std::min(r.last, p.last - reuse->di);
    }
    if (f <= l) t = {r.first, f - 1, l + 1, r.last};
    return t;
}

// Writes every texel of tex: the visible texels of c that were visible in `reuse` (if any) copied, their count
// added to `copied`; every other one "no surface" (-inf, depth 0) until evaluated. Returns the spans left to
// evaluate. reuse->tex may be tex itself where the side is the same (renderFrame hands the last frame's storage on, so a
// moving camera allocates nothing): this frame's row j reads the last frame's row j + dj, so rows are written in the
// order that reads each of the last frame's rows before overwriting it. A cascade of another side reads storage of
// its own (rows of reuse->cascade->n texels).
// With `rows` (RowFill): each row's spans into it, and only the spans left to evaluate written ("no surface"): the
// texels kept from `reuse` are counted, not copied (the caller keeps them elsewhere), and the others left as they are.
std::vector<Todo> copyReusedTexels(const Cascade& c, const TexelReuse* reuse, CascadeTextures& tex, uint64_t& copied, unsigned threads,
                                   std::vector<RowFill>* rows) {
    const int n = c.n;
    const float noSurface = -std::numeric_limits<float>::infinity();
    std::vector<Todo> todo(static_cast<size_t>(n));
    auto clearSpan = [&](size_t row, int lo, int hi) {  // [lo, hi] of a row "no surface"
        if (hi < lo) return;
        std::fill(&tex.terrain.h[row + size_t(lo)], &tex.terrain.h[row + size_t(hi)] + 1, noSurface);
        if (tex.hasWater) {
            std::fill(&tex.water.h[row + size_t(lo)], &tex.water.h[row + size_t(hi)] + 1, noSurface);
            std::fill(&tex.depth[row + size_t(lo)], &tex.depth[row + size_t(hi)] + 1, 0.0f);
        }
    };
    if (rows) {  // the spans only, the rows on all workers
        *rows = rowFills(c, reuse, copied);
        parallelFor(size_t(n), 64, threads, [&](size_t b, size_t e, unsigned) {
            for (size_t j = b; j < e; ++j) {
                const RowFill& r = (*rows)[j];
                todo[j] = {r.a0, r.a1, r.b0, r.b1};
                clearSpan(j * size_t(n), r.a0, r.a1), clearSpan(j * size_t(n), r.b0, r.b1);
            }
        });
        return todo;
    }
    if (!reuse) {  // a fresh cascade: every texel "no surface", the rows on all workers (up to 3 x 64 MB to write)
        parallelFor(size_t(n), 64, threads, [&](size_t b, size_t e, unsigned) {
            for (size_t j = b; j < e; ++j) {
                const Cascade::RowSpan& r = c.rows[j];
                todo[j].a0 = r.first, todo[j].a1 = r.last;
                clearSpan(j * size_t(n), 0, n - 1);
            }
        });
        return todo;
    }
    if (reuse->tex == &tex && reuse->cascade->n != n) throw hc::Error("approximate: a cascade kept in place changed its side (a bug)");
    const bool upwards = reuse->dj < 0;
    for (int step = 0; step < n; ++step) {
        const int j = upwards ? n - 1 - step : step;
        int f, l;  // the copied texels of row j
        Todo& t = todo[size_t(j)];
        t = keptSpan(c, reuse, j, f, l);
        if (f <= l) copied += uint64_t(l - f + 1);
        const int jp = j + reuse->dj;
        const size_t row = size_t(j) * size_t(n);
        auto place = [&](Texels& to, const Texels& from, float none) {
            float* const out = &to[row];
            if (l < f) {
                std::fill(out, out + n, none);
                return;
            }
            const size_t at = size_t(jp) * size_t(reuse->cascade->n) + size_t(f + reuse->di);
            std::memmove(out + f, &from[at], size_t(l - f + 1) * sizeof(float));  // may overlap (in place)
            std::fill(out, out + f, none);
            std::fill(out + l + 1, out + n, none);
        };
        place(tex.terrain.h, reuse->tex->terrain.h, noSurface);
        if (tex.hasWater) {
            place(tex.water.h, reuse->tex->water.h, noSurface);
            place(tex.depth, reuse->tex->depth, 0.0f);
        }
    }
    return todo;
}

// Catmull-Rom weights of the four samples around a point at fraction f in [0, 1) of their middle interval: the
// cubic through the samples with slopes from their neighbours. f = 0 gives (0, 1, 0, 0): the sample itself.
inline void catmullRom(double f, double w[4]) {
    const double f2 = f * f, f3 = f2 * f;
    w[0] = 0.5 * (-f3 + 2 * f2 - f);
    w[1] = 0.5 * (3 * f3 - 5 * f2 + 2);
    w[2] = 0.5 * (-3 * f3 + 4 * f2 + f);
    w[3] = 0.5 * (f3 - f2);
}

// Fills texels finer than every pyramid level stored around them (pyramid.h keeps level t only where the kernel of a
// cell as fine as its spacing reaches) by bicubic (Catmull-Rom) interpolation of the nearest coarser level whose samples around the
// texel are all stored, at most `maxUp` levels above the cascade's, and where no cell finer than that level's spacing
// lies within a kernel's reach of the samples: then the surface is smooth at that spacing (a sum of Gaussians at least
// one spacing wide, kernel.h). Such cells lie only in the stored tiles of the level below; their positions come from
// the grid's codes in those tiles' nodes (in memory or from the file), kept per worker in a table of recent tiles.
// Undefined samples (holes), a water level defined at some samples only (a flood's edge) and finer cells near are left
// to the kernels: such texels are not filled, as where no such level is stored.
//
// Separably, row by row: a texel row lies at one height between two rows of samples, so each column of 4 samples is
// blended vertically once per texel row (and kept in a small cache), and a texel blends 4 columns. A texel of level
// t + up's stencil shares its columns with the 2^up texels beside it. One per worker; rows are asked in any order.
class PyramidInterpolator {
public:
    PyramidInterpolator(const Scene& scene, const influence::SurfacePyramid& p, const influence::SurfacePyramid* water, int t, int maxUp)
        : scene_(scene), water_(water), channels3_(p.channels == 3) {
        for (int up = 1; up <= maxUp && t + up <= p.topLevel(); ++up) {
            Level& L = levels_.emplace_back();
            // A cascade finer than the finest cells (t < 0) has no level of its own; its texels interpolate level 0,
            // below which no cell lies (no finer tiles to ask).
            L.stored = t + up >= 0;
            if (!L.stored) continue;
            for (int k = 0; k < 4; ++k) {
                L.samples.emplace_back(p, t + up);
                if (water) L.water.emplace_back(*water, t + up);
                if (t + up > 0) L.finer.emplace_back(p, t + up - 1);
            }
            // A cell of level t + up - 1 or finer weighs up to R sigma of its size (kernel.h) around it: in samples of
            // this level, at most half of that.
            L.reach = int64_t(std::ceil(0.5 * p.params.truncation * p.params.sigma));
            L.finerLevel = t + up - 1;
            L.finerShift = L.finer.empty() ? 0 : std::countr_zero(L.finer[0].side());
            L.side = L.samples[0].side();
            L.shift = std::countr_zero(L.side);
            L.plane = L.samples[0].plane();
            for (uint64_t f = 0; f < (uint64_t{1} << up); ++f) {  // the weights of each fraction a texel can have
                std::array<double, 4> w;
                catmullRom(std::ldexp(double(f), -up), w.data());
                L.weights.push_back(w);
            }
        }
    }

    struct Value {
        float z, level, share;  // level NaN: dry
        int up;                 // levels above the cascade's
    };

    // Interpolates lattice points gi0 .. gi0 + count - 1 of row gj of the cascade's level: out[k] where filled[k].
    // Each point takes the first level, going up, where the samples of its stencil's non-zero weights are all stored;
    // it is refused (left to the kernels) where one of them is undefined, where wet and dry columns meet, where the
    // stencil would leave the domain, or where no level up to maxUp has them. A level's columns are taken once for the
    // run, from the column cache.
    void run(uint64_t gi0, int count, uint64_t gj, Value* out, uint8_t* filled) {
        enum : uint8_t { kPending, kDone, kRefused };
        state_.assign(size_t(count), kPending);
        int pending = count;
        for (int up = 1; up <= int(levels_.size()) && pending > 0; ++up) {
            Level& L = levels_[size_t(up - 1)];
            if (!L.stored) continue;
            const uint64_t mask = (uint64_t{1} << up) - 1, J = gj >> up;
            if (J == 0) break;  // the stencil would leave the domain: every point left is refused
            if (J != L.rowJ || (gj & mask) != L.rowF) {  // a new texel row at this level: new vertical weights
                L.rowJ = J, L.rowF = gj & mask, ++L.stamp;
            }
            const std::array<double, 4>& wy = L.weights[size_t(L.rowF)];
            int first = count, last = -1;  // the pending points
            for (int k = 0; k < count; ++k) {
                if (state_[size_t(k)] != kPending) continue;
                if (((gi0 + uint64_t(k)) >> up) == 0) {  // the stencil would leave the domain
                    state_[size_t(k)] = kRefused, --pending;
                    continue;
                }
                first = std::min(first, k), last = k;
            }
            if (last < 0) break;
            // Columns I - 1 .. I + 2 of every pending point, taken once (a copy: the cache holds only kColumns).
            const uint64_t c0 = ((gi0 + uint64_t(first)) >> up) - 1, c1 = ((gi0 + uint64_t(last)) >> up) + 2;
            columns_.resize(size_t(c1 - c0 + 1));
            for (uint64_t i = c0; i <= c1; ++i) columns_[size_t(i - c0)] = column(L, i, wy);
            for (int k = first; k <= last; ++k) {
                if (state_[size_t(k)] != kPending) continue;
                const uint64_t gi = gi0 + uint64_t(k);
                const Column* col = &columns_[size_t((gi >> up) - 1 - c0)];
                const std::array<double, 4>& wx = L.weights[size_t(gi & mask)];
                double z = 0, level = 0, share = 0;
                int wet = 0, dry = 0;
                bool missing = false, refused = false;
                for (int c = 0; c < 4 && !missing && !refused; ++c) {
                    if (wx[c] == 0) continue;
                    refused = col[c].kind == kUndefined;  // a hole's edge, or a flood's: the kernels decide
                    missing = col[c].kind == kMissing;    // not stored at this level: the next one up
                    wet += col[c].kind == kWet, dry += col[c].kind == kDry;
                    z += wx[c] * col[c].z, level += wx[c] * col[c].level, share += wx[c] * col[c].share;
                }
                if (missing) continue;
                --pending;
                if (refused || (wet && dry)) {  // wet and dry: a flood's edge
                    state_[size_t(k)] = kRefused;
                    continue;
                }
                state_[size_t(k)] = kDone;
                const float nan = std::numeric_limits<float>::quiet_NaN();
                out[k] = Value{float(z), wet ? float(level) : nan, wet ? float(share) : 0.0f, up};
            }
        }
        for (int k = 0; k < count; ++k) filled[k] = state_[size_t(k)] == kDone;
    }

private:
    // A column of samples blended vertically: some not stored at that level (missing), some undefined (a hole) or a
    // flood's edge (some wet, some dry: undefined too, for the texel's purpose), all dry, or all wet.
    enum Kind : uint8_t { kMissing, kUndefined, kDry, kWet };
    struct Column {
        uint64_t i = ~uint64_t{0}, stamp = 0;
        Kind kind = kMissing;
        double z = 0, level = 0, share = 0;
    };
    static constexpr size_t kColumns = 8;  // cached columns per level: a texel uses 4 neighbouring ones
    static constexpr size_t kFineTiles = 512, kRowMasks = 256;  // table sizes (powers of two; a row spans < 128 tiles)
    struct Level {
        bool stored = false;                                            // false: below level 0
        std::vector<influence::SurfacePyramid::Cursor> samples, water;  // by tile parity: a stencil spans up to 2 x 2 tiles
        std::vector<influence::SurfacePyramid::Cursor> finer;           // the level below, by tile parity
        int finerLevel = 0, finerShift = 0;                              // its level, log2 of its tile side
        // The last stored tiles of the level below met (a table by tile column and row parity, as the pyramid's
        // Cursor keeps), each with its fine cells: bit i of row j set when a cell of that level or finer lies between
        // its samples (i, j) and (i + 1, j + 1). A tile dropped from the table is read again when asked again.
        struct FineTile {
            int64_t tx = -1, ty = -1;
            std::array<uint16_t, 16> rows{};
        };
        std::vector<FineTile> fineCells = std::vector<FineTile>(kFineTiles);
        // For the current row of samples (rowJ): per tile column of the level below (a table by column), the OR of
        // its fine cells' rows that a kernel from the row's stencil reaches.
        struct RowMask {
            int64_t tx = -1;
            uint64_t rowJ = ~uint64_t{0};
            uint32_t bits = 0;
        };
        std::vector<RowMask> rowMask = std::vector<RowMask>(kRowMasks);
        int64_t reach = 2;  // samples of this level a finer cell's kernel reaches beyond it
        size_t side = 0, plane = 0;
        int shift = 0;
        std::vector<std::array<double, 4>> weights;  // [fraction]
        uint64_t rowJ = ~uint64_t{0}, rowF = 0, stamp = 1;
        std::array<Column, kColumns> cache;
    };

    // Column i of the current texel row (samples rowJ - 1 .. rowJ + 2, those of non-zero weight), cached.
    const Column& column(Level& L, uint64_t i, const std::array<double, 4>& wy) {
        Column& col = L.cache[i % kColumns];
        if (col.i == i && col.stamp == L.stamp) return col;
        col = Column{};
        col.i = i, col.stamp = L.stamp;
        // The surface is smooth at this level's spacing only where no finer cell weighs: near a cliff of fine cells the
        // cubic would ring (0.135 m beside 0.75 m cells in the tests' grid), so those texels are left to the kernels.
        if (fineCellNear(L, 2 * (int64_t(i) - L.reach), 2 * (int64_t(i) + L.reach))) return col.kind = kUndefined, col;
        int wet = 0, dry = 0;
        for (int r = 0; r < 4; ++r) {
            if (wy[r] == 0) continue;
            const uint64_t sj = L.rowJ - 1 + uint64_t(r);
            const size_t cursor = size_t((i >> L.shift) & 1) | size_t((sj >> L.shift) & 1) << 1;
            const float* s = L.samples[cursor].find(i, sj);
            if (!s) return col.kind = kMissing, col;
            if (std::isnan(s[0])) return col.kind = kUndefined, col;
            col.z += wy[r] * double(s[0]);
            const float* w = water_ ? L.water[cursor].find(i, sj) : channels3_ ? s + L.plane : nullptr;
            if (w && !std::isnan(w[0])) {
                col.level += wy[r] * double(w[0]), col.share += wy[r] * double(w[L.plane]);
                ++wet;
            } else {
                ++dry;
            }
        }
        col.kind = wet && dry ? kUndefined : wet ? kWet : kDry;
        return col;
    }

    // Whether a cell of the level below L's or finer lies between samples x0 - 1 .. x1 of that level (its lattice) in
    // the rows of the current texel row's stencil, grown by a kernel's reach.
    bool fineCellNear(Level& L, int64_t x0, int64_t x1) {
        if (L.finer.empty()) return false;  // level 0: no cell is finer
        const int64_t y0 = 2 * (int64_t(L.rowJ) - 1 - L.reach) - 1, y1 = 2 * (int64_t(L.rowJ) + 2 + L.reach);
        const int shift = L.finerShift;
        x0 = std::max<int64_t>(x0 - 1, 0);
        for (int64_t tx = x0 >> shift; tx <= x1 >> shift; ++tx) {
            Level::RowMask& m = L.rowMask[size_t(tx) & (kRowMasks - 1)];
            if (m.tx != tx || m.rowJ != L.rowJ) {
                m = {tx, L.rowJ, 0};
                for (int64_t ty = std::max<int64_t>(y0, 0) >> shift; ty <= y1 >> shift; ++ty) {
                    if (!L.finer[size_t(tx & 1) | size_t(ty & 1) << 1].find(uint64_t(tx) << shift, uint64_t(ty) << shift)) continue;
                    const std::array<uint16_t, 16>& rows = tileCells(L, tx, ty);
                    for (int64_t y = std::max(y0, ty << shift); y <= std::min(y1, ((ty + 1) << shift) - 1); ++y)
                        m.bits |= rows[size_t(y - (ty << shift))];
                }
            }
            const int64_t lo = std::max(x0, tx << shift) - (tx << shift), hi = std::min(x1, ((tx + 1) << shift) - 1) - (tx << shift);
            if ((m.bits >> lo) & ((uint32_t{1} << (hi - lo + 1)) - 1)) return true;
        }
        return false;
    }

    // The fine cells of stored tile (tx, ty) of the level below L's (Level::fineCells), from the grid's codes.
    const std::array<uint16_t, 16>& tileCells(Level& L, int64_t tx, int64_t ty) {
        Level::FineTile& f = L.fineCells[(size_t(tx) & (kFineTiles / 2 - 1)) | size_t(ty & 1) * (kFineTiles / 2)];
        if (f.tx == tx && f.ty == ty) return f.rows;
        f.tx = tx, f.ty = ty;
        f.rows.fill(0);
        const int level = L.finerLevel, shift = L.finerShift;
        const uint32_t x0 = uint32_t(tx) << (shift + level), y0 = uint32_t(ty) << (shift + level);
        const uint64_t key = mortonEncode(x0, y0);
        const int nodeLevel = std::min(level + shift, scene_.grid().rootLevel);
        std::span<const uint64_t> codes;  // the node's cells: the grid's own in memory, read into codes_ out of core
        if (scene_.outOfCore()) {
            codes_.clear();
            scene_.file()->codesInNode(key, nodeLevel, codes_);
            codes = codes_;
        } else {
            const std::vector<uint64_t>& all = scene_.grid().codes;
            const auto lo = std::lower_bound(all.begin(), all.end(), makeCellCode(key, 0));
            codes = {lo, std::lower_bound(lo, all.end(), makeCellCode(key + mortonSpan(nodeLevel), 0))};
        }
        for (uint64_t code : codes) {
            if (codeLevel(code) > level) continue;
            const uint32_t i = (Grid::keyX(code) - x0) >> level, j = (Grid::keyY(code) - y0) >> level;
            f.rows[j] |= uint16_t(1u << i);
        }
        return f.rows;
    }

    const Scene& scene_;
    std::vector<uint8_t> state_;    // run(): per point, pending, done or refused
    std::vector<Column> columns_;   // run(): the columns of one level for the run
    std::vector<uint64_t> codes_;  // out of core: a node's codes read from the file
    const influence::SurfacePyramid* water_;
    bool channels3_;
    std::vector<Level> levels_;
};

}  // namespace

int copySamples(const float* s, const float* w, size_t plane, int count, float minDepth, float* h, float* depth, float* water) {
    // Branch-free over raw pointers, so that it vectorises: a store through the mask's uint8_t may alias anything, and
    // through the vectors would have every pointer reloaded per texel.
    int defined = 0;
    float* __restrict hr = h;
    if (!w) {
        for (int k = 0; k < count; ++k) {
            const bool ok = !std::isnan(s[k]);  // NaN: outside every cell, no surface (as the kernels leave it)
            hr[k] = ok ? s[k] : hr[k];
            defined += ok;
        }
        return defined;
    }
    float* __restrict dr = depth;
    float* __restrict wr = water;
    const float* __restrict share = w + plane;
    const float wetShare = float(influence::kWetShareMin);
    for (int k = 0; k < count; ++k) {
        const float z = s[k], level = w[k], d = level - z;
        const bool ok = !std::isnan(z), wet = ok && !std::isnan(level) && share[k] >= wetShare;
        hr[k] = ok ? z : hr[k];
        dr[k] = wet && d > 0 ? d : dr[k];
        wr[k] = wet && d > minDepth ? level : wr[k];
        defined += ok;
    }
    return defined;
}

namespace {

// An interpolated texel into tex at `at`, with the water rule of surface.h as the kernel path applies it.
inline void writeInterpolated(const PyramidInterpolator::Value& v, size_t at, float minDepth, CascadeTextures& tex) {
    tex.terrain.h[at] = v.z;
    if (std::isnan(v.level) || double(v.share) < influence::kWetShareMin) return;
    const float d = v.level - v.z;
    if (d > 0) tex.depth[at] = d;
    if (d > minDepth) tex.water.h[at] = v.level;
}

// Level 0's tiles as PyramidTiles::Block wants them: whether the 3 x 3 tiles around tile (tx, ty) are all stored, all
// numbers and all dry or all wet (then PyramidInterpolator interpolates every texel of the block from level 0 and refuses
// none: no sample is undefined or missing, no wet meets dry, the stencil stays in the domain), and those tiles. One
// per worker: each tile's kind is kept in a small table by its address.
class LevelZeroBlocks {
public:
    LevelZeroBlocks(const influence::SurfacePyramid& p, const influence::SurfacePyramid* water)
        : samples_(p, 0), channels3_(p.channels == 3), plane_(samples_.plane()), shift_(std::countr_zero(samples_.side())) {
        if (water) water_.emplace(*water, 0);
    }
    // The block's tiles into b (tile, water), true where it is the caller's.
    bool take(int64_t tx, int64_t ty, PyramidTiles::Block* b = nullptr) {
        if (tx < 1 || ty < 1) return false;  // the stencil of the texels at the domain's edge would leave it
        Kind first = kMixed;
        for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx) {
                const uint64_t i = uint64_t(tx + dx) << shift_, j = uint64_t(ty + dy) << shift_;
                const float* s = samples_.find(i, j);
                if (!s) return false;
                const float* w = water_ ? water_->find(i, j) : channels3_ ? s + plane_ : nullptr;
                const Kind k = kindOf(s, w);
                if (k == kMixed || (first != kMixed && k != first)) return false;
                first = k;
                if (b) b->tile[size_t(3 * (dy + 1) + dx + 1)] = s, b->water[size_t(3 * (dy + 1) + dx + 1)] = k == kWet ? w : nullptr;
            }
        return true;
    }

private:
    enum Kind : uint8_t { kMixed, kDry, kWet };  // kMixed: a NaN elevation, or wet and dry samples
    Kind kindOf(const float* s, const float* w) {
        Entry& e = kinds_[(reinterpret_cast<uintptr_t>(s) / (plane_ * sizeof(float))) % kinds_.size()];
        if (e.tile == s && e.water == w) return e.kind;
        size_t wet = 0;
        bool number = true;
        for (size_t k = 0; k < plane_; ++k) number &= !std::isnan(s[k]), wet += w && !std::isnan(w[k]);
        e = {s, w, !number ? kMixed : wet == 0 ? kDry : wet == plane_ ? kWet : kMixed};
        return e.kind;
    }
    struct Entry {
        const float* tile = nullptr;
        const float* water = nullptr;
        Kind kind = kMixed;
    };
    influence::SurfacePyramid::Cursor samples_;
    std::optional<influence::SurfacePyramid::Cursor> water_;
    bool channels3_;
    size_t plane_;
    int shift_;
    std::array<Entry, 256> kinds_{};
};

// Out of core: whether the pyramid tile (level t, its lattice: copyPyramidTexels) holding lattice point (gi, gj) lies
// outside the domain or in a quadtree node that holds no cell at all. The surface is undefined at every texel there (a
// hole, or outside the data), so there is nothing to copy, interpolate or sum. Counting a node's cells takes two
// binary searches over the file's codes, next to each other; each tile is asked once. Where one tile covers the
// domain there is no node to ask, and nothing is said empty.
class EmptyTiles {
public:
    EmptyTiles(const GridRegionReader& file, int t) : file_(file), t_(t) {
        const int root = file.shape().rootLevel;
        asks_ = t >= 0 && t + influence::kPyramidTileLog2 <= root;
        if (asks_) last_ = (uint64_t{1} << (root - t)) - 1;  // the lattice's last index inside the domain
    }
    bool asks() const { return asks_; }
    bool operator()(uint64_t gi, uint64_t gj) {
        if (!asks_) return false;
        if (gi > last_ || gj > last_) return true;
        const uint64_t ti = gi >> influence::kPyramidTileLog2, tj = gj >> influence::kPyramidTileLog2;
        auto [it, fresh] = empty_.try_emplace(ti << 32 | tj, false);
        if (fresh) {
            const int shift = t_ + influence::kPyramidTileLog2;
            it->second = file_.cellsInNode(mortonEncode(uint32_t(ti << shift), uint32_t(tj << shift)), shift) == 0;
        }
        return it->second;
    }

private:
    const GridRegionReader& file_;
    int t_;
    bool asks_ = false;
    uint64_t last_ = 0;
    std::unordered_map<uint64_t, bool> empty_;  // per tile (ti << 32 | tj)
};

// Copies into tex the texels of `todo` whose centres are samples of a tile the surface pyramid holds at the
// cascade's level (texelM is that level's spacing and the corner lies on its lattice: cascades.h), applying the
// water rule of surface.h to the water channels as the kernel path does; with interpolateLevels > 0, texels finer
// than the levels stored around them are interpolated from a coarser one (PyramidInterpolator). Each span of `todo`
// shrinks to the texels it could not fill, from the first to the last of them, and `copiedMask` (n^2, zero) marks
// the filled texels, so that the kernel path skips those left inside a span (a row with holes at both ends keeps its
// whole span: 23 % of a far cascade's texels at 105 M cells, all of them copies). Out of core, texels in a tile whose
// node holds no cell (EmptyTiles) are marked too, left "no surface": the interpolator would look for coarser samples
// there in vain (1.4 us a texel: 8.5 ms of a fresh frame at 105 M cells, for 6 k texels over holes). Returns the
// texels copied, adds the texels interpolated to work.pyramidInterpolated (the most levels up to work.pyramidInterpolatedUp) and sets
// work.pyramidLevel to the pyramid level used (-1: none fits the cascade). With `tiles`, the copies are marked there
// (PyramidTiles: each worker sets its texels' bits, no list to merge) instead of written or counted (the caller counts
// what it copies), and each span shrinks to the texels written here (interpolated) or left to the kernels, from the
// first to the last (the interpolated ones marked in copiedMask, so the kernels skip them). With `tiles` and a cascade
// below level 0, the texels of blocks whose level-0 tiles are all stored and alike (PyramidTiles::Block) are left to
// the caller to interpolate: marked in copiedMask, counted as interpolated, their blocks listed in `tiles`.
uint64_t copyPyramidTexels(const Scene& scene, const Cascade& c, CascadeTextures& tex, double waterMinDepthM, int interpolateLevels, unsigned threads,
                           std::vector<Todo>& todo, std::vector<uint8_t>& copiedMask, ApproximationWork& work, PyramidTiles* tiles = nullptr) {
    work.pyramidLevel = -1;
    const influence::SurfacePyramid* p = scene.pyramid();
    if (!p) return 0;
    const double t = std::round(std::log2(c.texelM / p->finestCellM));
    if (t > p->topLevel() || std::abs(std::ldexp(p->finestCellM, int(t)) - c.texelM) > 1e-9 * c.texelM) return 0;
    // Texels finer than the finest cells (t < 0, on the same ladder) have no level to copy from, but may interpolate
    // level 0 if it lies within interpolateLevels.
    if (t < 0 && -t > interpolateLevels) return 0;
    if (t >= 0) work.pyramidLevel = int(t);
    const size_t channels = size_t(p->channels);
    // A later step of a scenario: the base's elevation, the step's water pyramid's water (pyramid.h); where the
    // water pyramid holds no tile the step draws no water.
    const influence::SurfacePyramid* wp = scene.waterPyramid();
    const double i0 = std::round(c.x0 / c.texelM), j0 = std::round(c.y0 / c.texelM);
    const float minDepth = float(waterMinDepthM);
    const unsigned workers = resolveThreads(threads);
    std::vector<uint64_t> copied(workers, 0), interpolated(workers, 0);
    std::vector<int> mostUp(workers, 0);
    // Each on its own allocation: side by side in one vector, one worker's writes (out of core, its codes_) would
    // evict the other's reads of the same cache line.
    std::vector<std::unique_ptr<PyramidInterpolator>> interpolators(workers);
    std::vector<std::unique_ptr<EmptyTiles>> emptyTiles(workers);
    // With `tiles`: the table over the tiles of level t that the cascade's texels cover (those at lattice points >= 0).
    const int64_t I0 = int64_t(i0), J0 = int64_t(j0);
    int64_t tx0 = 0, ty0 = 0;
    if (tiles) {
        *tiles = PyramidTiles{};
        for (size_t j = 0; j < todo.size(); ++j) tiles->spans.push_back({0, -1, todo[j].a0, todo[j].a1, todo[j].b0, todo[j].b1});
        if (t >= 0 && I0 + c.n > 0 && J0 + c.n > 0) {
            const influence::SurfacePyramid::Cursor probe(*p, int(t));
            const int shift = std::countr_zero(probe.side());
            tiles->side = int(probe.side()), tiles->plane = probe.plane();
            tx0 = std::max<int64_t>(I0, 0) >> shift, ty0 = std::max<int64_t>(J0, 0) >> shift;
            tiles->originI = I0 - (tx0 << shift), tiles->originJ = J0 - (ty0 << shift);
            tiles->width = int(((I0 + c.n - 1) >> shift) - tx0 + 1), tiles->height = int(((J0 + c.n - 1) >> shift) - ty0 + 1);
            const size_t entries = size_t(tiles->width) * size_t(tiles->height);
            tiles->tile.assign(entries, nullptr), tiles->water.assign(entries, nullptr);
            tiles->copied.assign(entries * size_t(tiles->side), 0);
        }
    }
    // With `tiles` and a cascade below level 0: the blocks left to the caller (PyramidTiles::Block), a table over those
    // the cascade's texels cover: 0 not yet asked, 1 the caller's (its tiles in blockTiles), 2 not, 3 being asked.
    enum : uint8_t { kUnasked, kCallers, kNotCallers, kAsking };
    int blockShift = 0;
    int64_t bx0 = 0, by0 = 0, blocksWide = 0;
    std::vector<uint8_t> blockState;
    std::vector<PyramidTiles::Block> blockTiles;
    std::vector<std::unique_ptr<LevelZeroBlocks>> zeroBlocks(workers);  // per worker: tile kinds kept across its rows
    if (tiles && t < 0 && -t <= PyramidTiles::kMaxBlockUp && I0 + c.n > 0 && J0 + c.n > 0) {
        const influence::SurfacePyramid::Cursor level0(*p, 0);
        if (level0.side() >= 2) {  // a stencil reaches one sample beyond its block: into the next tile only
            tiles->up = int(-t), tiles->levelSide = int(level0.side()), tiles->levelPlane = level0.plane();
            blockShift = std::countr_zero(level0.side()) + tiles->up;
            bx0 = std::max<int64_t>(I0, 0) >> blockShift, by0 = std::max<int64_t>(J0, 0) >> blockShift;
            blocksWide = ((I0 + c.n - 1) >> blockShift) - bx0 + 1;
            blockState.assign(size_t(blocksWide) * size_t(((J0 + c.n - 1) >> blockShift) - by0 + 1), kUnasked);
            blockTiles.resize(blockState.size());
        }
    }
    const uint64_t blockMask = (uint64_t{1} << blockShift) - 1;
    parallelFor(todo.size(), 16, threads, [&](size_t b, size_t e, unsigned worker) {
        std::optional<influence::SurfacePyramid::Cursor> samples, waterSamples;  // neighbouring rows share tiles
        std::unique_ptr<LevelZeroBlocks>& blocks = zeroBlocks[worker];
        if (blockShift && !blocks) blocks = std::make_unique<LevelZeroBlocks>(*p, wp);
        // Whether the block holding lattice point (gi, gj) is the caller's: asked once, by the worker that claims it
        // (its tiles into blockTiles); a worker that meets it while another asks finds the same answer itself.
        auto callersBlock = [&](uint64_t gi, uint64_t gj) {
            const int64_t bx = int64_t(gi >> blockShift), by = int64_t(gj >> blockShift);  // a block is one level-0 tile's texels
            const size_t entry = size_t(bx - bx0) + size_t(by - by0) * size_t(blocksWide);
            std::atomic_ref state(blockState[entry]);
            uint8_t now = state.load(std::memory_order_acquire);
            if (now == kUnasked && state.compare_exchange_strong(now, kAsking, std::memory_order_acquire)) {
                now = blocks->take(bx, by, &blockTiles[entry]) ? kCallers : kNotCallers;
                state.store(now, std::memory_order_release);
            } else if (now == kAsking) {
                now = blocks->take(bx, by) ? kCallers : kNotCallers;
            }
            return now == kCallers;
        };
        if (t >= 0) samples.emplace(*p, int(t));
        if (wp && t >= 0) waterSamples.emplace(*wp, int(t));
        // One per worker for the whole cascade, made when first wanted: the fine cells it looked up serve its later rows.
        std::unique_ptr<PyramidInterpolator>& interpolator = interpolators[worker];
        std::unique_ptr<EmptyTiles>& empty = emptyTiles[worker];
        if (scene.outOfCore() && t >= 0 && !empty) empty = std::make_unique<EmptyTiles>(*scene.file(), int(t));
        const size_t plane = samples ? samples->plane() : 0;
        uint64_t nCopied = 0, nInterpolated = 0;  // counted here, added once: per-worker counters share a cache line
        int up = 0;
        const uint64_t sideMask = samples ? samples->side() - 1 : 0;
        const int tileShift = std::countr_zero(sideMask + 1);
        std::vector<PyramidInterpolator::Value> values;  // a run's interpolated texels
        std::vector<uint8_t> filled;
        for (size_t j = b; j < e; ++j) {
            Todo& todoRow = todo[j];
            const double gj = j0 + double(j);
            const size_t rowAt = j * size_t(c.n);
            for (int span = 0; span < 2; ++span) {
                int* const lo = span == 0 ? &todoRow.a0 : &todoRow.b0;
                int* const hi = span == 0 ? &todoRow.a1 : &todoRow.b1;
                int first = *hi + 1, last = *lo - 1;  // the texels left to the kernels
                auto leave = [&](int i) { first = std::min(first, i), last = i; };
                for (int i = *lo; i <= *hi;) {
                    const double gi = i0 + double(i);
                    if (gi < 0 || gj < 0) {  // outside the domain's lattice
                        leave(i++);
                        continue;
                    }
                    // The run of texels in one tile of the cascade's level, or in one block (else to the span's end).
                    const int end = samples     ? std::min(*hi, i + int(sideMask - (uint64_t(gi) & sideMask)))
                                    : blockShift ? std::min(*hi, i + int(blockMask - (uint64_t(gi) & blockMask)))
                                                 : *hi;
                    const float* s = samples ? samples->find(uint64_t(gi), uint64_t(gj)) : nullptr;
                    if (s) {  // copies: the tile's samples side by side, with the water rule of surface.h
                        const float* w = wp ? waterSamples->find(uint64_t(gi), uint64_t(gj)) : channels == 3 ? s + plane : nullptr;
                        const int len = end - i + 1;
                        const size_t at = rowAt + size_t(i);
                        std::memset(&copiedMask[at], 1, size_t(len));
                        if (tiles) {  // left to the caller, who counts them too (without reading the samples here)
                            const int sample = int(s - samples->tile());  // the water tile's layout is the same
                            const size_t entry = size_t(int64_t(uint64_t(gi) >> tileShift) - tx0) +
                                                 size_t(int64_t(uint64_t(gj) >> tileShift) - ty0) * size_t(tiles->width);
                            // Workers meet in a tile only at the edges of their rows; the same pointers, bits or'ed.
                            std::atomic_ref(tiles->tile[entry]).store(s - sample, std::memory_order_relaxed);
                            if (w) std::atomic_ref(tiles->water[entry]).store(w - sample, std::memory_order_relaxed);
                            std::atomic_ref(tiles->copied[entry * size_t(tiles->side) + size_t(uint64_t(gj) & sideMask)])
                                .fetch_or(uint16_t(((1u << len) - 1) << (uint64_t(gi) & sideMask)), std::memory_order_relaxed);
                        } else {
                            nCopied += uint64_t(copySamples(s, w, plane, len, minDepth, &tex.terrain.h[at], w ? &tex.depth[at] : nullptr,
                                                            w ? &tex.water.h[at] : nullptr));
                        }
                        i = end + 1;
                        continue;
                    }
                    // Finer than the level stored here: interpolated, or left to the kernels; nothing where no cell is.
                    const int len = end - i + 1;
                    if (empty && (*empty)(uint64_t(gi), uint64_t(gj))) {
                        std::memset(&copiedMask[rowAt + size_t(i)], 1, size_t(len));
                        i = end + 1;
                        continue;
                    }
                    if (blockShift && callersBlock(uint64_t(gi), uint64_t(gj))) {  // the caller interpolates them
                        std::memset(&copiedMask[rowAt + size_t(i)], 1, size_t(len));
                        nInterpolated += uint64_t(len), up = std::max(up, tiles->up);
                        i = end + 1;
                        continue;
                    }
                    if (interpolateLevels > 0 && !interpolator) interpolator = std::make_unique<PyramidInterpolator>(scene, *p, wp, int(t), interpolateLevels);
                    if (interpolator) {
                        values.resize(size_t(len)), filled.resize(size_t(len));
                        interpolator->run(uint64_t(i0 + double(i)), len, uint64_t(gj), values.data(), filled.data());
                    }
                    for (int k = 0; k < len; ++k, ++i) {
                        if (!interpolator || !filled[size_t(k)]) {
                            leave(i);
                            continue;
                        }
                        const PyramidInterpolator::Value& v = values[size_t(k)];
                        const size_t at = rowAt + size_t(i);
                        copiedMask[at] = 1;
                        if (tiles) leave(i);  // written here: the caller packs it with the span
                        writeInterpolated(v, at, minDepth, tex);
                        ++nInterpolated;
                        up = std::max(up, v.up);
                    }
                }
                *lo = first, *hi = last;
            }
        }
        copied[worker] += nCopied, interpolated[worker] += nInterpolated, mostUp[worker] = std::max(mostUp[worker], up);
    });
    uint64_t total = 0;
    for (unsigned k = 0; k < workers; ++k)
        total += copied[k], work.pyramidInterpolated += interpolated[k], work.pyramidInterpolatedUp = std::max(work.pyramidInterpolatedUp, mostUp[k]);
    for (size_t e = 0; e < blockState.size(); ++e) {  // the caller's blocks, with their tiles
        if (blockState[e] != kCallers) continue;
        const int64_t bx = bx0 + int64_t(e % size_t(blocksWide)), by = by0 + int64_t(e / size_t(blocksWide));
        PyramidTiles::Block& b = tiles->blocks.emplace_back(blockTiles[e]);
        b.i0 = (bx << blockShift) - I0, b.j0 = (by << blockShift) - J0;
    }
    return total;
}

// The cells the approximation sums over: the scene's own (in memory) or a region's (out of core).
struct CellData {
    const Grid& grid;
    const influence::InfluenceLists& lists;
    const std::vector<Scene::CellKernel>& kernels;
    int waterLayer;  // grid layer of water_depth, or -1
};

// An inclusive range of texel columns and rows.
struct TexelRange {
    int i0, i1, j0, j1;
};

// Gathers the influence list of cell k into cand, relative to k's centre and value. Returns the water level
// base lk: the level of a wet cell, k's own if k is wet (NaN when no cell of the list is wet).
double gatherCandidates(const CellData& cells, uint32_t k, Candidates& cand) {
    const Grid& g = cells.grid;
    const auto& kernels = cells.kernels;
    const double kx = kernels[k].cx, ky = kernels[k].cy;
    const double zk = g.values[0][k];
    const int depthLayer = cells.waterLayer;
    const float* depthValues = depthLayer >= 0 ? g.values[size_t(depthLayer)].data() : nullptr;
    const auto list = cells.lists.list(k);
    // The water level field (DESIGN.md section 12, influence/surface.h) is taken relative to a wet cell's
    // level, k's own if k is wet, as the exact evaluator's levelBase() does: a constant level stays exact.
    double lk = std::numeric_limits<double>::quiet_NaN();
    if (depthValues) {
        if (depthValues[k] > 0) lk = zk + double(depthValues[k]);
        for (size_t idx = 0; idx < list.size() && std::isnan(lk); ++idx)
            if (depthValues[list[idx]] > 0) lk = double(g.values[0][list[idx]]) + double(depthValues[list[idx]]);
    }
    const bool anyWet = !std::isnan(lk);
    const size_t m = list.size(), padded = (m + kLanes - 1) / kLanes * kLanes;
    for (auto* v : {&cand.ex, &cand.ey, &cand.a, &cand.dz, &cand.dl, &cand.wet}) v->assign(padded, 0.0f);
    cand.r2.assign(padded, -1.0f);  // padding never counts: d2 < -1 is false
    cand.count = m;
    for (size_t idx = 0; idx < m; ++idx) {
        const uint32_t i = list[idx];
        const auto& ck = kernels[i];
        cand.ex[idx] = static_cast<float>(ck.cx - kx);
        cand.ey[idx] = static_cast<float>(ck.cy - ky);
        cand.a[idx] = ck.a;
        cand.r2[idx] = ck.r2;
        cand.dz[idx] = static_cast<float>(g.values[0][i] - zk);
        if (anyWet && depthValues[i] > 0) {
            cand.wet[idx] = 1.0f;
            cand.dl[idx] = static_cast<float>(double(g.values[0][i]) + double(depthValues[i]) - lk);
        }
    }
    return lk;
}

// The texels left to evaluate are listed cell by cell. Their bounding box's cells (Grid::cellsInBox) serve a
// fresh cascade, whose visible texels fill 25-100 % of that box. A moving camera leaves thin strips along the
// cascade's edges, whose bounding box is still the whole cascade: listing its cells would examine every cell
// under the cascade (about 2 M in Wachau's far cascade) for a few thousand texels. Below one texel to evaluate
// in kSparseTodo of the box, each texel's cell is located instead (Grid::locate, a binary search over the cells),
// so the work follows the texels. Fresh cascades without a pyramid (above 1/4) always list the box, and a moving
// camera's strips (0.1-1 % of the box in hc-bench's fly-through) are always located. Between them lie fresh cascades
// whose texels the pyramid mostly filled: Petzenkirchen's far cascade left 55 k texels to sum in a box of 817 k,
// whose listing examined 570 k cells in 17-21 ms; 4 (not 16, as first set) has them located.
constexpr uint64_t kSparseTodo = 4;

// Appends to `cells` (sorted, each once) the cells whose half-open squares hold a texel centre `need`ed in r:
// the cells the box listing would keep (a cell holding no texel to evaluate is skipped there too).
void cellsUnderTexels(const Grid& g, const Cascade& c, const std::vector<uint8_t>& need, const TexelRange& r, unsigned threads,
                      std::vector<uint32_t>& cells) {
    const double s = c.texelM;
    std::vector<std::vector<uint32_t>> found(resolveThreads(threads));
    parallelFor(size_t(r.j1 - r.j0 + 1), 64, threads, [&](size_t b, size_t e, unsigned worker) {
        std::vector<uint32_t>& out = found[worker];
        for (size_t jr = b; jr < e; ++jr) {
            const size_t j = size_t(r.j0) + jr;
            const double y = c.y0 + double(int(j)) * s;
            const uint8_t* row = &need[j * size_t(c.n)];
            Grid::Square last{0, 0, -1, -1};  // empty: no point is inside
            for (int i = r.i0; i <= r.i1; ++i) {
                if (!row[i]) continue;
                const double x = c.x0 + i * s;
                // Along a row, texels smaller than the cells fall into the cell just located.
                if (x >= last.x0 && x < last.x1 && y >= last.y0 && y < last.y1) continue;
                const std::optional<uint32_t> k = g.locate(x, y);
                if (!k) continue;
                out.push_back(*k);
                last = g.cellSquare(*k);
            }
        }
    });
    for (const std::vector<uint32_t>& f : found) cells.insert(cells.end(), f.begin(), f.end());
    std::sort(cells.begin(), cells.end());
    cells.erase(std::unique(cells.begin(), cells.end()), cells.end());
}

}  // namespace

void CascadeTextures::buildBothMip(unsigned threads) {
    bothMip.resize(terrain.mip.size());
    for (size_t l = 0; l < terrain.mip.size(); ++l) {
        const std::vector<float>&a = terrain.mip[l], &b = water.mip[l];
        bothMip[l].resize(a.size());
        parallelFor(a.size(), a.size() < kMipParallelNodes ? a.size() : size_t{1} << 16, threads, [&](size_t begin, size_t end, unsigned) {
            for (size_t i = begin; i < end; ++i) bothMip[l][i] = std::max(a[i], b[i]);
        });
    }
}

void Heightfield::buildMip(unsigned threads) {
    // Sides n - 1, then halving to 1. The levels' storage is reused when this heightfield's was (CascadeCache).
    mipSide.clear();
    for (int side = n - 1;; side = (side + 1) / 2) {
        mipSide.push_back(side);
        if (side <= 1) break;
    }
    mip.resize(mipSide.size());
    // Row by row, each node the largest of the four texels around its patch (level 0) or of its children (a child
    // past the lower level's side is none); the rows of the large levels on the workers.
    for (size_t l = 0; l < mip.size(); ++l) {
        const int side = mipSide[l];
        std::vector<float>& level = mip[l];
        level.resize(size_t(side) * size_t(side));
        const size_t rowsPerChunk = size_t(side) * size_t(side) < kMipParallelNodes ? size_t(side) : 16;
        parallelFor(size_t(side), rowsPerChunk, threads, [&](size_t b, size_t e, unsigned) {
            for (size_t j = b; j < e; ++j) {
                float* out = &level[j * size_t(side)];
                if (l == 0) {
                    const float* r0 = &h[j * size_t(n)];
                    const float* r1 = r0 + n;
                    for (int i = 0; i < side; ++i) out[i] = std::max(std::max(r0[i], r0[i + 1]), std::max(r1[i], r1[i + 1]));
                    continue;
                }
                const int lower = mipSide[l - 1];
                const std::vector<float>& lo = mip[l - 1];
                const float* c0 = &lo[2 * j * size_t(lower)];
                const float* c1 = 2 * j + 1 < size_t(lower) ? c0 + lower : nullptr;
                for (int i = 0; i < side; ++i) {
                    const int a = 2 * i, b1 = 2 * i + 1;
                    float m = c0[a];
                    if (b1 < lower) m = std::max(m, c0[b1]);
                    if (c1) m = std::max(m, b1 < lower ? std::max(c1[a], c1[b1]) : c1[a]);
                    out[i] = m;
                }
            }
        });
    }
}

namespace {

// Sums the kernels at the texels of `todo` inside range r that `need` it (not copied from the pyramid), whose centres
// lie in `cells` (sorted), each cell's texels over its influence list. Adds the kernel evaluations to *gaussians.
void sumTexels(const CellData& data, const Cascade& c, const std::vector<Todo>& todo, const std::vector<uint8_t>& need, const TexelRange& r,
               const std::vector<uint32_t>& cells, CascadeTextures& tex, double waterMinDepthM, unsigned threads, uint64_t* gaussiansOut) {
    const Grid& g = data.grid;
    const int n = c.n;
    const double s = c.texelM;
    const int i0 = r.i0, i1 = r.i1, j0 = r.j0, j1 = r.j1;
    const float tail = static_cast<float>(data.lists.params().tail());
    const float minDepth = static_cast<float>(waterMinDepthM);
    std::vector<uint64_t> gaussians(resolveThreads(threads), 0);
    std::vector<Candidates> scratch(gaussians.size());
    parallelFor(cells.size(), 64, threads, [&](size_t b, size_t e, unsigned worker) {
        Candidates& cand = scratch[worker];
        uint64_t evaluated = 0;  // added to gaussians[worker] once: the workers' counters share a cache line
        for (size_t ci = b; ci < e; ++ci) {
            const uint32_t k = cells[ci];
            const Grid::Square q = g.cellSquare(k);
            // Texel centres inside k's half-open square [x0, x1) x [y0, y1).
            auto first = [&](double lo, double origin) {
                double t = std::ceil((lo - origin) / s);
                while (origin + (t - 1) * s >= lo) t -= 1;
                while (origin + t * s < lo) t += 1;
                return t;
            };
            const int ia = std::max(i0, int(first(q.x0, c.x0))), ib = std::min(i1 + 1, int(first(q.x1, c.x0)));
            const int ja = std::max(j0, int(first(q.y0, c.y0))), jb = std::min(j1 + 1, int(first(q.y1, c.y0)));
            if (ia >= ib || ja >= jb) continue;
            // Only a cell with a texel centre to evaluate gathers its list: in the visible texels' bounding box
            // (the polygon is a slab of a trapezoid) 25-65 % of the cells that hold a texel centre hold no
            // visible one.
            bool any = false;
            for (int j = ja; j < jb && !any; ++j) {
                const Todo& t = todo[size_t(j)];
                any = std::max(ia, t.a0) <= std::min(ib - 1, t.a1) || std::max(ia, t.b0) <= std::min(ib - 1, t.b1);
            }
            if (!any) continue;
            const double lk = gatherCandidates(data, k, cand);
            const bool anyWet = !std::isnan(lk);
            const size_t m = cand.count, padded = cand.ex.size();
            const double kx = data.kernels[k].cx, ky = data.kernels[k].cy;
            const double zk = g.values[0][k];
            for (int j = ja; j < jb; ++j) {
                const float fy = static_cast<float>(c.y0 + j * s - ky);
                const Todo& span = todo[size_t(j)];
                for (auto [lo, hi] : {std::pair{span.a0, span.a1}, {span.b0, span.b1}}) {
                    for (int i = std::max(ia, lo), rb = std::min(ib, hi + 1); i < rb; ++i) {
                        const size_t t = size_t(j) * size_t(n) + size_t(i);
                        if (!need[t]) continue;
                        const float fx = static_cast<float>(c.x0 + i * s - kx);
                        evaluated += m;
                        float num[kLanes] = {}, den[kLanes] = {}, numL[kLanes] = {}, denW[kLanes] = {};
                        const float* __restrict ex = cand.ex.data();
                        const float* __restrict ey = cand.ey.data();
                        const float* __restrict ca = cand.a.data();
                        const float* __restrict cr2 = cand.r2.data();
                        const float* __restrict cdz = cand.dz.data();
                        const float* __restrict cdl = cand.dl.data();
                        const float* __restrict cwet = cand.wet.data();
                        // Branch-free (masks as 0/1 factors) so the compiler vectorises across the 8 lanes.
                        for (size_t base = 0; base < padded; base += kLanes)
                            for (int l = 0; l < kLanes; ++l) {
                                const size_t idx = base + size_t(l);
                                const float dx = fx - ex[idx], dy = fy - ey[idx];
                                const float d2 = dx * dx + dy * dy;
                                const float kernel = expNeg(-d2 * ca[idx]) - tail;
                                const float w = std::max(kernel, 0.0f) * static_cast<float>(d2 < cr2[idx]);
                                num[l] += w * cdz[idx];
                                numL[l] += w * cdl[idx];  // cdl is 0 for dry cells
                                denW[l] += w * cwet[idx];
                                den[l] += w;
                            }
                        float sn = 0, sd = 0, snL = 0, sdW = 0;
                        for (int l = 0; l < kLanes; ++l) sn += num[l], sd += den[l], snL += numL[l], sdW += denW[l];
                        // sd >= the cell's own weight at its farthest point (kernel.h): never zero here.
                        const double z = zk + double(sn / sd);
                        tex.terrain.h[t] = static_cast<float>(z);
                        // Water where the wet cells hold at least kWetShareMin of the weight and their level is above
                        // the terrain (surface.h); the depth texture holds level - terrain there (0 elsewhere), the
                        // water heightfield the level itself where that depth exceeds the minimum drawn.
                        if (anyWet && sdW > 0 && double(sdW) >= influence::kWetShareMin * double(sd)) {
                            const double level = lk + double(snL / sdW);
                            const float d = static_cast<float>(level - z);
                            if (d > 0) tex.depth[t] = d;
                            if (d > minDepth) tex.water.h[t] = static_cast<float>(level);
                        }
                    }
                }
            }
        }
        gaussians[worker] += evaluated;
    });
    for (uint64_t v : gaussians) *gaussiansOut += v;
}

// Out of core, the texels left to evaluate are taken a block of kOutOfCoreBlock^2 at a time: the block's cells,
// with those whose kernels reach it, are read from the grid file and their lists built (influence/region.h), then
// dropped. 256: a block of a fresh far cascade (texels up to 2x the cells) reads ~0.1-0.3 M cells (~30-70 MB with
// their lists) and the per-block overhead (the kernel margin read twice at block edges) stays a small share.
constexpr int kOutOfCoreBlock = 256;
// Blocks whose texels to evaluate fill less than 1/kOutOfCoreSplit of them are split, down to kOutOfCoreMinBlock a
// side: a block's region holds every cell under it, and in a far cascade the texels to sum (over coarse cells) sit
// beside copied ones over fine cells, whose cells a loose block would read and build lists for in vain.
constexpr uint64_t kOutOfCoreSplit = 4;
constexpr int kOutOfCoreMinBlock = 16;

// Clears `need` at the texels of r whose pyramid tile (level t, its lattice: copyPyramidTexels) is not stored because
// its quadtree node holds no cell at all: the surface is undefined at every texel there (a hole, or outside the data),
// so no cell need be read for them (EmptyTiles). Texels outside the domain are cleared too.
void dropEmptyTiles(const GridRegionReader& file, const Cascade& c, int t, const TexelRange& r, std::vector<uint8_t>& need) {
    EmptyTiles empty(file, t);
    if (!empty.asks()) return;
    const double i0 = std::round(c.x0 / c.texelM), j0 = std::round(c.y0 / c.texelM);
    for (int j = r.j0; j <= r.j1; ++j)
        for (int i = r.i0; i <= r.i1; ++i) {
            uint8_t& flag = need[size_t(j) * size_t(c.n) + size_t(i)];
            if (!flag) continue;
            const double gi = i0 + i, gj = j0 + j;
            if (gi < 0 || gj < 0 || empty(uint64_t(gi), uint64_t(gj))) flag = 0;
        }
}

// The region out of core for the texels `need`ed in block r: the cells whose squares meet the block grown by their
// kernel reach (GridRegionReader::region), less those that reach no needed texel (their square grown by their reach
// holds none: a summed-area table of `need` over the block answers each in four reads), with the lists of the rest.
// A far cascade's texels to sum lie over coarse cells beside copied texels over fine ones, whose cells the box alone
// would bring in and build lists for in vain (Marchfeld's far cascade: 1.0 M cells read for 64 k texels). A cell kept
// is one that may weigh at a needed texel, so the texels' sums are what the whole grid gives. Adds the cells read
// from the file to *cellsRead.
influence::SurfaceRegion readNeededRegion(const GridRegionReader& file, const influence::KernelParams& params, const std::vector<double>& reach,
                                          const Cascade& c, const std::vector<uint8_t>& need, const TexelRange& r, uint64_t& cellsRead) {
    const double s = c.texelM;
    Grid all = file.region({c.x0 + r.i0 * s, c.y0 + r.j0 * s, c.x0 + r.i1 * s, c.y0 + r.j1 * s}, reach);
    cellsRead += all.cellCount();
    const int w = r.i1 - r.i0 + 1, h = r.j1 - r.j0 + 1;
    std::vector<uint32_t> sat(size_t(w + 1) * size_t(h + 1), 0);  // sat[(j + 1) (w + 1) + i + 1]: needed texels in [0, i] x [0, j]
    for (int j = 0; j < h; ++j)
        for (int i = 0; i < w; ++i)
            sat[size_t(j + 1) * size_t(w + 1) + size_t(i + 1)] = sat[size_t(j) * size_t(w + 1) + size_t(i + 1)] +
                                                                 sat[size_t(j + 1) * size_t(w + 1) + size_t(i)] -
                                                                 sat[size_t(j) * size_t(w + 1) + size_t(i)] +
                                                                 need[size_t(r.j0 + j) * size_t(c.n) + size_t(r.i0 + i)];
    auto first = [&](double v, double origin, int lo, int count) {  // first texel index at or after v, clamped to [lo, lo + count]
        return std::clamp(int(std::ceil((v - origin) / s)), lo, lo + count);
    };
    auto last = [&](double v, double origin, int lo, int count) {  // last texel index at or before v, clamped to [lo - 1, lo + count - 1]
        return std::clamp(int(std::floor((v - origin) / s)), lo - 1, lo + count - 1);
    };
    Grid kept = all;
    kept.codes.clear();
    for (auto& v : kept.values) v.clear();
    for (size_t k = 0; k < all.cellCount(); ++k) {
        const Grid::Square q = all.cellSquare(k);
        const double m = reach[size_t(all.level(k))] + s;  // a texel's rounding aside, one texel of slack
        const int ia = first(q.x0 - m, c.x0, r.i0, w), ib = last(q.x1 + m, c.x0, r.i0, w);
        const int ja = first(q.y0 - m, c.y0, r.j0, h), jb = last(q.y1 + m, c.y0, r.j0, h);
        if (ia > ib || ja > jb) continue;
        const size_t x0 = size_t(ia - r.i0), x1 = size_t(ib - r.i0 + 1), y0 = size_t(ja - r.j0), y1 = size_t(jb - r.j0 + 1);
        const size_t W = size_t(w + 1);
        if (sat[y1 * W + x1] + sat[y0 * W + x0] - sat[y0 * W + x1] - sat[y1 * W + x0] == 0) continue;
        kept.codes.push_back(all.codes[k]);
        for (size_t l = 0; l < all.values.size(); ++l) kept.values[l].push_back(all.values[l][k]);
    }
    influence::SurfaceRegion out;
    out.lists = influence::buildInfluenceLists(kept, params, 1, false);
    out.grid = std::move(kept);
    return out;
}

}  // namespace

uint64_t interpolateBlock(const Scene& scene, const Cascade& c, const PyramidTiles& tiles, const PyramidTiles::Block& block, double waterMinDepthM,
                          CascadeTextures& tex, std::vector<RowFill>& rows) {
    const influence::SurfacePyramid* p = scene.pyramid();
    if (!p || tiles.up < 1) throw Error("interpolateBlock: no block to interpolate (a bug)");
    PyramidInterpolator interpolator(scene, *p, scene.waterPyramid(), -tiles.up, tiles.up);
    const int64_t I0 = int64_t(std::round(c.x0 / c.texelM)), J0 = int64_t(std::round(c.y0 / c.texelM));
    const size_t side = size_t(tiles.levelSide) << tiles.up;
    std::vector<PyramidInterpolator::Value> values(side);
    std::vector<uint8_t> filled(side);
    uint64_t written = 0;
    forEachBlockRun(tiles, block, c.n, [&](int j, int lo, int hi, int span) {
        const int len = hi - lo + 1;
        interpolator.run(uint64_t(I0 + lo), len, uint64_t(J0 + j), values.data(), filled.data());
        for (int k = 0; k < len; ++k) {
            if (!filled[size_t(k)]) throw Error("interpolateBlock: a texel of a block refused (a bug)");
            writeInterpolated(values[size_t(k)], size_t(j) * size_t(c.n) + size_t(lo + k), float(waterMinDepthM), tex);
        }
        written += uint64_t(len);
        widenSpan(rows[size_t(j)], span, lo, hi);
    });
    return written;
}

std::vector<RowFill> rowFills(const Cascade& c, const TexelReuse* reuse, uint64_t& kept) {
    std::vector<RowFill> rows(size_t(c.n));
    for (int j = 0; j < c.n; ++j) {
        int f, l;
        const Todo t = keptSpan(c, reuse, j, f, l);
        rows[size_t(j)] = RowFill{f, l, t.a0, t.a1, t.b0, t.b1};
        if (f <= l) kept += uint64_t(l - f + 1);
    }
    return rows;
}

ApproximationWork approximate(const Scene& scene, const Cascade& c, CascadeTextures& tex, double waterMinDepthM, unsigned threads,
                              const TexelReuse* reuse, int interpolateLevels, std::vector<RowFill>* rows, PyramidTiles* tiles) {
    const int n = c.n;
    tex.hasWater = scene.hasWater();
    tex.terrain.n = tex.water.n = n;
    // Sized only: copyReusedTexels writes every texel (with `rows`, every texel to evaluate).
    tex.terrain.h.resize(size_t(n) * size_t(n));
    if (tex.hasWater) {
        tex.water.h.resize(size_t(n) * size_t(n));
        tex.depth.resize(size_t(n) * size_t(n));
    }
    ApproximationWork work;
    std::vector<Todo> todo = copyReusedTexels(c, reuse, tex, work.reusedTexels, threads, rows);
    // The texels left to evaluate: `need` (n^2) marks them, the spans of `todo` hold them (and copies between them).
    std::vector<uint8_t> copied(size_t(n) * size_t(n), 0), need(size_t(n) * size_t(n), 0);
    if (tiles && !rows) throw Error("approximate: pyramid tiles without row spans (a bug)");
    work.pyramidTexels = copyPyramidTexels(scene, c, tex, waterMinDepthM, interpolateLevels, threads, todo, copied, work, tiles);
    if (tiles)  // each span: the texels written here, the copies left out at its ends
        for (size_t j = 0; j < size_t(n); ++j) {
            RowFill& r = (*rows)[j];
            r.a0 = todo[j].a0, r.a1 = todo[j].a1, r.b0 = todo[j].b0, r.b1 = todo[j].b1;
        }
    // The texels left to the kernels, their box and count; on all cores where the spans are long (a fresh cascade 0 at
    // 105 M cells: 553 k texels to look at, 0.9 ms on one core, all of them interpolated), else on this one (a moving
    // frame's few new texels: waking the workers would cost more).
    struct Box {
        int i0, i1, j0, j1;
        uint64_t texels;
    };
    uint64_t spanTexels = 0;
    for (const Todo& t : todo) spanTexels += uint64_t(std::max(0, t.a1 - t.a0 + 1) + std::max(0, t.b1 - t.b0 + 1));
    const unsigned boxThreads = spanTexels >= (uint64_t{1} << 16) ? threads : 1;
    std::vector<Box> boxes(resolveThreads(boxThreads), Box{n, -1, n, -1, 0});
    parallelFor(size_t(n), 64, boxThreads, [&](size_t b, size_t e, unsigned worker) {
        Box x = boxes[worker];  // a copy: the workers' boxes share cache lines
        for (int j = int(b); j < int(e); ++j) {
            const Todo& t = todo[size_t(j)];
            for (auto [lo, hi] : {std::pair{t.a0, t.a1}, {t.b0, t.b1}})
                for (int i = lo; i <= hi; ++i) {
                    const size_t at = size_t(j) * size_t(n) + size_t(i);
                    if (copied[at]) continue;
                    need[at] = 1;
                    x = {std::min(x.i0, i), std::max(x.i1, i), std::min(x.j0, j), std::max(x.j1, j), x.texels + 1};
                }
        }
        boxes[worker] = x;
    });
    int i0 = n, i1 = -1, j0 = n, j1 = -1;
    uint64_t todoTexels = 0;
    for (const Box& x : boxes)
        i0 = std::min(i0, x.i0), i1 = std::max(i1, x.i1), j0 = std::min(j0, x.j0), j1 = std::max(j1, x.j1), todoTexels += x.texels;
    copied = {};
    if (i1 < 0) return work;
    const double s = c.texelM;
    auto cellsFor = [&](const Grid& g, const TexelRange& r, uint64_t todoInRange, std::vector<uint32_t>& cells) {
        const uint64_t boxTexels = uint64_t(r.i1 - r.i0 + 1) * uint64_t(r.j1 - r.j0 + 1);
        if (todoInRange * kSparseTodo < boxTexels) cellsUnderTexels(g, c, need, r, threads, cells);
        else g.cellsInBox(c.x0 + r.i0 * s, c.y0 + r.j0 * s, c.x0 + r.i1 * s, c.y0 + r.j1 * s, cells);
        work.cellsVisited += cells.size();
    };
    std::vector<uint32_t> cells;
    if (!scene.outOfCore()) {
        const TexelRange all{i0, i1, j0, j1};
        cellsFor(scene.grid(), all, todoTexels, cells);
        sumTexels({scene.grid(), scene.lists(), scene.kernels(), scene.waterLayer()}, c, todo, need, all, cells, tex, waterMinDepthM, threads,
                  &work.gaussians);
        return work;
    }
    // Out of core: less the texels in pyramid tiles whose nodes hold no cell.
    if (work.pyramidLevel >= 0) dropEmptyTiles(*scene.file(), c, work.pyramidLevel, TexelRange{i0, i1, j0, j1}, need);
    // Blocks of at most kOutOfCoreBlock^2 texels, shrunk to the texels they need and split while those are sparse, so
    // that a region read follows the texels (a frame's few stray texels along a hole's edge must not read the cells
    // of whole blocks around them).
    std::vector<TexelRange> blocks, pending{{i0, i1, j0, j1}};
    std::vector<uint64_t> blockTexels;
    while (!pending.empty()) {
        TexelRange r = pending.back();
        pending.pop_back();
        uint64_t count = 0;
        TexelRange box{r.i1 + 1, r.i0 - 1, r.j1 + 1, r.j0 - 1};
        for (int j = r.j0; j <= r.j1; ++j)
            for (int i = r.i0; i <= r.i1; ++i)
                if (need[size_t(j) * size_t(n) + size_t(i)]) {
                    ++count;
                    box = {std::min(box.i0, i), std::max(box.i1, i), std::min(box.j0, j), std::max(box.j1, j)};
                }
        if (count == 0) continue;
        r = box;
        const int w = r.i1 - r.i0 + 1, h = r.j1 - r.j0 + 1;
        const uint64_t area = uint64_t(w) * uint64_t(h);
        if (area > uint64_t(kOutOfCoreBlock) * kOutOfCoreBlock || (count * kOutOfCoreSplit < area && std::max(w, h) > kOutOfCoreMinBlock)) {
            const int mi = r.i0 + w / 2, mj = r.j0 + h / 2;
            for (const TexelRange& q : {TexelRange{r.i0, mi - 1, r.j0, mj - 1}, TexelRange{mi, r.i1, r.j0, mj - 1},
                                        TexelRange{r.i0, mi - 1, mj, r.j1}, TexelRange{mi, r.i1, mj, r.j1}})
                if (q.i0 <= q.i1 && q.j0 <= q.j1) pending.push_back(q);
            continue;
        }
        blocks.push_back(r);
        blockTexels.push_back(count);
    }
    // The blocks on the workers, one each at a time, single-threaded inside: most are small (a moving camera's strips,
    // the scattered texels of a far cascade over coarse cells), where starting threads per block cost more than the
    // block (Marchfeld's far cascade: 1.1 s for 64 k texels that way). Blocks hold disjoint texels.
    struct Tally {
        uint64_t regions = 0, cellsRead = 0, cellsVisited = 0, gaussians = 0;
    };
    std::vector<Tally> tally(resolveThreads(threads));
    const std::vector<double> reach = influence::kernelReachM(scene.grid(), scene.params());
    parallelFor(blocks.size(), 1, threads, [&](size_t b, size_t e, unsigned worker) {
        Tally& t = tally[worker];
        std::vector<uint32_t> blockCells;
        for (size_t k = b; k < e; ++k) {
            const TexelRange& r = blocks[k];
            const influence::SurfaceRegion region = readNeededRegion(*scene.file(), scene.params(), reach, c, need, r, t.cellsRead);
            ++t.regions;
            if (region.grid.cellCount() == 0) continue;
            const std::vector<Scene::CellKernel> kernels = Scene::kernelsOf(region.grid, scene.params());
            blockCells.clear();
            const uint64_t boxTexels = uint64_t(r.i1 - r.i0 + 1) * uint64_t(r.j1 - r.j0 + 1);
            if (blockTexels[k] * kSparseTodo < boxTexels) cellsUnderTexels(region.grid, c, need, r, 1, blockCells);
            else region.grid.cellsInBox(c.x0 + r.i0 * s, c.y0 + r.j0 * s, c.x0 + r.i1 * s, c.y0 + r.j1 * s, blockCells);
            t.cellsVisited += blockCells.size();
            sumTexels({region.grid, region.lists, kernels, scene.waterLayer()}, c, todo, need, r, blockCells, tex, waterMinDepthM, 1,
                      &t.gaussians);
        }
    });
    for (const Tally& t : tally)
        work.regionsRead += t.regions, work.cellsRead += t.cellsRead, work.cellsVisited += t.cellsVisited, work.gaussians += t.gaussians;
    return work;
}

}  // namespace hc::render::detail
