// tests/hostile_files.h: crafted .hcg and .hci files whose checksums are all VALID (issue 11). A reader that
// trusts a declared count because its CRC matches is the bug these files expose, so every one of them is
// written through the real container writer (hc::SectionedFileWriter), which computes every CRC and the
// declared size. Used by grid_file_test, grid_file_blocks_test, cache_file_test and the CLI tests' helper
// (cli/hostile_craft.cpp).
#pragma once

#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "heightcast/core/bytes.h"
#include "heightcast/core/sectioned_file.h"

namespace hc::hostile {

// The formats' container parameters (grid_file_internal.h, cache_file.cpp), repeated here on purpose: a test that
// borrowed the readers' own constants would not notice if they changed.
inline const FileFormat kGridFormat{
    {'\x89', 'H', 'C', 'G', 'R', 'I', 'D', '\n'}, 1, 0, "heightcast grid (.hcg)", {1, 2, 3}};
inline const FileFormat kCacheFormat{
    {'\x89', 'H', 'C', 'I', 'N', 'F', 'L', '\n'}, 1, 0, "heightcast influence cache (.hci)", {1, 2}};
enum : uint32_t { kGridMeta = 1, kGridCells = 2, kGridLayer = 3, kCacheOffsets = 1, kCacheIndices = 2 };
// Header fields (grid_file.h, cache_file.cpp).
constexpr size_t kGridCellCountAt = 24, kCacheCellCountAt = 24, kCacheEntryCountAt = 32;

struct Section {
    uint32_t kind = 0, index = 0;
    std::vector<std::byte> bytes;
};
struct Container {
    std::vector<std::byte> header;  // kFileHeaderBytes, the format's own fields included
    std::vector<Section> sections;  // in file order
};

// Reads a valid container (throws hc::Error otherwise).
inline Container readContainer(const std::string& path, const FileFormat& format) {
    const SectionedFileReader r(path, format);
    Container c;
    c.header.assign(r.header(), r.header() + kFileHeaderBytes);
    for (const FileSection& s : r.sections()) {
        const auto d = r.data(s);
        c.sections.push_back({s.kind, s.index, {d.begin(), d.end()}});
    }
    return c;
}

// Writes `c` with every checksum, the declared size and the section table computed afresh.
inline void writeContainer(const Container& c, const std::string& path, const FileFormat& format) {
    SectionedFileWriter w(path, format, {}, c.sections.size());
    for (const Section& s : c.sections) w.addSection(s.kind, s.index, s.bytes);
    w.commit(c.header);
}

// A grid declaring `cellCount` cells whose CELLS and LAYER sections are empty. With 2^62 cells the old size
// checks computed 2^62 * 8 and 2^62 * 4, both 0 modulo 2^64, accepted the empty sections, and the reader
// then tried to allocate 2^62 cells (std::length_error "vector::_M_default_append", no file name).
inline void gridWithEmptySections(const std::string& in, const std::string& out, uint64_t cellCount) {
    Container c = readContainer(in, kGridFormat);
    bytes::store<uint64_t>(c.header, kGridCellCountAt, cellCount);
    for (Section& s : c.sections)
        if (s.kind == kGridCells || s.kind == kGridLayer) s.bytes.clear();
    writeContainer(c, out, kGridFormat);
}

// A cache declaring `entryCount` entries, with an empty INDICES section and OFFSETS that end at
// `entryCount` (the others as built). With 2^62 the old check computed 2^62 * 4 = 0, accepted the empty
// INDICES, and walking the last cell's list read past the end of the file.
inline void cacheWithEntryCount(const std::string& in, const std::string& out, uint64_t entryCount) {
    Container c = readContainer(in, kCacheFormat);
    bytes::store<uint64_t>(c.header, kCacheEntryCountAt, entryCount);
    for (Section& s : c.sections) {
        if (s.kind == kCacheIndices) s.bytes.clear();
        if (s.kind == kCacheOffsets) bytes::store<uint64_t>(s.bytes, s.bytes.size() - 8, entryCount);
    }
    writeContainer(c, out, kCacheFormat);
}

// A cache whose first list ends `beyond` entries past the entry count while OFFSETS still end at it: the
// old reader checked only that offsets do not decrease and that the last one equals the count, and read
// `beyond` indices past the end of INDICES before noticing the decrease.
inline void cacheWithListPastTheEnd(const std::string& in, const std::string& out, uint64_t beyond) {
    Container c = readContainer(in, kCacheFormat);
    const uint64_t m = bytes::load<uint64_t>(c.header.data() + kCacheEntryCountAt);
    for (Section& s : c.sections)
        if (s.kind == kCacheOffsets) bytes::store<uint64_t>(s.bytes, 8, m + beyond);
    writeContainer(c, out, kCacheFormat);
}

}  // namespace hc::hostile
