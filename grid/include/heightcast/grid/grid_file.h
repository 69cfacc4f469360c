// heightcast/grid/grid_file.h: the .hcg grid file format, version 1.0.
//
// Little-endian throughout; no pointers; every byte is covered by a checksum or checked to be zero.
//
//   offset  size  field
//   0       8     magic "\x89HCGRID\n" (high bit and line end catch 7-bit and text-mode damage)
//   8       2     major version (1): a reader refuses a newer major
//   10      2     minor version (0): a newer minor only adds sections or META keys a reader may skip
//   12      4     header bytes (128)
//   16      8     file bytes: must equal the file's length (truncation check)
//   24      8     cell count
//   32      8     origin x, world [m], double
//   40      8     origin y, world [m], double
//   48      8     finest cell size [m], double
//   56      1     root level (domain = finest * 2^root per side)
//   57      1     min level
//   58      1     max level
//   59      1     layer count (1 = elevation only)
//   60      4     section count
//   64      8     content hash (Grid::contentHash)
//   72      8     structure hash (Grid::structureHash)
//   80      40    reserved, zero
//   120     4     CRC-32 of the section table
//   124     4     CRC-32 of bytes 0..123
//   128     32*S  section table: { u32 kind, u32 index, u64 offset, u64 bytes, u32 crc32, u32 zero }
//   ...           sections, each at a 64-byte aligned offset (mmap- and SIMD-friendly), zero padding
//
// Sections, in file order: CELLS (kind 2: u64 cell codes, sorted), LAYER (kind 3, index = layer:
// float32 values, one section per layer), META (kind 1: u32-length-prefixed key/value strings:
// crs_wkt, layer.N.name, layer.N.units, ingest.*). Readers locate sections by the table, not by order.
//
// Hashes: structure = Hash64 over (finest size f64, root level i32, cell count u64, codes);
// content = Hash64 over (structure hash, then per layer its name + NUL and Hash64 of its values).
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "heightcast/grid/grid.h"

namespace hc {

constexpr uint16_t kGridFileMajor = 1;
constexpr uint16_t kGridFileMinor = 0;
constexpr uint32_t kGridHeaderBytes = 128;
constexpr uint32_t kGridSectionEntryBytes = 32;
constexpr uint32_t kGridSectionAlign = 64;

// Writes `grid` to `path` atomically (temporary file + rename). Throws hc::Error on I/O failure or if
// the grid is invalid (Grid::validate), leaving no file behind.
void writeGrid(const Grid& grid, const std::string& path);

// Streams a grid to a file without ever holding it: cells arrive in order, in batches of any size,
// straight to their final place; CRCs, hashes and every cell invariant are computed on the way.
// Nothing appears under `path` unless commit() succeeds. Throws hc::Error.
class GridFileWriter {
public:
    // `shape` gives geometry, CRS and layers (its cells, if any, are ignored).
    GridFileWriter(const std::string& path, const Grid& shape, uint64_t cellCount);
    ~GridFileWriter();
    GridFileWriter(const GridFileWriter&) = delete;
    GridFileWriter& operator=(const GridFileWriter&) = delete;

    // Next cells in Morton order; layerValues[l][i] is layer l of codes[i].
    void append(std::span<const uint64_t> codes, const std::vector<std::span<const float>>& layerValues);
    // After exactly cellCount cells: writes the statistics, header and table, and renames into place.
    void commit(const IngestStats& stats);

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// Reads and fully validates a grid file: header, section table, every checksum, every cell
// invariant, both hashes. Throws hc::Error naming the file, the byte offset and the problem.
Grid readGrid(const std::string& path);

}  // namespace hc
