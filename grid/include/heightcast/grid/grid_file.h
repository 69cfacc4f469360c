// heightcast/grid/grid_file.h: the .hcg grid file format, version 1.3 (reads 1.0 to 1.2).
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
//   59      1     layer count: the static LAYER sections (1 = elevation only; the step layers are not counted)
//   64      8     content hash (Grid::contentHash; with water steps (1.3) the scenario's: below)
//   72      8     structure hash (Grid::structureHash)
//   80      8     (1.3) rotation [degrees], double: Grid::rotationDeg, 0 for rasters; zero bytes before 1.3
//   88      32    reserved, zero
//
// Sections, in file order: CELLS (kind 2: u64 cell codes, sorted), LAYER (kind 3, index = layer:
// float32 values, one section per layer), (1.3) STEP and STEPS (water steps), META (kind 1: u32-length-prefixed
// key/value strings: crs_wkt, crs_name, layer.N.name, layer.N.units, layer.N.min, layer.N.max, summary.*, ingest.*),
// then (1.2) the container's block checksums. Readers locate sections by the table, not by order. ingest.source_kind
// ("UGRID mesh") is written only for a grid not made from a raster; its absence means a raster.
//
// The summary (1.2), written as the cells stream past, so a reader need not read them (readGridInfo):
//   summary.cells_per_level  "n0 n1 ... nMax": cells per level 0..max level, decimal, space-separated
//   summary.bounds_finest    "x0 y0 x1 y1": bounding box of the cells in finest cells (local frame / finest
//                            cell size; "0 0 0 0" for an empty grid)
//   layer.N.min, layer.N.max the least and greatest value of layer N (shortest exact decimal of the float32;
//                            absent in an empty grid)
//
// Water steps (1.3, docs/design.md section 6). The layers from water_depth on are the step layers
// (Grid::firstStepLayer); they are not LAYER sections. META holds step_layers (their count L) and step_layer.N.name /
// .units. Then:
//   STEP  (kind 5, index = step k): the wet cells of step k (water_depth > 0), u32 ascending cell indices, then per
//         step layer one f32 per wet cell (water_depth first): 4 * wet * (1 + L) bytes. Dry cells store nothing and
//         read as 0. Grids with steps hold at most 2^32 - 1 cells.
//   STEPS (kind 4, index 0): per step, 24 + 8 * L bytes: time [s] f64 (finite, strictly increasing), wet cells u64,
//         the content hash of the grid with that step selected u64 (what influence data of that step keys on), and per
//         step layer its min and max f32 over the wet cells (0 0 when none is wet).
// A reader selects one step and reads that step's section only (lazily: rendering step k touches step k). The header's
// content hash is then Hash64 over the static grid's content hash and every step's (time, hash).
//
// Versions (byte tables: docs/formats/hcg.md). A newer minor is read; an older reader misses what it added, and a
// 1.2 reader refuses a rotated 1.3 grid (reserved bytes) and a 1.3 grid with steps (its content hash):
//   1.0  the layout above, META without crs_name
//   1.1  META key crs_name (Grid::crsName); read from a 1.0 file as ""
//   1.2  block checksums (sectioned_file.h: a CRC-32 per 1 MiB, checked when first read) and the summary
//        in META; a 1.0/1.1 file has neither: readGridInfo reads it whole
//   1.3  water steps (STEP, STEPS, META step_layer*); water is no longer a LAYER; the rotation at byte 80. A 1.2 file's
//   water_depth LAYER reads
//        as a grid with water and no steps (one step at time 0)
//
// Hashes: structure = Hash64 over (finest size f64, root level i32, cell count u64, codes);
// content = Hash64 over (structure hash, then per layer its name + NUL and Hash64 of its values).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "heightcast/grid/grid.h"

namespace hc {

constexpr uint16_t kGridFileMajor = 1;
constexpr uint16_t kGridFileMinor = 3;
constexpr uint32_t kGridHeaderBytes = 128;

// One water step as a file stores it: its wet cells only.
struct WaterStepData {
    double timeS = 0;                        // [s]
    std::vector<uint32_t> wet;               // ascending indices of the cells with water_depth > 0
    std::vector<std::vector<float>> values;  // [step layer][j]: the value at cell wet[j]; layer 0 is water_depth (> 0)
};
// The selected step of a grid (its dense step layers) in stored form.
WaterStepData sparseStep(const Grid& grid);
// Fills the grid's step layers (dense, 0 where dry) from a step's stored form; `step` becomes grid.step.
void selectStep(Grid& grid, const WaterStepData& data, size_t step);

// Writes `grid` to `path` atomically (temporary file + rename). Throws hc::Error on I/O failure or if
// the grid is invalid (Grid::validate), leaving no file behind. A grid with water is written with one step: the
// selected one, at its time (GridFileWriter writes scenarios of many steps).
void writeGrid(const Grid& grid, const std::string& path);

// Streams a grid to a file without ever holding it: cells arrive in order, in batches of any size,
// straight to their final place; CRCs, hashes and every cell invariant are computed on the way.
// Nothing appears under `path` unless commit() succeeds. Throws hc::Error.
class GridFileWriter {
public:
    // `shape` gives geometry, CRS and layers (its cells, if any, are ignored); `stepCount` water steps follow the
    // cells (appendStep) when the shape has step layers (Grid::firstStepLayer), at least 1 then.
    GridFileWriter(const std::string& path, const Grid& shape, uint64_t cellCount, size_t stepCount = 0);
    ~GridFileWriter();
    GridFileWriter(const GridFileWriter&) = delete;
    GridFileWriter& operator=(const GridFileWriter&) = delete;

