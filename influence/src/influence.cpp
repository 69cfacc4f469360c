// Building influence lists: super-blocks of cells (quadtree nodes of at most 256 cells) in parallel, each
// through the candidate search of list_index.h, their lists appended in cell order.
#include "heightcast/influence/influence.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "heightcast/core/error.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/progress.h"
#include "heightcast/core/sectioned_file.h"
#include "list_index.h"

namespace hc::influence {

InfluenceLists::InfluenceLists(KernelParams params, uint64_t structureHash, uint64_t contentHash,
                               std::vector<uint64_t> offsets, std::unique_ptr<uint32_t[]> indices, size_t entryCount)
    : params_(params),
      structureHash_(structureHash),
      contentHash_(contentHash),
      ownedOffsets_(std::move(offsets)),
      ownedIndices_(std::move(indices)),
      offsets_(ownedOffsets_),
      indices_(ownedIndices_.get(), entryCount) {}

InfluenceLists::InfluenceLists(KernelParams params, uint64_t structureHash, uint64_t contentHash,
                               std::span<const uint64_t> offsets, std::span<const uint32_t> indices,
                               std::shared_ptr<const MappedFile> mapping)
    : params_(params),
      structureHash_(structureHash),
      contentHash_(contentHash),
      mapping_(std::move(mapping)),
      offsets_(offsets),
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

namespace detail {

ListPart buildListPart(const ListIndex& index, const std::vector<NodeRange>& superBlocks, size_t s0, size_t s1,
                       unsigned threads, Progress& bar) {
    threads = resolveThreads(threads);
    ListPart part;
    part.firstCell = s0 < s1 ? superBlocks[s0].lo : 0;
    const size_t n = s0 < s1 ? superBlocks[s1 - 1].hi - part.firstCell : 0, base = part.firstCell;
    std::vector<uint64_t>& offsets = part.offsets;
    offsets.assign(n + 1, 0);
    // The entries, grown by doubling; pages are first touched by the parallel copies below.
    size_t capacity = std::max<size_t>(n * 48, 1024), used = 0;
    auto indices = std::unique_ptr<uint32_t[]>(new uint32_t[capacity]);

    std::vector<ListIndex::Scratch> scratch(threads);
    // Batches of super-blocks run in parallel; their lists are appended in cell order after each.
    constexpr size_t kBatch = 256;
    std::vector<std::vector<uint32_t>> batchEntries(kBatch), batchLengths(kBatch);
    for (size_t b0 = s0; b0 < s1; b0 += kBatch) {
        const size_t b1 = std::min(s1, b0 + kBatch);
        parallelFor(b1 - b0, 1, threads, [&](size_t bb, size_t be, unsigned worker) {
            ListIndex::Scratch& sc = scratch[worker];
            for (size_t b = b0 + bb; b < b0 + be; ++b) {
                auto& entries = batchEntries[b - b0];
                auto& lengths = batchLengths[b - b0];
                entries.clear();
                lengths.clear();
                index.listsFor(superBlocks[b], sc, entries, lengths);
            }
        });
        // Offsets in order (cheap), then every super-block's entries copied to their place in parallel.
        std::vector<size_t> at(b1 - b0);
        for (size_t b = b0; b < b1; ++b) {
            const NodeRange& sb = superBlocks[b];
            at[b - b0] = offsets[sb.lo - base];
            for (size_t k = sb.lo; k < sb.hi; ++k)
                offsets[k + 1 - base] = offsets[k - base] + batchLengths[b - b0][k - sb.lo];
        }
        const size_t needed = offsets[superBlocks[b1 - 1].hi - base];
        if (b0 == s0 && superBlocks[b1 - 1].hi - base < n) {
            // The first batch tells the mean list length: size the buffer for all cells now, while
            // moving it is cheap (lists grow with sigma and with the cell-size ratio).
            const double perCell = double(needed) / double(superBlocks[b1 - 1].hi - base);
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
            for (size_t b = bb; b < be; ++b)
                std::copy(batchEntries[b].begin(), batchEntries[b].end(), indices.get() + at[b]);
        });
        used = needed;
        bar.advance(superBlocks[b1 - 1].hi - superBlocks[b0].lo);
    }
    part.indices = std::move(indices);
    part.entries = used;
    return part;
}

void checkListInputs(const Grid& g, const KernelParams& params) {
    if (std::string why = params.validate(); !why.empty()) throw Error("influence parameters: " + why);
    if (g.cellCount() >= std::numeric_limits<uint32_t>::max())
        throw Error("grid has too many cells for 32-bit influence indices");
}

}  // namespace detail

InfluenceLists buildInfluenceLists(const Grid& g, const KernelParams& params, unsigned threads, bool progress) {
    detail::checkListInputs(g, params);
    const detail::ListIndex index(g, params);
    // Super-blocks of at most 256 cells gather candidates with one range query per level (list_index.h).
    const auto superBlocks = detail::splitNodes(g, {0, g.rootLevel, 0, g.cellCount()}, detail::kSuperBlockCells);
    Progress bar("influence lists", g.cellCount(), progress);
    detail::ListPart part = detail::buildListPart(index, superBlocks, 0, superBlocks.size(), threads, bar);
    bar.finish();
    if (part.offsets.size() != g.cellCount() + 1) part.offsets.assign(g.cellCount() + 1, 0);  // no cells
    return InfluenceLists(params, g.structureHash(), g.contentHash(), std::move(part.offsets), std::move(part.indices),
                          part.entries);
}

}  // namespace hc::influence
