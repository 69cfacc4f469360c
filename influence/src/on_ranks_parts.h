// influence/src/on_ranks_parts.h: what the lists (on_ranks.cpp) and the pyramid (pyramid_on_ranks.cpp) built on the
// ranks share: a node's region read from the grid file, this rank's nodes, the file's pages released as regions are
// read, and the collective write of a sectioned file whose runs the ranks hold. Private to influence/src/.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "heightcast/core/sectioned_file.h"
#include "heightcast/influence/on_ranks.h"

namespace hc::influence::detail {

// Keeps the grid file's pages that many small regions touch from piling up in resident memory: they are released
// (GridRegionReader::releasePages) every 32 regions, and sooner once the regions read since the last release hold about
// 64 MB of the file (their cells at 8 bytes of code and 4 of each value, and the blocks their reads checksummed, a
// block whole). A region's binary searches touch pages beyond its cells: without this, the coarse tiles' many small
// regions left far more of the file resident than the cells they read. Any thread may call after(); a region read
// meanwhile reads its pages back from the page cache.
class PageReleaser {
public:
    explicit PageReleaser(const GridRegionReader& file) : file_(file), checkedAt_(file.bytesChecked()) {}
    void after(const Grid& region) {
        const uint64_t bytes = region.cellCount() * (8 + 4 * uint64_t(std::max<size_t>(1, region.values.size())));
        const uint64_t touched = touched_.fetch_add(bytes) + bytes;
        const uint64_t checked = file_.bytesChecked();
        if (++regions_ % kRegions != 0 && touched + (checked - std::min(checked, checkedAt_.load())) < kBytes)
            return;  // min: a race
        touched_ = 0, checkedAt_ = checked;
        file_.releasePages();
    }

private:
    static constexpr uint64_t kBytes = uint64_t{64} << 20, kRegions = 32;
    const GridRegionReader& file_;
    std::atomic<uint64_t> touched_{0}, checkedAt_, regions_{0};
};

Grid::Square nodeSquare(const Grid& shape, uint64_t key, int level);

// A region of the file with each of its cells' index in the file.
struct IndexedRegion {
    Grid grid;
    std::vector<uint32_t> fileIndex;  // per region cell
    size_t lo = 0, hi = 0;            // the region cells inside the node it was read for
};
// The cells of `box` and `margins` around it (region.h), read for node `key` of `level`; wantIndex: with their indices.
IndexedRegion readIndexed(const GridRegionReader& file, const Grid::Square& box, const std::vector<double>& margins,
                          uint64_t key, int level, bool wantIndex);

// The indices in part.keys of this rank's nodes, in Morton order.
std::vector<size_t> myNodes(const RankPartition& part);

// A file of this rank's samples written as they are made, read back when the file they belong to is written
// (pyramid_on_ranks.cpp): created beside that file and unlinked at once (no name left behind, whatever ends the
// process), appended to through a buffer, then mapped for reading.
class SampleSpill {
public:
    explicit SampleSpill(const std::string& besidePath);  // throws hc::Error naming the folder
    ~SampleSpill();
    SampleSpill(const SampleSpill&) = delete;
    SampleSpill& operator=(const SampleSpill&) = delete;
    // Appends `bytes`; returns their offset in the spill.
    uint64_t append(std::span<const std::byte> bytes);
    // Ends the appends and maps the whole spill for reading (its bytes [offset, offset + n)).
    std::span<const std::byte> map();
    // Drops the whole pages inside `bytes` (of the mapping) from resident memory: they stay in the page cache.
    void release(std::span<const std::byte> bytes) const;
    uint64_t size() const { return size_; }

private:
    void flush();
    std::string where_;
    int fd_ = -1;
    std::vector<std::byte> buffer_;
    uint64_t size_ = 0;
    void* mapped_ = nullptr;
};

// A run of bytes a rank writes: bytes [at, at + bytes.size()) of section `section` of a placed layout. Bytes in a
// SampleSpill's mapping (spill) are written a chunk at a time, each chunk's pages released after it, so that the write
// does not leave the whole spill resident.
struct Run {
    size_t section;
    uint64_t at;
    std::span<const std::byte> bytes;
    const SampleSpill* spill = nullptr;
};

// Collective: writes the file at `path` whose sections (`layout`, of `format`) the ranks' runs fill, each rank's runs
// in order, the ranks' runs of a section in rank order and rank 0's first: rank 0 places the sections in its temporary
// and appends its runs, the others write theirs into that temporary in place (SectionedFilePart: a file system every
// rank sees), then rank 0 takes their pieces' CRCs in rank order, as if it had appended their bytes, and commits with
// `header` (rank 0's). A failure on any rank stops every rank at the next step and leaves no file (rank 0's writer
// removes its temporary).
void writeByParts(const std::string& path, const FileFormat& format, std::vector<FileSection> layout,
                  const std::vector<Run>& runs, std::vector<std::byte> header);

}  // namespace hc::influence::detail
