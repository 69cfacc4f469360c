// influence/src/pyramid.cpp: building the surface pyramid (pyramid.h) and looking samples up.
//
// Per block of 4 x 4 samples of a tile: the cells whose kernels reach the block are gathered (one range query
// per level, list_index.h), and every sample sums them in double, relative to one cell value of the block
// (as the exact evaluator sums relative to the containing cell's, surface.cpp), so a constant field stays
// exactly constant and centimetre relief at 8000 m keeps its digits.
#include "heightcast/influence/pyramid.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iterator>
#include <limits>

#include "heightcast/core/error.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/progress.h"
#include "heightcast/influence/surface.h"
#include "kernel_sums.h"
#include "list_index.h"
#include "pyramid_build.h"
#include "pyramid_storage.h"

namespace hc::influence {

long SurfacePyramid::Level::findTile(uint64_t key) const {
    const auto it = std::lower_bound(keys.begin(), keys.end(), key);
    return it != keys.end() && *it == key ? long(it - keys.begin()) : -1;
}

long SurfacePyramid::tileAt(int t, uint64_t i, uint64_t j) const {
    if (t < 0 || t > topLevel()) return -1;
    const Level& L = levels[size_t(t)];
    const uint64_t side = uint64_t(L.tileSide), perSide = uint64_t{1} << (rootLevel - t);
    if (i >= perSide || j >= perSide) return -1;
    const uint64_t key = mortonEncode(uint32_t((i / side * side) << t), uint32_t((j / side * side) << t));
    return L.findTile(key);
}

int SurfacePyramid::channelIndex(PyramidChannel c) const {
    const int k = int(c);
    if (channels == 2) return c == PyramidChannel::Elevation ? -1 : k - 1;
    return k < channels ? k : -1;
}

std::optional<float> SurfacePyramid::sample(int t, uint64_t i, uint64_t j, PyramidChannel c) const {
    const long tile = tileAt(t, i, j);
    const int k = channelIndex(c);
    if (tile < 0 || k < 0) return std::nullopt;
    const Level& L = levels[size_t(t)];
    const size_t side = size_t(L.tileSide);
    return L.samples[(size_t(tile) * size_t(channels) + size_t(k)) * side * side + (j % side) * side + (i % side)];
}

SurfacePyramid::Cursor::Cursor(const SurfacePyramid& p, int t)
    : p_(p), t_(t), side_(size_t(p.levels[size_t(t)].tileSide)), shift_(std::countr_zero(side_)) {
    if (!std::has_single_bit(side_))
        throw Error("surface pyramid: a tile side of " + std::to_string(side_) + " samples is not a power of two");
}

void SurfacePyramid::Cursor::seek(uint64_t i, uint64_t j) {
    const bool first = tileI_ == ~uint64_t{0};
    tileI_ = i >> shift_, tileJ_ = j >> shift_;
    if (!first && table_.empty()) table_.resize(kRemembered);
    Remembered* slot =
        table_.empty() ? nullptr : &table_[(tileI_ & (kRemembered / 2 - 1)) | (tileJ_ & 1) * (kRemembered / 2)];
    if (slot && slot->tileI == tileI_ && slot->tileJ == tileJ_) {
        tile_ = slot->tile;
        return;
    }
    const long tile = p_.tileAt(t_, i, j);
    tile_ = tile < 0 ? nullptr : &p_.levels[size_t(t_)].samples[size_t(tile) * size_t(p_.channels) * plane()];
    if (slot) *slot = {tileI_, tileJ_, tile_};
}

uint64_t SurfacePyramid::sampleCount() const {
    uint64_t n = 0;
    for (const Level& L : levels) n += L.samples.size();
    return n;
}

uint64_t SurfacePyramid::bytes() const {
    uint64_t n = 0;
    for (const Level& L : levels) n += L.keys.size_bytes() + L.parentErrorM.size_bytes() + L.samples.size_bytes();
    return n;
}

std::string defaultPyramidPath(const std::string& gridPath, size_t step, size_t stepCount) {
    std::filesystem::path p(gridPath);
    if (stepCount > 1) {
        char tail[32];
        std::snprintf(tail, sizeof tail, ".step%04zu.hcp", step);
        p.replace_extension(tail);
    } else {
        p.replace_extension(".hcp");
    }
    return p.string();
}

namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// Whether the node (corner key, level) meets a cell of g: holds one, or lies in a coarser one (as
// GridRegionReader::cellsInNode counts them in a file).
bool nodeMeetsCells(const Grid& g, uint64_t key, int level) {
    const auto lo = std::lower_bound(g.codes.begin(), g.codes.end(), makeCellCode(key, 0));
    if (lo != g.codes.end() && codeKey(*lo) < key + mortonSpan(level)) return true;
    if (lo == g.codes.begin()) return false;
    const uint64_t before = *(lo - 1);
    return codeKey(before) + mortonSpan(std::min(codeLevel(before), g.rootLevel)) > key;
}

// The tiles of each level (pyramid.h's rule: tileKeysOfCells over every cell, less those whose node meets no cell:
// all their samples would be NaN), ascending.
std::vector<std::vector<uint64_t>> tileKeys(const Grid& g, const KernelParams& params, int top,
                                            const std::vector<int>& sides) {
    std::vector<std::vector<uint64_t>> keys(size_t(top) + 1);
    detail::tileKeysOfCells(g, params, 0, g.cellCount(), 0, top, top, sides, keys);
    for (int t = 0; t <= top; ++t) {
        std::vector<uint64_t>& k = keys[size_t(t)];
        std::sort(k.begin(), k.end());
        k.erase(std::unique(k.begin(), k.end()), k.end());
        const int nodeLevel = t + std::countr_zero(unsigned(sides[size_t(t)]));
        std::erase_if(k, [&](uint64_t key) { return !nodeMeetsCells(g, key, nodeLevel); });
    }
    return keys;
}

}  // namespace

