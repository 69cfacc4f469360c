// Texels finer than the pyramid levels stored around them, interpolated from a coarser level: PyramidInterpolator
// (declared with its caches in approximate_internal.h), and interpolateBlock(), the blocks a backend left to the CPU.
// Part of the approximation pass (approximate.cpp).
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>
#include <span>

#include "approximate_internal.h"
#include "heightcast/core/error.h"
#include "heightcast/grid/morton.h"

namespace hc::render::detail {
namespace {

// Catmull-Rom weights of the four samples around a point at fraction f in [0, 1) of their middle interval: the
// cubic through the samples with slopes from their neighbours. f = 0 gives (0, 1, 0, 0): the sample itself.
inline void catmullRom(double f, double w[4]) {
    const double f2 = f * f, f3 = f2 * f;
    w[0] = 0.5 * (-f3 + 2 * f2 - f);
    w[1] = 0.5 * (3 * f3 - 5 * f2 + 2);
    w[2] = 0.5 * (-3 * f3 + 4 * f2 + f);
    w[3] = 0.5 * (f3 - f2);
}

}  // namespace

PyramidInterpolator::PyramidInterpolator(const Scene& scene, const influence::SurfacePyramid& p,
                                         const influence::SurfacePyramid* water, int t, int maxUp)
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

void PyramidInterpolator::run(uint64_t gi0, int count, uint64_t gj, Value* out, uint8_t* filled) {
    enum : uint8_t { kPending, kDone, kRefused };
    state_.assign(size_t(count), kPending);
    int pending = count;
    for (int up = 1; up <= int(levels_.size()) && pending > 0; ++up) {
        Level& L = levels_[size_t(up - 1)];
        if (!L.stored) continue;
        const uint64_t mask = (uint64_t{1} << up) - 1, J = gj >> up;
        if (J == 0) break;                           // the stencil would leave the domain: every point left is refused
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

// Column i of the current texel row (samples rowJ - 1 .. rowJ + 2, those of non-zero weight), cached.
const PyramidInterpolator::Column& PyramidInterpolator::column(Level& L, uint64_t i, const std::array<double, 4>& wy) {
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
bool PyramidInterpolator::fineCellNear(Level& L, int64_t x0, int64_t x1) {
    if (L.finer.empty()) return false;  // level 0: no cell is finer
    const int64_t y0 = 2 * (int64_t(L.rowJ) - 1 - L.reach) - 1, y1 = 2 * (int64_t(L.rowJ) + 2 + L.reach);
    const int shift = L.finerShift;
    x0 = std::max<int64_t>(x0 - 1, 0);
    for (int64_t tx = x0 >> shift; tx <= x1 >> shift; ++tx) {
        Level::RowMask& m = L.rowMask[size_t(tx) & (kRowMasks - 1)];
        if (m.tx != tx || m.rowJ != L.rowJ) {
            m = {tx, L.rowJ, 0};
            for (int64_t ty = std::max<int64_t>(y0, 0) >> shift; ty <= y1 >> shift; ++ty) {
                if (!L.finer[size_t(tx & 1) | size_t(ty & 1) << 1].find(uint64_t(tx) << shift, uint64_t(ty) << shift))
                    continue;
                const std::array<uint16_t, 16>& rows = tileCells(L, tx, ty);
                for (int64_t y = std::max(y0, ty << shift); y <= std::min(y1, ((ty + 1) << shift) - 1); ++y)
                    m.bits |= rows[size_t(y - (ty << shift))];
            }
        }
        const int64_t lo = std::max(x0, tx << shift) - (tx << shift),
                      hi = std::min(x1, ((tx + 1) << shift) - 1) - (tx << shift);
        if ((m.bits >> lo) & ((uint32_t{1} << (hi - lo + 1)) - 1)) return true;
    }
    return false;
}

// The fine cells of stored tile (tx, ty) of the level below L's (Level::fineCells), from the grid's codes.
const std::array<uint16_t, 16>& PyramidInterpolator::tileCells(Level& L, int64_t tx, int64_t ty) {
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

uint64_t interpolateBlock(const Scene& scene, const Cascade& c, const PyramidTiles& tiles,
                          const PyramidTiles::Block& block, double waterMinDepthM, CascadeTextures& tex,
                          std::vector<RowFill>& rows) {
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

}  // namespace hc::render::detail
