// Texels copied from the surface pyramid into a cascade's textures: copySamples() (a row of samples, both backends),
// and copyPyramidTexels() (approximate_internal.h), the approximation pass's first source of texels after the last
// frame's, which hands texels finer than every stored level to PyramidInterpolator (approximate_interpolate.cpp).
#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstring>
#include <memory>
#include <optional>

#include "approximate_internal.h"
#include "heightcast/core/parallel.h"

namespace hc::render::detail {

int copySamples(const float* s, const float* w, size_t plane, int count, float minDepth, float* h, float* depth,
                float* water) {
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
    for (int k = 0; k < count; ++k) {  // the water rule, water_rule.h
        const float z = s[k], level = w[k], d = level - z;
        const bool ok = !std::isnan(z), wet = ok && !std::isnan(level) && water::wetShare(share[k]);
        hr[k] = ok ? z : hr[k];
        dr[k] = wet && water::holdsDepth(d) ? d : dr[k];
        wr[k] = wet && water::drawsWater(d, minDepth) ? level : wr[k];
        defined += ok;
    }
    return defined;
}

namespace {

// Level 0's tiles as PyramidTiles::Block wants them: whether the 3 x 3 tiles around tile (tx, ty) are all stored, all
// numbers and all dry or all wet (then PyramidInterpolator interpolates every texel of the block from level 0 and
// refuses none: no sample is undefined or missing, no wet meets dry, the stencil stays in the domain), and those tiles.
// One per worker: each tile's kind is kept in a small table by its address.
class LevelZeroBlocks {
public:
    LevelZeroBlocks(const influence::SurfacePyramid& p, const influence::SurfacePyramid* water)
        : samples_(p, 0),
          channels3_(p.channels == 3),
          plane_(samples_.plane()),
          shift_(std::countr_zero(samples_.side())) {
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
                if (b)
                    b->tile[size_t(3 * (dy + 1) + dx + 1)] = s, b->water[size_t(3 * (dy + 1) + dx + 1)] =
                                                                    k == kWet ? w : nullptr;
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

// copyPyramidTexels() in stages: the pyramid level that fits the cascade (fitLevel), the tables of the tiles and of the
// blocks left to the caller (setUpTiles, setUpBlocks), the rows on the workers (copyRows: each span run by run, a run
// being the texels in one tile or block: copied, or over an empty tile, or a caller's block, or interpolated), then
// the totals and the caller's blocks (finish).
class PyramidCopier {
public:
    PyramidCopier(const PyramidCopy& in, ApproximationWork& work) : in_(in), work_(work) {}

    uint64_t run() {
        work_.pyramidLevel = -1;
        if (!fitLevel()) return 0;
        if (t_ >= 0) work_.pyramidLevel = int(t_);
        setUp();
        if (in_.tiles) setUpTiles();
        setUpBlocks();
        parallelFor(in_.todo.size(), 16, in_.threads,
                    [&](size_t b, size_t e, unsigned worker) { copyRows(b, e, worker); });
        return finish();
    }

private:
    // One worker's state over its rows: the cursors neighbouring rows share (they share tiles), its interpolator and
    // table of empty tiles (one per worker for the whole cascade, made when first wanted: the fine cells it looked up
    // serve its later rows), and its counts (added once: per-worker counters share a cache line).
    struct Worker {
        Worker(std::unique_ptr<PyramidInterpolator>& i, std::unique_ptr<EmptyTiles>& e) : interpolator(i), empty(e) {}
        std::unique_ptr<PyramidInterpolator>& interpolator;
        std::unique_ptr<EmptyTiles>& empty;
        std::optional<influence::SurfacePyramid::Cursor> samples, waterSamples;
        LevelZeroBlocks* blocks = nullptr;
        size_t plane = 0;
        uint64_t nCopied = 0, nInterpolated = 0;
        int up = 0;
        uint64_t sideMask = 0;
        int tileShift = 0;
        std::vector<PyramidInterpolator::Value> values;  // a run's interpolated texels
        std::vector<uint8_t> filled;
    };
    // The texels of a span left to the kernels: from the first to the last of them.
    struct LeftToKernels {
        int first, last;
        void leave(int i) { first = std::min(first, i), last = i; }
    };
    // The blocks' table (setUpBlocks): 0 not yet asked, 1 the caller's (its tiles in blockTiles_), 2 not, 3 being
    // asked.
    enum : uint8_t { kUnasked, kCallers, kNotCallers, kAsking };

    // The pyramid level t whose spacing is the cascade's texel size; false where none fits.
    bool fitLevel() {
        const Cascade& c = in_.c;
        p_ = in_.scene.pyramid();
        if (!p_) return false;
        const double t = std::round(std::log2(c.texelM / p_->finestCellM));
        if (t > p_->topLevel() || std::abs(std::ldexp(p_->finestCellM, int(t)) - c.texelM) > 1e-9 * c.texelM)
            return false;
        // Texels finer than the finest cells (t < 0, on the same ladder) have no level to copy from, but may
        // interpolate level 0 if it lies within interpolateLevels.
        if (t < 0 && -t > in_.interpolateLevels) return false;
        t_ = t;
        return true;
    }

    // The cascade's place on level t's lattice, and the workers' tables.
    void setUp() {
        const Cascade& c = in_.c;
        channels_ = size_t(p_->channels);
        // A later step of a scenario: the base's elevation, the step's water pyramid's water (pyramid.h); where the
        // water pyramid holds no tile the step draws no water.
        wp_ = in_.scene.waterPyramid();
        i0_ = std::round(c.x0 / c.texelM), j0_ = std::round(c.y0 / c.texelM);
        minDepth_ = float(in_.waterMinDepthM);
        const unsigned workers = resolveThreads(in_.threads);
        copied_.assign(workers, 0), interpolated_.assign(workers, 0);
        mostUp_.assign(workers, 0);
        // Each on its own allocation: side by side in one vector, one worker's writes (out of core, its codes_) would
        // evict the other's reads of the same cache line.
        interpolators_.resize(workers);
        emptyTiles_.resize(workers);
        zeroBlocks_.resize(workers);  // per worker: tile kinds kept across its rows
        I0_ = int64_t(i0_), J0_ = int64_t(j0_);
    }

    // With `tiles`: the table over the tiles of level t that the cascade's texels cover (those at lattice points >= 0).
    void setUpTiles() {
        const Cascade& c = in_.c;
        PyramidTiles* const tiles = in_.tiles;
        *tiles = PyramidTiles{};
        const std::vector<Todo>& todo = in_.todo;
        for (size_t j = 0; j < todo.size(); ++j) tiles->spans.push_back({{}, todo[j].a, todo[j].b});
        if (t_ >= 0 && I0_ + c.n > 0 && J0_ + c.n > 0) {
            const influence::SurfacePyramid::Cursor probe(*p_, int(t_));
            const int shift = std::countr_zero(probe.side());
            tiles->side = int(probe.side()), tiles->plane = probe.plane();
            tx0_ = std::max<int64_t>(I0_, 0) >> shift, ty0_ = std::max<int64_t>(J0_, 0) >> shift;
            tiles->originI = I0_ - (tx0_ << shift), tiles->originJ = J0_ - (ty0_ << shift);
            tiles->width = int(((I0_ + c.n - 1) >> shift) - tx0_ + 1);
            tiles->height = int(((J0_ + c.n - 1) >> shift) - ty0_ + 1);
            const size_t entries = size_t(tiles->width) * size_t(tiles->height);
            tiles->tile.assign(entries, nullptr), tiles->water.assign(entries, nullptr);
            tiles->copied.assign(entries * size_t(tiles->side), 0);
        }
    }

    // With `tiles` and a cascade below level 0: the blocks left to the caller (PyramidTiles::Block), a table over those
    // the cascade's texels cover.
    void setUpBlocks() {
        const Cascade& c = in_.c;
        PyramidTiles* const tiles = in_.tiles;
        if (tiles && t_ < 0 && -t_ <= PyramidTiles::kMaxBlockUp && I0_ + c.n > 0 && J0_ + c.n > 0) {
            const influence::SurfacePyramid::Cursor level0(*p_, 0);
            if (level0.side() >= 2) {  // a stencil reaches one sample beyond its block: into the next tile only
                tiles->up = int(-t_), tiles->levelSide = int(level0.side()), tiles->levelPlane = level0.plane();
                blockShift_ = std::countr_zero(level0.side()) + tiles->up;
                bx0_ = std::max<int64_t>(I0_, 0) >> blockShift_, by0_ = std::max<int64_t>(J0_, 0) >> blockShift_;
                blocksWide_ = ((I0_ + c.n - 1) >> blockShift_) - bx0_ + 1;
                blockState_.assign(size_t(blocksWide_) * size_t(((J0_ + c.n - 1) >> blockShift_) - by0_ + 1), kUnasked);
                blockTiles_.resize(blockState_.size());
            }
        }
        blockMask_ = (uint64_t{1} << blockShift_) - 1;
    }

    // Rows b .. e - 1 on one worker.
    void copyRows(size_t b, size_t e, unsigned worker) {
        Worker wk(interpolators_[worker], emptyTiles_[worker]);
        std::unique_ptr<LevelZeroBlocks>& blocks = zeroBlocks_[worker];
        if (blockShift_ && !blocks) blocks = std::make_unique<LevelZeroBlocks>(*p_, wp_);
        wk.blocks = blocks.get();
        if (t_ >= 0) wk.samples.emplace(*p_, int(t_));
        if (wp_ && t_ >= 0) wk.waterSamples.emplace(*wp_, int(t_));
        if (in_.scene.outOfCore() && t_ >= 0 && !wk.empty)
            wk.empty = std::make_unique<EmptyTiles>(*in_.scene.file(), int(t_));
        wk.plane = wk.samples ? wk.samples->plane() : 0;
        wk.sideMask = wk.samples ? wk.samples->side() - 1 : 0;
        wk.tileShift = std::countr_zero(wk.sideMask + 1);
        for (size_t j = b; j < e; ++j)
            for (int span = 0; span < 2; ++span) copySpan(wk, j, span);
        copied_[worker] += wk.nCopied, interpolated_[worker] += wk.nInterpolated;
        mostUp_[worker] = std::max(mostUp_[worker], wk.up);
    }

    // Span `span` (0: a, 1: b) of row j, run by run; the span shrinks to the texels left to the kernels.
    void copySpan(Worker& wk, size_t j, int span) {
        Todo& todoRow = in_.todo[j];
        const double gj = j0_ + double(j);
        const size_t rowAt = j * size_t(in_.c.n);
        int* const lo = &todoRow.span(span).first;
        int* const hi = &todoRow.span(span).last;
        LeftToKernels left{*hi + 1, *lo - 1};
        for (int i = *lo; i <= *hi;) {
            const double gi = i0_ + double(i);
            if (gi < 0 || gj < 0) {  // outside the domain's lattice
                left.leave(i++);
                continue;
            }
            // The run of texels in one tile of the cascade's level, or in one block (else to the span's end).
            const int end = wk.samples    ? std::min(*hi, i + int(wk.sideMask - (uint64_t(gi) & wk.sideMask)))
                            : blockShift_ ? std::min(*hi, i + int(blockMask_ - (uint64_t(gi) & blockMask_)))
                                          : *hi;
            const float* s = wk.samples ? wk.samples->find(uint64_t(gi), uint64_t(gj)) : nullptr;
            if (s)
                copyRun(wk, s, gi, gj, rowAt + size_t(i), end - i + 1);
            else
                fillRun(wk, gi, gj, rowAt, i, end, left);
            i = end + 1;
        }
        *lo = left.first, *hi = left.last;
    }

    // Copies: the tile's samples side by side (s the first, at texel `at`), with the water rule of surface.h.
    void copyRun(Worker& wk, const float* s, double gi, double gj, size_t at, int len) {
        CascadeTextures& tex = in_.tex;
        PyramidTiles* const tiles = in_.tiles;
        const float* w = wp_              ? wk.waterSamples->find(uint64_t(gi), uint64_t(gj))
                         : channels_ == 3 ? s + wk.plane
                                          : nullptr;
        std::memset(&in_.copiedMask[at], 1, size_t(len));
        if (tiles) {  // left to the caller, who counts them too (without reading the samples here)
            const int sample = int(s - wk.samples->tile());  // the water tile's layout is the same
            const size_t entry = size_t(int64_t(uint64_t(gi) >> wk.tileShift) - tx0_) +
                                 size_t(int64_t(uint64_t(gj) >> wk.tileShift) - ty0_) * size_t(tiles->width);
            // Workers meet in a tile only at the edges of their rows; the same pointers, bits or'ed.
            std::atomic_ref(tiles->tile[entry]).store(s - sample, std::memory_order_relaxed);
            if (w) std::atomic_ref(tiles->water[entry]).store(w - sample, std::memory_order_relaxed);
            std::atomic_ref(tiles->copied[entry * size_t(tiles->side) + size_t(uint64_t(gj) & wk.sideMask)])
                .fetch_or(uint16_t(((1u << len) - 1) << (uint64_t(gi) & wk.sideMask)), std::memory_order_relaxed);
        } else {
            wk.nCopied += uint64_t(copySamples(s, w, wk.plane, len, minDepth_, &tex.terrain.h[at],
                                               w ? &tex.depth[at] : nullptr, w ? &tex.water.h[at] : nullptr));
        }
    }

    // Texels i .. end (lattice point (gi, gj) the first), finer than the level stored here: interpolated, or left to
    // the kernels; nothing where no cell is.
    void fillRun(Worker& wk, double gi, double gj, size_t rowAt, int i, int end, LeftToKernels& left) {
        const int len = end - i + 1;
        if (wk.empty && (*wk.empty)(uint64_t(gi), uint64_t(gj))) {
            std::memset(&in_.copiedMask[rowAt + size_t(i)], 1, size_t(len));
            return;
        }
        if (blockShift_ && callersBlock(wk, uint64_t(gi), uint64_t(gj))) {  // the caller interpolates them
            std::memset(&in_.copiedMask[rowAt + size_t(i)], 1, size_t(len));
            wk.nInterpolated += uint64_t(len), wk.up = std::max(wk.up, in_.tiles->up);
            return;
        }
        std::unique_ptr<PyramidInterpolator>& interpolator = wk.interpolator;
        if (in_.interpolateLevels > 0 && !interpolator)
            interpolator = std::make_unique<PyramidInterpolator>(in_.scene, *p_, wp_, int(t_), in_.interpolateLevels);
        if (interpolator) {
            wk.values.resize(size_t(len)), wk.filled.resize(size_t(len));
            interpolator->run(uint64_t(i0_ + double(i)), len, uint64_t(gj), wk.values.data(), wk.filled.data());
        }
        for (int k = 0; k < len; ++k, ++i) {
            if (!interpolator || !wk.filled[size_t(k)]) {
                left.leave(i);
                continue;
            }
            const PyramidInterpolator::Value& v = wk.values[size_t(k)];
            const size_t at = rowAt + size_t(i);
            in_.copiedMask[at] = 1;
            if (in_.tiles) left.leave(i);  // written here: the caller packs it with the span
            writeInterpolated(v, at, minDepth_, in_.tex);
            ++wk.nInterpolated;
            wk.up = std::max(wk.up, v.up);
        }
    }

    // Whether the block holding lattice point (gi, gj) is the caller's: asked once, by the worker that claims it
    // (its tiles into blockTiles_); a worker that meets it while another asks finds the same answer itself.
    bool callersBlock(Worker& wk, uint64_t gi, uint64_t gj) {
        // A block is one level-0 tile's texels.
        const int64_t bx = int64_t(gi >> blockShift_), by = int64_t(gj >> blockShift_);
        const size_t entry = size_t(bx - bx0_) + size_t(by - by0_) * size_t(blocksWide_);
        std::atomic_ref state(blockState_[entry]);
        uint8_t now = state.load(std::memory_order_acquire);
        if (now == kUnasked && state.compare_exchange_strong(now, kAsking, std::memory_order_acquire)) {
            now = wk.blocks->take(bx, by, &blockTiles_[entry]) ? kCallers : kNotCallers;
            state.store(now, std::memory_order_release);
        } else if (now == kAsking) {
            now = wk.blocks->take(bx, by) ? kCallers : kNotCallers;
        }
        return now == kCallers;
    }

    // The workers' counts into work_, the caller's blocks with their tiles into `tiles`; returns the texels copied.
    uint64_t finish() {
        uint64_t total = 0;
        for (size_t k = 0; k < copied_.size(); ++k)
            total += copied_[k], work_.pyramidInterpolated += interpolated_[k],
                work_.pyramidInterpolatedUp = std::max(work_.pyramidInterpolatedUp, mostUp_[k]);
        for (size_t e = 0; e < blockState_.size(); ++e) {  // the caller's blocks, with their tiles
            if (blockState_[e] != kCallers) continue;
            const int64_t bx = bx0_ + int64_t(e % size_t(blocksWide_)), by = by0_ + int64_t(e / size_t(blocksWide_));
            PyramidTiles::Block& b = in_.tiles->blocks.emplace_back(blockTiles_[e]);
            b.i0 = (bx << blockShift_) - I0_, b.j0 = (by << blockShift_) - J0_;
        }
        return total;
    }

    const PyramidCopy& in_;
    ApproximationWork& work_;
    const influence::SurfacePyramid* p_ = nullptr;
    const influence::SurfacePyramid* wp_ = nullptr;  // the water pyramid of a later step, or nullptr
    double t_ = 0;                                   // the cascade's pyramid level
    size_t channels_ = 0;
    double i0_ = 0, j0_ = 0;  // the cascade's corner on level t's lattice
    int64_t I0_ = 0, J0_ = 0;
    float minDepth_ = 0;
    std::vector<uint64_t> copied_, interpolated_;  // per worker
    std::vector<int> mostUp_;
    std::vector<std::unique_ptr<PyramidInterpolator>> interpolators_;
    std::vector<std::unique_ptr<EmptyTiles>> emptyTiles_;
    std::vector<std::unique_ptr<LevelZeroBlocks>> zeroBlocks_;
    int64_t tx0_ = 0, ty0_ = 0;  // with `tiles`: the table's first tile
    int blockShift_ = 0;         // with blocks: log2 of a block's side in texels, else 0
    int64_t bx0_ = 0, by0_ = 0, blocksWide_ = 0;
    uint64_t blockMask_ = 0;
    std::vector<uint8_t> blockState_;
    std::vector<PyramidTiles::Block> blockTiles_;
};

}  // namespace

uint64_t copyPyramidTexels(const PyramidCopy& in, ApproximationWork& work) { return PyramidCopier(in, work).run(); }

}  // namespace hc::render::detail