namespace detail {

void tileKeysOfCells(const Grid& g, const KernelParams& params, size_t lo, size_t hi, int t0, int t1, int top,
                     const std::vector<int>& sides, std::vector<std::vector<uint64_t>>& out) {
    // Per level: a tile's side in finest cells, tiles per side of the domain, a tile's side in metres, the top's key
    // mask, and the last reach box added (neighbours in Morton order mostly share it).
    struct Level {
        uint64_t span = 0, topMask = 0;
        long perSide = 0;
        double tileM = 0;
        long last[4] = {-1, -1, -1, -1};
    };
    std::vector<Level> levels(size_t(t1 - t0 + 1));
    for (int t = t0; t <= t1; ++t) {
        Level& L = levels[size_t(t - t0)];
        L.span = uint64_t(sides[size_t(t)]) << t;
        L.perSide = long(((uint64_t{1} << g.rootLevel) + L.span - 1) / L.span);
        L.tileM = g.finestCellM * double(L.span);
        L.topMask = ~(mortonSpan(t + std::countr_zero(unsigned(sides[size_t(t)]))) - 1);
    }
    for (size_t i = lo; i < hi; ++i) {
        const int level = codeLevel(g.codes[i]);
        const int from = std::max(t0, std::min(level, top));  // the top holds every cell
        if (from > t1) continue;
        double cx = 0, cy = 0;
        const double r = params.radiusM(g.cellSizeM(i));
        if (from < top) g.cellCenterLocal(i, cx, cy);
        for (int t = from; t <= t1; ++t) {
            Level& L = levels[size_t(t - t0)];
            std::vector<uint64_t>& keys = out[size_t(t)];
            if (t >= top) {  // the top: the tiles holding any cell
                const uint64_t key = codeKey(g.codes[i]) & L.topMask;
                if (keys.empty() || keys.back() != key) keys.push_back(key);
                continue;
            }
            // Below it: the tiles that the kernel reach box of a cell of level <= t meets (its own tile among them).
            const long tx0 = std::max(0L, long(std::floor((cx - r) / L.tileM))),
                       tx1 = std::min(L.perSide - 1, long(std::floor((cx + r) / L.tileM)));
            const long ty0 = std::max(0L, long(std::floor((cy - r) / L.tileM))),
                       ty1 = std::min(L.perSide - 1, long(std::floor((cy + r) / L.tileM)));
            if (tx0 == L.last[0] && tx1 == L.last[1] && ty0 == L.last[2] && ty1 == L.last[3]) continue;
            L.last[0] = tx0, L.last[1] = tx1, L.last[2] = ty0, L.last[3] = ty1;
            for (long ty = ty0; ty <= ty1; ++ty)
                for (long tx = tx0; tx <= tx1; ++tx)
                    keys.push_back(mortonEncode(uint32_t(uint64_t(tx) * L.span), uint32_t(uint64_t(ty) * L.span)));
        }
    }
}

// tileKeysOfCells for levels [t0, t1] over cells [lo, hi), the cells split among `threads` workers and their
// keys appended in turn (a repeat at a seam is harmless: the keys are sorted and made unique after).
void tileKeysOnThreads(const Grid& g, const KernelParams& params, size_t lo, size_t hi, int t0, int t1, int top,
                       const std::vector<int>& sides, unsigned threads, std::vector<std::vector<uint64_t>>& out) {
    if (t0 > t1 || lo >= hi) return;
    const size_t parts = threads > 1 && hi - lo >= 65536 ? threads : 1;
    std::vector<std::vector<std::vector<uint64_t>>> partKeys(parts, std::vector<std::vector<uint64_t>>(out.size()));
    parallelFor(parts, 1, threads, [&](size_t b, size_t e, unsigned) {
        for (size_t p = b; p < e; ++p)
            detail::tileKeysOfCells(g, params, lo + (hi - lo) * p / parts, lo + (hi - lo) * (p + 1) / parts, t0, t1,
                                    top, sides, partKeys[p]);
    });
    for (const auto& part : partKeys)
        for (size_t t = 0; t < out.size(); ++t) out[t].insert(out[t].end(), part[t].begin(), part[t].end());
}

int pyramidBlockSide(const Grid& shape, const KernelParams& params, int t) {
    return shape.levelSizeM(t) >= params.radiusM(shape.levelSizeM(std::clamp(shape.maxLevel, 0, shape.rootLevel)))
               ? 1
               : kPyramidBlock;
}

namespace {

// The levels 0..kTileGatherTop gather a tile's candidates once (buildTile); coarser tiles span so many cells that a
// gather per block costs less than narrowing the tile's (docs/benchmarks.md, issue 42).
constexpr int kTileGatherTop = 1;

// One tile being sampled: where its samples lie and go.
struct TileFrame {
    const Grid& g;
    double x0, y0, h;     // the tile's first sample and the spacing [m]
    double tail, halfR2;  // the kernel's (KernelParams::tail, R^2 / 2)
    const float* z;       // elevation
    const float* depth;   // water depth, or null
    int side, channels;   // samples a side; planes
    float* out;           // channels planes of side^2 samples
};

// Samples [bi, bi1) x [bj, bj1) of the tile from `c`, the cells whose kernels reach the block; g0: working memory.
void sampleBlock(const TileFrame& f, const Candidates& c, Gathered& g0, int bi, int bi1, int bj, int bj1) {
    const size_t m = c.index.size(), plane = size_t(f.side) * size_t(f.side);
    // Relative to one cell's value per block, and to one wet cell's level (as surface.cpp does per point: any value of
    // the neighbourhood keeps the digits; a constant field stays exactly constant).
    const double base = m ? double(f.z[c.index[0]]) : kNaN;
    double baseLevel = kNaN;
    for (size_t k = 0; k < m && f.depth && std::isnan(baseLevel); ++k)
        if (const uint32_t i = c.index[k]; f.depth[i] > 0) baseLevel = double(f.z[i]) + double(f.depth[i]);
    g0.reset(m);
    for (size_t k = 0; k < m; ++k) {
        const uint32_t i = c.index[k];
        g0.ex[k] = c.cx[k], g0.ey[k] = c.cy[k], g0.r2[k] = c.r2[k];
        g0.a[k] = f.halfR2 / c.r2[k];  // 1 / (2 sigma^2 c^2), as r2 = (R sigma c)^2
        g0.rel0[k] = double(f.z[i]) - base;
        if (f.depth && f.depth[i] > 0) {
            g0.wet[k] = 1.0;
            g0.rel1[k] = double(f.z[i]) + double(f.depth[i]) - baseLevel;
        }
    }
    for (int j = bj; j < bj1; ++j)
        for (int i = bi; i < bi1; ++i) {
            const double px = f.x0 + i * f.h, py = f.y0 + j * f.h;
            const size_t at = size_t(j) * size_t(f.side) + size_t(i);
            if (!f.g.locate(px, py)) {
                for (int k = 0; k < f.channels; ++k) f.out[size_t(k) * plane + at] = kNaN;
                continue;
            }
            const KernelSums sum = sumKernels(g0, px, py, f.tail);
            // den >= the containing cell's own weight there (kernel.h): never zero.
            f.out[at] = float(base + sum.num0 / sum.den);
            if (f.channels == 3) {
                f.out[plane + at] = sum.denWet > 0 ? float(baseLevel + sum.num1 / sum.denWet) : kNaN;
                f.out[2 * plane + at] = float(sum.denWet / sum.den);
            }
        }
}

}  // namespace

void buildTile(const Grid& g, const ListIndex& index, const KernelParams& params, int t, int side, uint64_t key,
               int channels, int depthLayer, float* out, PyramidWorkspace& w, int onlyBlock) {
    const int block = pyramidBlockSide(g, params, t);
    const double h = g.levelSizeM(t);
    const double x0 = double(mortonX(key)) * g.finestCellM, y0 = double(mortonY(key)) * g.finestCellM;
    const TileFrame frame{g,
                          x0,
                          y0,
                          h,
                          params.tail(),
                          0.5 * params.truncation * params.truncation,
                          g.values[0].data(),
                          depthLayer >= 0 ? g.values[size_t(depthLayer)].data() : nullptr,
                          side,
                          channels,
                          out};
    const int blocksPerSide = (side + block - 1) / block;
    // A tile of several blocks on the finest levels gathers its candidates once, over the whole tile, and narrows them
    // to each row of blocks and then to each block by the test the gather ends with (kernelReaches): the same
    // candidates in the same order as a gather per block, for one walk of the levels' quadtrees a tile instead of one a
    // block, and each block testing its row's few candidates, not the tile's many.
    const bool perTile = onlyBlock < 0 && blocksPerSide > 1 && t <= kTileGatherTop;
    if (perTile) index.candidatesFor(Grid::Square{x0, y0, x0 + (side - 1) * h, y0 + (side - 1) * h}, w.tile);
    for (int bj = 0; bj < side; bj += block) {
        const int bj1 = std::min(side, bj + block);
        if (perTile)
            narrowCandidates(w.tile, Grid::Square{x0, y0 + bj * h, x0 + (side - 1) * h, y0 + (bj1 - 1) * h}, w.row,
                             w.row.keep);
        for (int bi = 0; bi < side; bi += block) {
            if (onlyBlock >= 0 && onlyBlock != (bj / block) * blocksPerSide + bi / block) continue;
            const int bi1 = std::min(side, bi + block);
            const Grid::Square box{x0 + bi * h, y0 + bj * h, x0 + (bi1 - 1) * h, y0 + (bj1 - 1) * h};
            if (perTile)
                narrowCandidates(w.row, box, w.wide, w.wide.keep);
            else
                index.candidatesFor(box, w.wide);
            sampleBlock(frame, w.wide, w.block, bi, bi1, bj, bj1);
        }
    }
}

// parentErrorM of every tile below the top (pyramid.h); a parent sample p lacks is looked for in `halo` (its tiles have
// p's sides and channels), if given.
void measureParentErrorsInto(const SurfacePyramid& p, std::vector<std::vector<float>>& errors, unsigned threads,
                             const SurfacePyramid* halo) {
    for (int t = 0; t < p.topLevel(); ++t) {
        const SurfacePyramid::Level& L = p.levels[size_t(t)];
        const size_t side = size_t(L.tileSide), plane = side * side;
        parallelFor(L.tileCount(), 16, threads, [&](size_t b, size_t e, unsigned) {
            SurfacePyramid::Cursor parent(
                p, t + 1);  // a tile's parent samples lie in one parent tile (the far edges: its neighbours)
            std::optional<SurfacePyramid::Cursor> beside;
            if (halo) beside.emplace(*halo, t + 1);
            for (size_t tile = b; tile < e; ++tile) {
                const uint64_t i0 = mortonX(L.keys[tile]) >> t, j0 = mortonY(L.keys[tile]) >> t;
                for (int c = 0; c < p.channels; ++c) {
                    const size_t channel = size_t(c) * parent.plane();
                    float worst = 0;
                    const float* s = &L.samples[(tile * size_t(p.channels) + size_t(c)) * plane];
                    for (size_t j = 0; j < side; ++j)
                        for (size_t i = 0; i < side; ++i) {
                            const uint64_t gi = i0 + i, gj = j0 + j;
                            // Parent lattice: (gi / 2, gj / 2), half-way where odd.
                            const uint64_t pi = gi / 2, pj = gj / 2;
                            const uint64_t pi1 = pi + (gi & 1), pj1 = pj + (gj & 1);
                            const float v = s[j * side + i];
                            if (std::isnan(v)) continue;
                            double interp = 0;
                            bool held = true;
                            for (const auto& [qi, qj] : {std::pair{pi, pj}, {pi1, pj}, {pi, pj1}, {pi1, pj1}}) {
                                const float* q = parent.find(qi, qj);
                                if (!q && beside) q = beside->find(qi, qj);
                                held = held && q;
                                if (q) interp += 0.25 * double(q[channel]);
                            }
                            if (!held || std::isnan(interp)) continue;
                            worst = std::max(worst, float(std::abs(double(v) - interp)));
                        }
                    errors[size_t(t)][tile * size_t(p.channels) + size_t(c)] = worst;
                }
            }
        });
    }
}

void wetMarkedTiles(const Grid& g, const KernelParams& params, int depthLayer, size_t lo, size_t hi, int t, int side,
                    std::vector<uint64_t>& marked) {
    const float* depth = g.values[size_t(depthLayer)].data();
    const uint64_t span = uint64_t(side) << t;  // a tile's side in finest cells
    const long perSide = long(((uint64_t{1} << g.rootLevel) + span - 1) / span);
    const double tileM = g.finestCellM * double(span);
    long last[4] = {-1, -1, -1, -1};
    for (size_t i = lo; i < hi; ++i) {
        if (!(depth[i] > 0)) continue;
        double cx = 0, cy = 0;
        g.cellCenterLocal(i, cx, cy);
        const double r = params.radiusM(g.cellSizeM(i));
        const long tx0 = std::max(0L, long(std::floor((cx - r) / tileM)) - 1),
                   tx1 = std::min(perSide - 1, long(std::floor((cx + r) / tileM)) + 1);
        const long ty0 = std::max(0L, long(std::floor((cy - r) / tileM)) - 1),
                   ty1 = std::min(perSide - 1, long(std::floor((cy + r) / tileM)) + 1);
        if (tx0 == last[0] && tx1 == last[1] && ty0 == last[2] && ty1 == last[3])
            continue;  // neighbours in Morton order
        last[0] = tx0, last[1] = tx1, last[2] = ty0, last[3] = ty1;
        for (long ty = ty0; ty <= ty1; ++ty)
            for (long tx = tx0; tx <= tx1; ++tx)
                marked.push_back(mortonEncode(uint32_t(uint64_t(tx) * span), uint32_t(uint64_t(ty) * span)));
    }
}

}  // namespace detail

