// influence/src/list_index.cpp: the candidate search (list_index.h). A node gathers candidates once, level by
// level (a level's cells only within that level's radius of the node), its blocks of at most 16 cells narrow
// them down, and every cell of a block keeps the candidates that reach its square (kernelReaches, vectorised).
#include "list_index.h"

#include <algorithm>
#include <cmath>

namespace hc::influence::detail {
namespace {

// keep[c] = kernelReaches(cx[c], cy[c], r2[c], square) for every candidate, in a form the compiler
// vectorises (no aliasing, selects instead of branches).
void reachMask(const double* __restrict cx, const double* __restrict cy, const double* __restrict r2, size_t m,
               double x0, double y0, double x1, double y1, uint8_t* __restrict keep) {
    for (size_t c = 0; c < m; ++c) {
        const double ax = x0 - cx[c], bx = cx[c] - x1, ay = y0 - cy[c], by = cy[c] - y1;
        double dx = ax > bx ? ax : bx;
        double dy = ay > by ? ay : by;
        dx = dx > 0.0 ? dx : 0.0;
        dy = dy > 0.0 ? dy : 0.0;
        keep[c] = dx * dx + dy * dy < r2[c];
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
            bounds[q] =
                static_cast<size_t>(std::lower_bound(g.codes.begin() + static_cast<std::ptrdiff_t>(bounds[q - 1]),
                                                     g.codes.begin() + static_cast<std::ptrdiff_t>(n.hi),
                                                     makeCellCode(n.key + quarter * static_cast<uint64_t>(q), 0)) -
                                    g.codes.begin());
        for (int q = 3; q >= 0; --q)
            stack.push_back({n.key + quarter * static_cast<uint64_t>(q), n.level - 1, bounds[q], bounds[q + 1]});
    }
    return out;
}

NodeRange nodeCells(const Grid& g, uint64_t key, int level) {
    const auto lo = std::lower_bound(g.codes.begin(), g.codes.end(), makeCellCode(key, 0));
    const auto hi = std::lower_bound(lo, g.codes.end(), makeCellCode(key + mortonSpan(level), 0));
    return {key, level, static_cast<size_t>(lo - g.codes.begin()), static_cast<size_t>(hi - g.codes.begin())};
}

ListIndex::ListIndex(const Grid& g, const KernelParams& params) : g_(g), params_(params) {
    const size_t levels = static_cast<size_t>(g.maxLevel) + 1;
    byLevel_.resize(levels);
    levelIndex_.resize(levels);
    std::vector<size_t> counts(levels, 0);
    for (uint64_t code : g.codes) ++counts[static_cast<size_t>(codeLevel(code))];
    for (size_t l = 0; l < levels; ++l) {
        byLevel_[l].finestCellM = g.finestCellM;
        byLevel_[l].rootLevel = g.rootLevel;
        byLevel_[l].maxLevel = g.maxLevel;
        byLevel_[l].codes.reserve(counts[l]);
        levelIndex_[l].reserve(counts[l]);
    }
    for (size_t i = 0; i < g.cellCount(); ++i) {
        auto l = static_cast<size_t>(g.level(i));
        byLevel_[l].codes.push_back(g.codes[i]);
        levelIndex_[l].push_back(static_cast<uint32_t>(i));
    }
}

void narrowCandidates(const Candidates& from, const Grid::Square& box, Candidates& to, std::vector<uint8_t>& keep) {
    const size_t m = from.index.size();
    keep.resize(m);
    reachMask(from.cx.data(), from.cy.data(), from.r2.data(), m, box.x0, box.y0, box.x1, box.y1, keep.data());
    to.cx.resize(m), to.cy.resize(m), to.r2.resize(m), to.index.resize(m);
    size_t kept = 0;
    for (size_t c = 0; c < m; ++c) {  // a branch-free compaction of the mask
        to.cx[kept] = from.cx[c], to.cy[kept] = from.cy[c], to.r2[kept] = from.r2[c], to.index[kept] = from.index[c];
        kept += keep[c];
    }
    to.cx.resize(kept), to.cy.resize(kept), to.r2.resize(kept), to.index.resize(kept);
}

void ListIndex::candidatesFor(const Grid::Square& box, Scratch& s) const {
    s.cx.clear(), s.cy.clear(), s.r2.clear(), s.index.clear();
    for (size_t l = 0; l < byLevel_.size(); ++l) {
        const Grid& lg = byLevel_[l];
        if (lg.codes.empty()) continue;
        const double r = params_.radiusM(g_.levelSizeM(static_cast<int>(l)));
        const double r2 = r * r;
        s.hits.clear();
        lg.cellsInBox(box.x0 - r, box.y0 - r, box.x1 + r, box.y1 + r, s.hits);
        for (uint32_t j : s.hits) {
            double cx, cy;
            lg.cellCenterLocal(j, cx, cy);
            if (!kernelReaches(cx, cy, r2, box.x0, box.y0, box.x1, box.y1)) continue;
            s.cx.push_back(cx);
            s.cy.push_back(cy);
            s.r2.push_back(r2);
            s.index.push_back(levelIndex_[l][j]);
        }
    }
}

void ListIndex::listsFor(const NodeRange& node, Scratch& s, std::vector<uint32_t>& entries,
                         std::vector<uint32_t>& lengths) const {
    if (node.lo == node.hi) return;
    const Grid::Square box = boundsOf(g_, node.lo, node.hi);
    candidatesFor(box, s);
    for (const NodeRange& blk : splitNodes(g_, node, 16)) {
        // The node's candidates narrowed to the block, then every one of those against each cell.
        const Grid::Square bbox = boundsOf(g_, blk.lo, blk.hi);
        narrowCandidates(s, bbox, s.narrowed, s.keep);
        const Candidates& n = s.narrowed;
        const size_t m = n.index.size();
        s.keep.resize(m);
        for (size_t k = blk.lo; k < blk.hi; ++k) {
            // A branch-free compaction of the mask.
            const Grid::Square q = g_.cellSquare(k);
            reachMask(n.cx.data(), n.cy.data(), n.r2.data(), m, q.x0, q.y0, q.x1, q.y1, s.keep.data());
            const size_t before = entries.size();
            entries.resize(before + m);
            uint32_t* outp = entries.data() + before;
            size_t kept = 0;
            for (size_t c = 0; c < m; ++c) {
                outp[kept] = n.index[c];
                kept += s.keep[c];
            }
            entries.resize(before + kept);
            lengths.push_back(static_cast<uint32_t>(kept));
        }
    }
}

}  // namespace hc::influence::detail