    // Next cells in Morton order; layerValues[l][i] is static layer l (those before firstStepLayer) of codes[i].
    void append(std::span<const uint64_t> codes, const std::vector<std::span<const float>>& layerValues);
    // The next water step, after all cells: times strictly increasing, indices ascending and below the cell count,
    // water_depth > 0 and every value finite (checked). Written straight to the file: one step in memory at a time.
    void appendStep(const WaterStepData& step);
    // After exactly cellCount cells and stepCount steps: writes the statistics, header and table, and renames
    // into place.
    void commit(const IngestStats& stats);

    // Under mpirun (docs/design.md section 7) the other ranks write their own runs of cells, after this writer's own
    // append()ed ones and in rank order, straight into its temporary (GridFilePart over placement(), which must lie on
    // a file system every rank sees). The hashes and the order check's seam run on from run to run: streamState() is
    // where the cells appended here leave them, for the first part to go on from; addPart() takes each part's result in
    // order (its block checksums, its cells' summary, the state after them). A part's cells count for commit() as
    // appended ones.
    std::vector<std::byte> placement() const;
    std::vector<std::byte> streamState() const;
    void addPart(std::span<const std::byte> part);

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// One rank's run of cells in a grid file that rank 0's GridFileWriter writes (under mpirun; GridFileWriter::placement).
// append() checks, summarises and writes the run's cells at their place in the file (every rank at once); then, rank
// by rank, resume() takes the state the runs before left (the hashes, the last cell's end), follow() hashes the run's
// cells from it, read back from the file, and state() passes it on (the only part that runs in turn: the hashes are one
// stream over the whole file); finish() flushes the run and returns what the writer's addPart() takes. Nothing of it is
// a file until the writer commits; the writer removes the temporary if it does not.
class GridFilePart {
public:
    // `shape`: the one the writer was given (geometry, layers; no cells); this run's first cell is `firstCell`.
    GridFilePart(std::span<const std::byte> placement, const Grid& shape, uint64_t firstCell);
    ~GridFilePart();
    GridFilePart(const GridFilePart&) = delete;
    GridFilePart& operator=(const GridFilePart&) = delete;

