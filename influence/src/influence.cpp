// Building influence lists. Cells are taken in blocks (quadtree nodes of at most 64 cells); a block
// gathers candidates once, level by level (a level's cells only within that level's radius of the
// block), then every cell of the block keeps the candidates that reach its square. This keeps the
// candidate search to one small range query per block and level, whatever the cell-size ratio.
#include "heightcast/influence/influence.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "heightcast/core/error.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/progress.h"
#include "heightcast/core/sectioned_file.h"

namespace hc::influence {

InfluenceLists::InfluenceLists(KernelParams params, uint64_t structureHash, uint64_t contentHash, std::vector<uint64_t> offsets,
                               std::unique_ptr<uint32_t[]> indices, size_t entryCount)
    : params_(params), structureHash_(structureHash), contentHash_(contentHash), ownedOffsets_(std::move(offsets)),
      ownedIndices_(std::move(indices)), offsets_(ownedOffsets_), indices_(ownedIndices_.get(), entryCount) {}

InfluenceLists::InfluenceLists(KernelParams params, uint64_t structureHash, uint64_t contentHash, std::span<const uint64_t> offsets,
                               std::span<const uint32_t> indices, std::shared_ptr<const MappedFile> mapping)
    : params_(params), structureHash_(structureHash), contentHash_(contentHash), mapping_(std::move(mapping)), offsets_(offsets),
      indices_(indices) {}

InfluenceLists::Stats InfluenceLists::stats() const {
    Stats s;
    const size_t n = cellCount();
    s.bytes = offsets_.size_bytes() + indices_.size_bytes();
    if (n == 0) return s;
    std::vector<uint64_t> lengths(n);
    for (size_t k = 0; k < n; ++k) lengths[k] = offsets_[k + 1] - offsets_[k];
    s.meanLength = static_cast<double>(entryCount()) / static_cast<double>(n);
    s.maxLength = *std::max_element(lengths.begin(), lengths.end());
    auto p99 = lengths.begin() + static_cast<std::ptrdiff_t>(std::min(n - 1, n * 99 / 100));
    std::nth_element(lengths.begin(), p99, lengths.end());
    s.p99Length = *p99;
    return s;
}

bool influences(const Grid& grid, const KernelParams& params, size_t i, size_t k) {
    double cx, cy;
    grid.cellCenterLocal(i, cx, cy);
    const double r = params.radiusM(grid.cellSizeM(i));
    const Grid::Square q = grid.cellSquare(k);
    return kernelReaches(cx, cy, r * r, q.x0, q.y0, q.x1, q.y1);
}

namespace {

// keep[c] = kernelReaches(cx[c], cy[c], r2[c], square) for every candidate, in a form the compiler
// vectorises (no aliasing, selects instead of branches).
void reachMask(const double* __restrict cx, const double* __restrict cy, const double* __restrict r2, size_t m, double x0, double y0,
               double x1, double y1, uint8_t* __restrict keep) {
    for (size_t c = 0; c < m; ++c) {
        const double ax = x0 - cx[c], bx = cx[c] - x1, ay = y0 - cy[c], by = cy[c] - y1;
        double dx = ax > bx ? ax : bx;
        double dy = ay > by ? ay : by;
        dx = dx > 0.0 ? dx : 0.0;
        dy = dy > 0.0 ? dy : 0.0;
        keep[c] = dx * dx + dy * dy < r2[c];
    }
}

struct Candidate {
    std::vector<double> cx, cy, r2;
    std::vector<uint32_t> index;
    void clear() {
        cx.clear();
        cy.clear();
        r2.clear();
        index.clear();
    }
};

// A quadtree node and the cells it holds (an index range: a node's cells are contiguous).
struct NodeRange {
    uint64_t key;
    int level;
    size_t lo, hi;
};

// The nodes below `start` that hold at most maxCells cells each, in Morton order (they cover
// start's cells exactly, in order).
std::vector<NodeRange> splitNodes(const Grid& g, NodeRange start, size_t maxCells) {
    std::vector<NodeRange> out, stack{start};
    while (!stack.empty()) {
        NodeRange n = stack.back();
        stack.pop_back();
        if (n.lo == n.hi) continue;
        if (n.hi - n.lo <= maxCells || n.level == 0) {
            out.push_back(n);
            continue;
        }
        const uint64_t quarter = mortonSpan(n.level - 1);
        size_t bounds[5] = {n.lo, 0, 0, 0, n.hi};
        for (int q = 1; q < 4; ++q)
            bounds[q] = static_cast<size_t>(std::lower_bound(g.codes.begin() + static_cast<std::ptrdiff_t>(bounds[q - 1]),
                                                             g.codes.begin() + static_cast<std::ptrdiff_t>(n.hi),
                                                             makeCellCode(n.key + quarter * static_cast<uint64_t>(q), 0)) -
                                            g.codes.begin());
        for (int q = 3; q >= 0; --q) stack.push_back({n.key + quarter * static_cast<uint64_t>(q), n.level - 1, bounds[q], bounds[q + 1]});
    }
    return out;
}

// Keeps the candidates whose disks reach the box [x0, x1] x [y0, y1]: from (in) to (out).
void filterCandidates(const Candidate& in, double x0, double y0, double x1, double y1, std::vector<uint8_t>& keep, Candidate& out) {
    const size_t m = in.index.size();
    keep.resize(m);
    reachMask(in.cx.data(), in.cy.data(), in.r2.data(), m, x0, y0, x1, y1, keep.data());
    out.clear();
    for (size_t c = 0; c < m; ++c)
        if (keep[c]) {
            out.cx.push_back(in.cx[c]);
            out.cy.push_back(in.cy[c]);
            out.r2.push_back(in.r2[c]);
            out.index.push_back(in.index[c]);
        }
}

Grid::Square boundsOf(const Grid& g, size_t lo, size_t hi) {
    Grid::Square b{HUGE_VAL, HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
    for (size_t k = lo; k < hi; ++k) {
        const Grid::Square q = g.cellSquare(k);
        b.x0 = std::min(b.x0, q.x0);
        b.y0 = std::min(b.y0, q.y0);
        b.x1 = std::max(b.x1, q.x1);
        b.y1 = std::max(b.y1, q.y1);
    }
    return b;
}

}  // namespace

InfluenceLists buildInfluenceLists(const Grid& g, const KernelParams& params, unsigned threads, bool progress) {
    if (std::string why = params.validate(); !why.empty()) throw Error("influence parameters: " + why);
    if (g.cellCount() >= std::numeric_limits<uint32_t>::max()) throw Error("grid has too many cells for 32-bit influence indices");
    const size_t n = g.cellCount();
    threads = resolveThreads(threads);

    // One query index per level: a Grid holding only that level's codes (queries need no values).
    const size_t levels = static_cast<size_t>(g.maxLevel) + 1;
    std::vector<Grid> byLevel(levels);
    std::vector<std::vector<uint32_t>> levelIndex(levels);
    for (size_t l = 0; l < levels; ++l) {
        byLevel[l].finestCellM = g.finestCellM;
        byLevel[l].rootLevel = g.rootLevel;
        byLevel[l].maxLevel = g.maxLevel;
    }
    for (size_t i = 0; i < n; ++i) {
        auto l = static_cast<size_t>(g.level(i));
        byLevel[l].codes.push_back(g.codes[i]);
        levelIndex[l].push_back(static_cast<uint32_t>(i));
    }

    // Centres of each level's cells, for the candidate search.
    std::vector<std::vector<double>> levelCx(levels), levelCy(levels);
    for (size_t l = 0; l < levels; ++l) {
        levelCx[l].resize(levelIndex[l].size());
        levelCy[l].resize(levelIndex[l].size());
        for (size_t j = 0; j < levelIndex[l].size(); ++j) g.cellCenterLocal(levelIndex[l][j], levelCx[l][j], levelCy[l][j]);
    }

    // Two-level blocking: a super-block (at most 256 cells) gathers candidates with one range query
    // per level; its blocks (at most 16 cells) narrow them down; each cell tests its block's few.
    const auto superBlocks = splitNodes(g, {0, g.rootLevel, 0, n}, 256);
    std::vector<uint64_t> offsets(n + 1, 0);
    // The entries, grown by doubling; pages are first touched by the parallel copies below.
    size_t capacity = std::max<size_t>(n * 48, 1024), used = 0;
    auto indices = std::unique_ptr<uint32_t[]>(new uint32_t[capacity]);

    struct Scratch {
        Candidate wide, narrow;
        std::vector<uint32_t> hits;
        std::vector<uint8_t> keep;
    };
    std::vector<Scratch> scratch(threads);
    Progress bar("influence lists", n, progress);
    // Batches of super-blocks run in parallel; their lists are appended in cell order after each.
    constexpr size_t kBatch = 256;
    std::vector<std::vector<uint32_t>> batchEntries(kBatch), batchLengths(kBatch);
    for (size_t b0 = 0; b0 < superBlocks.size(); b0 += kBatch) {
        const size_t b1 = std::min(superBlocks.size(), b0 + kBatch);
        parallelFor(b1 - b0, 1, threads, [&](size_t bb, size_t be, unsigned worker) {
            Scratch& s = scratch[worker];
            for (size_t b = b0 + bb; b < b0 + be; ++b) {
                const NodeRange& sb = superBlocks[b];
                auto& entries = batchEntries[b - b0];
                auto& lengths = batchLengths[b - b0];
                entries.clear();
                lengths.clear();
                const Grid::Square box = boundsOf(g, sb.lo, sb.hi);
                s.wide.clear();
                for (size_t l = 0; l < levels; ++l) {
                    if (byLevel[l].codes.empty()) continue;
                    const double r = params.radiusM(g.levelSizeM(static_cast<int>(l)));
                    const double r2 = r * r;
                    s.hits.clear();
                    byLevel[l].cellsInBox(box.x0 - r, box.y0 - r, box.x1 + r, box.y1 + r, s.hits);
                    for (uint32_t j : s.hits) {
                        if (!kernelReaches(levelCx[l][j], levelCy[l][j], r2, box.x0, box.y0, box.x1, box.y1)) continue;
                        s.wide.cx.push_back(levelCx[l][j]);
                        s.wide.cy.push_back(levelCy[l][j]);
                        s.wide.r2.push_back(r2);
                        s.wide.index.push_back(levelIndex[l][j]);
                    }
                }
                for (const NodeRange& blk : splitNodes(g, sb, 16)) {
                    const Grid::Square bbox = boundsOf(g, blk.lo, blk.hi);
                    filterCandidates(s.wide, bbox.x0, bbox.y0, bbox.x1, bbox.y1, s.keep, s.narrow);
                    const size_t m = s.narrow.index.size();
                    s.keep.resize(m);
                    for (size_t k = blk.lo; k < blk.hi; ++k) {
                        // Every candidate against the cell (vectorised), then a branch-free compaction.
                        const Grid::Square q = g.cellSquare(k);
                        reachMask(s.narrow.cx.data(), s.narrow.cy.data(), s.narrow.r2.data(), m, q.x0, q.y0, q.x1, q.y1, s.keep.data());
                        const size_t before = entries.size();
                        entries.resize(before + m);
                        uint32_t* outp = entries.data() + before;
                        size_t kept = 0;
                        for (size_t c = 0; c < m; ++c) {
                            outp[kept] = s.narrow.index[c];
                            kept += s.keep[c];
                        }
                        entries.resize(before + kept);
                        lengths.push_back(static_cast<uint32_t>(kept));
                    }
                }
            }
        });
        // Offsets in order (cheap), then every super-block's entries copied to their place in parallel.
        std::vector<size_t> at(b1 - b0);
        for (size_t b = b0; b < b1; ++b) {
            const NodeRange& sb = superBlocks[b];
            at[b - b0] = offsets[sb.lo];
            for (size_t k = sb.lo; k < sb.hi; ++k) offsets[k + 1] = offsets[k] + batchLengths[b - b0][k - sb.lo];
        }
        const size_t needed = offsets[superBlocks[b1 - 1].hi];
        if (b0 == 0 && superBlocks[b1 - 1].hi < n) {
            // The first batch tells the mean list length: size the buffer for all cells now, while
            // moving it is cheap (lists grow with sigma and with the cell-size ratio).
            const double perCell = double(needed) / double(superBlocks[b1 - 1].hi);
            const size_t estimate = size_t(perCell * 1.1 * double(n)) + 1024;
            if (estimate > capacity) {
                auto bigger = std::unique_ptr<uint32_t[]>(new uint32_t[estimate]);
                std::copy(indices.get(), indices.get() + used, bigger.get());
                indices = std::move(bigger);
                capacity = estimate;
            }
        }
        if (needed > capacity) {
            capacity = std::max(needed, capacity * 2);
            auto bigger = std::unique_ptr<uint32_t[]>(new uint32_t[capacity]);
            std::copy(indices.get(), indices.get() + used, bigger.get());
            indices = std::move(bigger);
        }
        parallelFor(b1 - b0, 4, threads, [&](size_t bb, size_t be, unsigned) {
            for (size_t b = bb; b < be; ++b) std::copy(batchEntries[b].begin(), batchEntries[b].end(), indices.get() + at[b]);
        });
        used = needed;
        bar.advance(superBlocks[b1 - 1].hi - superBlocks[b0].lo);
    }
    bar.finish();
    return InfluenceLists(params, g.structureHash(), g.contentHash(), std::move(offsets), std::move(indices), used);
}

}  // namespace hc::influence
