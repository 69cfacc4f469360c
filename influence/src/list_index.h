// influence/src/list_index.h: the candidate search behind every influence list (influence.h's rule), shared
// by the whole-grid builder (buildInfluenceLists) and by builders that need the lists of one region at a time
// (the surface pyramid, pyramid.cpp), so that no caller has to hold every list of a large grid.
//
// The index holds each level's cell codes apart (a level's cells only within that level's radius of a block
// are candidates): 12 bytes per cell. Lists come out per quadtree node, in cell order, each list holding each
// level's cells in Morton order, finer levels first.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "heightcast/core/progress.h"

#include "heightcast/grid/grid.h"
#include "heightcast/influence/kernel.h"

namespace hc::influence::detail {

// A quadtree node and the cells it holds (an index range: a node's cells are contiguous).
struct NodeRange {
    uint64_t key;
    int level;
    size_t lo, hi;
};

// The nodes below `start` that hold at most maxCells cells each, in Morton order (they cover start's cells
// exactly, in order).
std::vector<NodeRange> splitNodes(const Grid& g, NodeRange start, size_t maxCells);

// The node of `level` with corner key `key` (a multiple of 4^level) and the range of cells inside it.
NodeRange nodeCells(const Grid& g, uint64_t key, int level);

// Cells a super-block of the list builder holds at most (one range query per level serves them all).
constexpr size_t kSuperBlockCells = 256;

// Candidate cells of a box: centres, squared kernel radii and cell indices.
struct Candidates {
    std::vector<double> cx, cy, r2;
    std::vector<uint32_t> index;
};

class ListIndex {
public:
    ListIndex(const Grid& g, const KernelParams& params);

    // Per-thread working memory of candidatesFor() and listsFor(): the candidates, and those narrowed to a block.
    struct Scratch : Candidates {
        Candidates narrowed;
        std::vector<uint32_t> hits;
        std::vector<uint8_t> keep;
    };
    // The cells whose kernel disks reach into the closed box with a positive weight (kernelReaches): their
    // centres, squared radii and cell indices into s.cx, s.cy, s.r2, s.index (replacing what was there),
    // each level's in Morton order, finer levels first.
    void candidatesFor(const Grid::Square& box, Scratch& s) const;
    // Appends the lists of the cells of `node` (at most a few hundred cells: one range query per level
    // serves them all) to `entries`, one length per cell to `lengths`, in cell order.
    void listsFor(const NodeRange& node, Scratch& s, std::vector<uint32_t>& entries,
                  std::vector<uint32_t>& lengths) const;

private:
    const Grid& g_;
    KernelParams params_;
    std::vector<Grid> byLevel_;                      // one query index per level: that level's codes only
    std::vector<std::vector<uint32_t>> levelIndex_;  // their cell indices in g
};

// The candidates of `from` (candidatesFor over a box holding `box`, or narrowed from one) whose kernels reach `box`, in
// their order, into `to` (replacing what was there): the same as candidatesFor(box, to), without a walk of the levels.
// `keep`: working memory.
void narrowCandidates(const Candidates& from, const Grid::Square& box, Candidates& to, std::vector<uint8_t>& keep);

// The lists of the cells of super-blocks [s0, s1) of `superBlocks` (splitNodes of the whole grid): offsets from the
// first of those cells (firstCell; offsets.size() = their cell count + 1) into `entries` indices. A whole-grid build is
// the part of every super-block; a rank of mpirun builds its share (influence/src/on_ranks.cpp).
struct ListPart {
    size_t firstCell = 0;
    std::vector<uint64_t> offsets;
    std::unique_ptr<uint32_t[]> indices;
    size_t entries = 0;
};
ListPart buildListPart(const ListIndex& index, const std::vector<NodeRange>& superBlocks, size_t s0, size_t s1,
                       unsigned threads, Progress& bar);
// Throws hc::Error for invalid parameters or a grid of 2^32 cells or more.
void checkListInputs(const Grid& g, const KernelParams& params);

}  // namespace hc::influence::detail
