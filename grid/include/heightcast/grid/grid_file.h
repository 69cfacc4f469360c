// heightcast/grid/grid_file.h: the .hcg grid file format, version 1.1 (reads 1.0).
//
// A sectioned container (sectioned_file.h: magic, version, declared size, CRC-32 of header, table
// and every section, 64-byte aligned sections, zero padding checked). The grid's own header fields:
//
//   offset  size  field
//   0       8     magic "\x89HCGRID\n" (high bit and line end catch 7-bit and text-mode damage)
//   24      8     cell count
//   32      8     origin x, world [m], double
//   40      8     origin y, world [m], double
//   48      8     finest cell size [m], double
//   56      1     root level (domain = finest * 2^root per side)
//   57      1     min level
//   58      1     max level
//   59      1     layer count (1 = elevation only)
//   64      8     content hash (Grid::contentHash)
//   72      8     structure hash (Grid::structureHash)
//   80      40    reserved, zero
//
// Sections, in file order: CELLS (kind 2: u64 cell codes, sorted), LAYER (kind 3, index = layer:
// float32 values, one section per layer), META (kind 1: u32-length-prefixed key/value strings:
// crs_wkt, crs_name, layer.N.name, layer.N.units, ingest.*). Readers locate sections by the table, not by order.
//
// Versions (a newer minor only adds what an older reader skips: sectioned_file.h):
//   1.0  the layout above, META without crs_name
//   1.1  META key crs_name (Grid::crsName); read from a 1.0 file as ""
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
constexpr uint16_t kGridFileMinor = 1;
constexpr uint32_t kGridHeaderBytes = 128;

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

// Reads (memory-mapped) and fully validates a grid file: header, section table, every checksum,
// every cell invariant, both hashes. Throws hc::Error naming the file, the byte offset and the problem.
// `fileMinor`, when given, receives the file's minor version (a newer minor than kGridFileMinor is
// read: it only adds sections this reader skips).
Grid readGrid(const std::string& path, uint16_t* fileMinor = nullptr);

}  // namespace hc