namespace {

// The tiles of `keys` (per level) that a wet cell's kernel reaches, each dilated by one tile: only these can hold a
// sample with any wet weight, so every other tile draws no water; the dilation keeps beside each kept tile the
// parent-level tiles whose samples the parent-error pass (measureParentErrorsInto) reads at its far edges (a kept
// tile's parent is kept: its node holds the child's).
std::vector<std::vector<uint64_t>> wetReachedKeys(const Grid& g, const KernelParams& params,
                                                  const std::vector<std::vector<uint64_t>>& keys,
                                                  const std::vector<int>& sides, int depthLayer) {
    std::vector<std::vector<uint64_t>> out(keys.size());
    for (size_t t = 0; t < keys.size(); ++t) {
        std::vector<uint64_t> marked;
        detail::wetMarkedTiles(g, params, depthLayer, 0, g.cellCount(), int(t), sides[t], marked);
        std::sort(marked.begin(), marked.end());
        marked.erase(std::unique(marked.begin(), marked.end()), marked.end());
        std::set_intersection(keys[t].begin(), keys[t].end(), marked.begin(), marked.end(), std::back_inserter(out[t]));
    }
    return out;
}

}  // namespace

namespace detail {

bool waterDrawnIn(const float* tile, size_t plane) {
    const float *z = tile, *level = tile + plane, *share = tile + 2 * plane;
    for (size_t s = 0; s < plane; ++s)
        if (double(share[s]) >= kWetShareMin && level[s] > z[s]) return true;  // NaN compares false
    return false;
}

std::vector<int> pyramidTileSides(const Grid& shape) {
    const int top = std::max(0, shape.rootLevel - kPyramidTileLog2);
    std::vector<int> sides(size_t(top) + 1);
    for (int t = 0; t <= top; ++t) sides[size_t(t)] = std::min(kPyramidTileSide, 1 << (shape.rootLevel - t));
    return sides;
}

SurfacePyramid finishPyramid(SurfacePyramid p, std::shared_ptr<SurfacePyramid::Storage> owned,
                             const std::vector<int>& sides, unsigned threads, const SurfacePyramid* halo) {
    const size_t levels = sides.size();
    owned->errors.resize(levels);
    p.levels.resize(levels);
    for (size_t t = 0; t < levels; ++t) {
        owned->errors[t].assign(owned->keys[t].size() * size_t(p.channels), 0.0f);
        SurfacePyramid::Level& L = p.levels[t];
        L.level = int(t);
        L.tileSide = sides[t];
        L.keys = owned->keys[t];
        L.samples = owned->samples[t];
        L.parentErrorM = owned->errors[t];
    }
    measureParentErrorsInto(p, owned->errors, resolveThreads(threads), halo);
    p.storage = std::move(owned);
    return p;
}

}  // namespace detail