    // The run's next cells: checked as GridFileWriter::append checks them (throws hc::Error naming the cell),
    // summarised, written.
    void append(std::span<const uint64_t> codes, const std::vector<std::span<const float>>& layerValues);
    // The state after the cells before this run (the writer's streamState() or the previous part's state()): it must
    // count exactly firstCell cells, and this run's first cell must not overlap the last of them.
    void resume(std::span<const std::byte> state);
    // Every cell append()ed, read back from the temporary (a run's own writes: in its page cache) and hashed in order,
    // so that nothing of the run is held between append() and its turn.
    void follow();
    // The state after this run's cells, for the next; throws unless every cell appended was followed.
    std::vector<std::byte> state() const;
    // After state() was reached: flushes (fsync) and returns the part for GridFileWriter::addPart.
    std::vector<std::byte> finish();

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// Reads (memory-mapped) and fully validates a grid file: header, section table, every checksum,
// every cell invariant, both hashes. Throws hc::Error naming the file, the byte offset and the problem.
// `fileMinor`, when given, receives the file's minor version (a newer minor than kGridFileMinor is
// read, skipping the sections it does not know).
// A file with water steps is read with step `step` selected (0 by default); the other steps' sections are not read.
Grid readGrid(const std::string& path, uint16_t* fileMinor = nullptr, size_t step = 0);

// Replaces the step layers of `grid` (read from `path` by readGrid) with step `step`'s, reading only that step's
// section; checks the step's content hash. Switching steps of a grid in memory (hc-influence, hc-view) costs one
// step's bytes, not the grid's. Throws hc::Error naming the file (and leaves `grid` as it was).
// The check needs the grid's structure hash and its static layers' digests: passes over every cell, the whole grid's
// cost and not one step's. A caller that switches often computes them once (staticDigestsOf, while the cells and
// static values stay as read) and passes them as `known`; the step's content hash is then checked from them and the
// step's values.
struct StaticDigests {
    uint64_t structureHash = 0;
    std::vector<std::pair<std::string, uint64_t>> layers;  // name and Hash64 digest of each static layer
};
StaticDigests staticDigestsOf(const Grid& grid);
void readGridStep(const std::string& path, Grid& grid, size_t step, const StaticDigests* known = nullptr);

// What a full pass over the cells would tell (stored in META from format 1.2 on).
struct GridSummary {
    std::vector<uint64_t> cellsPerLevel;     // index: level 0..maxLevel
    std::array<uint64_t, 4> boundsFinest{};  // x0, y0, x1, y1 [finest cells, local frame]; zero when empty
    std::vector<float> layerMin, layerMax;   // per layer; empty for a grid without cells
};

// A grid file's header, META and summary.
struct GridFileInfo {
    Grid shape;  // geometry, CRS, layers, ingest statistics, steps (shape.step selected); no cells
    uint64_t cellCount = 0;
    uint16_t fileMinor = 0;
    uint64_t fileBytes = 0;
    uint64_t blockBytes = 0;                      // of the block checksums; 0 for a 1.0/1.1 file (one CRC per section)
    uint64_t structureHash = 0, contentHash = 0;  // as the header stores them (recomputed only when verified); with
                                                  // steps, contentHash is the selected step's (STEPS)
    GridSummary summary;                          // layer ranges: the static layers' and the selected step's
    bool verified = false;             // every checksum, cell invariant, hash and the summary checked against the cells
    uint64_t bytesChecked = 0;         // section bytes whose checksums were checked
    std::shared_ptr<const Grid> grid;  // the whole grid, from verifyGridFile only
};

// Header, META and summary without reading CELLS or LAYER data: what open checks (sectioned_file.h:
// header, table, placement, padding, block checksum table) plus META's checksum and its fields. Cells and
// values are NOT verified (verified = false). A 1.0/1.1 file stores no summary: it is then read and
// validated whole, as readGrid does (verified = true). Throws hc::Error naming the file and byte offset.
GridFileInfo readGridInfo(const std::string& path, size_t step = 0);

// Everything readGrid checks (every block checksum, every cell invariant, both hashes) and, from 1.2 on,
// that the stored summary matches the cells, and every water step (its section, ranges and content hash); returns
// the summary computed from the cells and the grid, with step `step` selected.
GridFileInfo verifyGridFile(const std::string& path, size_t step = 0);

// A grid file read a region at a time, never whole (out of core, docs/design.md section 4): the tools that work on
// part of a grid too large to hold (hc-probe, hc-render) keep one of these instead of the grid. Opening reads
// only what readGridInfo reads. A region reads the cells it returns and the codes its binary searches
// touch, checking the block checksums of exactly those bytes (each block once, sectioned_file.h), and validates
// the cells it returns (Grid::validate). Thread-safe: regions may be read from several threads at once.
class GridRegionReader {
public:
    // Regions carry water step `step` (out of range: hc::Error naming the file and the step count).
    explicit GridRegionReader(const std::string& path, size_t step = 0);  // throws hc::Error naming the file
    ~GridRegionReader();
    GridRegionReader(const GridRegionReader&) = delete;
    GridRegionReader& operator=(const GridRegionReader&) = delete;

    const std::string& path() const;
    const GridFileInfo& info() const;  // shape (no cells), cell count, stored hashes and summary
    const Grid& shape() const { return info().shape; }
    uint64_t cellCount() const { return info().cellCount; }

    // Every cell whose closed square meets the closed box grown by marginM[level of the cell] (levels past the
    // span's end: the last margin; an empty span: 0), as a grid of the file's geometry, CRS and layers (its hashes
    // are the region's own, not the file's). Cells come in file order. Throws hc::Error naming the file and
    // the byte offset if a block read is damaged or the cells break an invariant.
    // `runs` (optional) gets the file's cell index ranges [lo, hi) the region's cells came from, ascending: region cell
    // k is file cell lo + k - (cells of the runs before), for builders that name cells by their index in the file.
    Grid region(const Grid::Square& box, std::span<const double> marginM = {},
                std::vector<std::pair<uint64_t, uint64_t>>* runs = nullptr) const;
    // The square of the cell containing a local point (Grid::locate's rule), or nullopt: one binary search.
    std::optional<Grid::Square> cellSquareAt(double xLocal, double yLocal) const;
    // How many cells meet the quadtree node of `level` with corner key `key`: those inside it, and the one coarser
    // cell that may contain it (two binary searches). 0: the node is all hole.
    uint64_t cellsInNode(uint64_t key, int level) const;
    // Appends to `out` the codes of the cells inside that node (not a coarser one containing it), ascending.
    void codesInNode(uint64_t key, int level, std::vector<uint64_t>& out) const;
    // Section bytes whose block checksums have been checked so far.
    uint64_t bytesChecked() const;
    // Drops the file's pages from this process's resident memory; they stay in the page cache, and a later region
    // reads them back from it. A builder that walks the grid a region at a time calls it between regions, so that
    // its memory follows a region, not all of the file it has walked (hc-influence --no-lists: docs/benchmarks.md).
    void releasePages() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace hc
