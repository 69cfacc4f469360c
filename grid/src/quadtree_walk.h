// grid/src/quadtree_walk.h: the depth-first walk over the implicit quadtree of sorted cell codes, shared by
// the in-memory queries (Grid::cellsInBox, cellsInDisk) and the region reads of a grid file that is not held
// (GridRegionReader, grid_region_reader.cpp), which reach the codes through a function rather than an array.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "heightcast/grid/morton.h"

namespace hc::detail {

// A node (level L, corner key k) owns exactly the cells with keys in [k, k + 4^L): one binary search per child
// splits a node's run of cells. codeAt(i) returns cell i's code (i < count, codes ascending); lowerBound(lo, hi, code)
// the first index in [lo, hi) whose code is not below `code` (hi if none).
// nodeMeets(key, level) -> 0: the node is disjoint from the query, 1: partly inside, 2: inside (every cell in it
// is taken); emitRange(lo, hi) takes cells [lo, hi) of a node inside; emitCell(i) decides for one cell of a node
// partly inside that holds a single cell (or is the cell). Ranges and cells come in ascending order.
// The walk starts at the node (startKey, startLevel) whose cells are [lo, hi): the root and every cell for a whole
// grid.
template <typename CodeAt, typename LowerBound, typename Meets, typename EmitRange, typename EmitCell>
void walkQuadtree(uint64_t startKey, int startLevel, size_t lo, size_t hi, CodeAt&& codeAt, LowerBound&& lowerBound,
                  Meets&& nodeMeets, EmitRange&& emitRange, EmitCell&& emitCell) {
    struct Node {
        uint64_t key;
        int level;
        size_t lo, hi;  // cell index range [lo, hi)
    };
    if (lo >= hi) return;
    std::vector<Node> stack;
    stack.push_back({startKey, startLevel, lo, hi});
    while (!stack.empty()) {
        const Node n = stack.back();
        stack.pop_back();
        const int meets = nodeMeets(n.key, n.level);
        if (meets == 0) continue;
        if (meets == 2) {
            emitRange(n.lo, n.hi);
            continue;
        }
        if (n.hi - n.lo == 1 || n.level == 0 || codeLevel(codeAt(n.lo)) == n.level) {
            // A single cell (or the leaf itself): test the cells directly.
            for (size_t i = n.lo; i < n.hi; ++i) emitCell(i);
            continue;
        }
        const uint64_t quarter = mortonSpan(n.level - 1);
        size_t bounds[5];
        bounds[0] = n.lo;
        bounds[4] = n.hi;
        for (int q = 1; q < 4; ++q)
            bounds[q] = lowerBound(bounds[q - 1], n.hi, makeCellCode(n.key + quarter * static_cast<uint64_t>(q), 0));
        for (int q = 3; q >= 0; --q)  // pushed in reverse so children pop in Morton order
            if (bounds[q] < bounds[q + 1])
                stack.push_back({n.key + quarter * static_cast<uint64_t>(q), n.level - 1, bounds[q], bounds[q + 1]});
    }
}

}  // namespace hc::detail