namespace {

// The tiles of every level of `g` (tileKeys), or only those a wet cell's kernel reaches (wetReachedKeys), sampled.
SurfacePyramid buildPyramid(const Grid& g, const KernelParams& params, unsigned threads, bool progress,
                            bool wetReachedOnly) {
    if (std::string why = params.validate(); !why.empty()) throw Error("influence parameters: " + why);
    if (g.cellCount() >= std::numeric_limits<uint32_t>::max())
        throw Error("grid has too many cells for 32-bit cell indices");
    threads = resolveThreads(threads);
    SurfacePyramid p;
    p.finestCellM = g.finestCellM;
    p.rootLevel = g.rootLevel;
    p.params = params;
    p.structureHash = g.structureHash();
    p.contentHash = g.contentHash();
    const int depthLayer = g.findLayer("water_depth");
    p.channels = depthLayer >= 0 ? 3 : 1;
    const std::vector<int> sides = detail::pyramidTileSides(g);
    const int top = int(sides.size()) - 1;

    auto owned = std::make_shared<SurfacePyramid::Storage>();
    owned->keys = g.cellCount() ? tileKeys(g, params, top, sides) : std::vector<std::vector<uint64_t>>(size_t(top) + 1);
    if (wetReachedOnly) owned->keys = wetReachedKeys(g, params, owned->keys, sides, depthLayer);
    uint64_t tiles = 0;
    for (const auto& k : owned->keys) tiles += k.size();
    owned->samples.resize(size_t(top) + 1);

    const detail::ListIndex index(g, params);
    std::vector<detail::PyramidWorkspace> scratch(threads);
    Progress bar("surface pyramid", tiles, progress);
    for (int t = top; t >= 0; --t) {
        const auto& keys = owned->keys[size_t(t)];
        const size_t plane = size_t(sides[size_t(t)]) * size_t(sides[size_t(t)]);
        auto& samples = owned->samples[size_t(t)];
        samples.resize(keys.size() * size_t(p.channels) * plane);
        parallelFor(keys.size(), 8, threads, [&](size_t b, size_t e, unsigned worker) {
            for (size_t tile = b; tile < e; ++tile)
                detail::buildTile(g, index, params, t, sides[size_t(t)], keys[tile], p.channels, depthLayer,
                                  &samples[tile * size_t(p.channels) * plane], scratch[worker], -1);
            bar.advance(e - b);
        });
    }
    bar.finish();
    return detail::finishPyramid(std::move(p), std::move(owned), sides, threads);
}

}  // namespace

SurfacePyramid buildSurfacePyramid(const Grid& g, const KernelParams& params, unsigned threads, bool progress) {
    return buildPyramid(g, params, threads, progress, false);
}

SurfacePyramid buildWaterPyramid(const Grid& g, const KernelParams& params, unsigned threads, bool progress) {
    if (g.findLayer("water_depth") < 0) throw Error("a water pyramid is built for a grid with water");
    return waterPyramidOf(buildPyramid(g, params, threads, progress, true));
}

SurfacePyramid waterPyramidOf(const SurfacePyramid& whole) {
    if (whole.channels != 3) throw Error("a water pyramid is made from a pyramid with water channels");
    SurfacePyramid p = whole;
    p.channels = 2;
    auto owned = std::make_shared<SurfacePyramid::Storage>();
    owned->keys.resize(whole.levels.size());
    owned->samples.resize(whole.levels.size());
    owned->errors.resize(whole.levels.size());
    for (size_t t = 0; t < whole.levels.size(); ++t) {
        const SurfacePyramid::Level& L = whole.levels[t];
        const size_t plane = size_t(L.tileSide) * size_t(L.tileSide);
        for (size_t tile = 0; tile < L.tileCount(); ++tile) {
            const float* z = L.samples.data() + tile * 3 * plane;
            const float* level = z + plane;
            if (!detail::waterDrawnIn(z, plane)) continue;
            owned->keys[t].push_back(L.keys[tile]);
            owned->samples[t].insert(owned->samples[t].end(), level, level + 2 * plane);
            const float* errors =
                L.parentErrorM.data() + tile * 3;  // pointers: [tile * 3 + 3] is one past the last tile's
            owned->errors[t].insert(owned->errors[t].end(), errors + 1, errors + 3);
        }
        p.levels[t].keys = owned->keys[t];
        p.levels[t].samples = owned->samples[t];
        p.levels[t].parentErrorM = owned->errors[t];
    }
    p.storage = std::move(owned);
    return p;
}

}  // namespace hc::influence
