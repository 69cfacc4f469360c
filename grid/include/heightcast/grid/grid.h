// heightcast/grid/grid.h: the adaptive quadtree grid, in memory.
//
// Frames and units
//   World: the grid's CRS (crsWkt), metres, x east, y north. Only doubles ever hold world values.
//   Local: metres relative to the domain's south-west corner (originWorld), along the grid's own axes, which may be
//          rotated against the CRS's by rotationDeg (a rotated quadtree model mesh: docs/design.md section 6). Queries
//          take local coordinates, so no absolute coordinate (UTM northings are ~5e6 m) reaches float maths; every
//          world <-> local mapping goes through worldToLocal / localToWorld.
//   Finest units: integers, one per finest cell; cell (ix, iy) covers local
//          [ix * finestCellM, (ix + 2^level) * finestCellM) in x, likewise in y.
//
// The domain is a square of 2^rootLevel finest cells per side. Its leaves that carry data are the
// cells; the rest of the domain is holes (nodata, outside the survey). A hole is never a value.
//
// Storage: one sorted array of packed cell codes (morton.h) and one float32 array per layer,
// 8 + 4 * layers bytes per cell (12 bytes for elevation alone). Layer 0 is always elevation.
//
// Water steps (docs/design.md section 6): a flood scenario is one structure and terrain and any number of water
// steps. The layers from "water_depth" on (firstStepLayer()) are the step layers: in memory they hold ONE step,
// the selected one (`step`), densely (0 where dry); `steps` describes every step of the scenario. Files store a
// step sparsely, its wet cells only (grid_file.h). A grid with a water layer and no `steps` is one step at time 0.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "heightcast/core/checksum.h"
#include "heightcast/grid/morton.h"

namespace hc {

struct LayerInfo {
    std::string name;   // "elevation", "water_depth", "velocity", ...
    std::string units;  // "m", "m/s", ...
};

// One water step of a scenario, as a file describes it (grid_file.h: STEPS).
struct StepInfo {
    double timeS = 0;                       // seconds from the scenario's start; strictly increasing over the steps
    uint64_t wetCells = 0;                  // cells with water_depth > 0: only those store step values
    uint64_t contentHash = 0;               // Grid::contentHash of the grid with this step selected
    std::vector<float> layerMin, layerMax;  // per step layer, over the wet cells (empty when no cell is wet)
};

// What ingest measured when it built the grid (absent fields are NaN / 0 / empty).
struct IngestStats {
    std::string sourcePath;     // the input raster as given
    std::string sourceCrsName;  // the input's CRS name ("" when it had none)
    std::string sourceKind;     // "" for a raster (the working raster and deviation below apply); "UGRID mesh" for a
                                // mesh taken as it is (one cell per face: no working raster, nothing to deviate)
    std::string sourceFormat;  // a flood model's results: the model, format, mesh kind, faces, nodes and steps ("SFINCS
                               // quadtree map (UGRID-1.0): 4226 faces (quadtree), ..."); "" for a raster
    double latticeResidualM = -1;  // a quadtree mesh taken as it is: the largest distance of a node from the fitted
                                   // lattice [m]; < 0 for none
    uint64_t sourceWidth = 0;      // pixels of the working raster (after projection / resampling)
    uint64_t sourceHeight = 0;
    uint64_t validPixels = 0;  // working-raster pixels that carry data
    double toleranceM = 0;     // requested: max |pixel - cell| in every layer
    double maxDevM = 0;        // achieved max |pixel - covering cell value| over every layer
    double rmsDevM = 0;        // achieved RMS of the same, over elevation
    double seconds = 0;  // ingest wall time (printed by hc-ingest; no longer written to the file: its bytes depend on
                         // its inputs only)
};

class Grid {
public:
    // ---- geometry (set before adding cells) ----
    double originWorldX = 0;  // domain's south-west corner in the grid CRS [m]
    double originWorldY = 0;
    double finestCellM = 1;  // size of a level-0 cell [m], > 0
    double rotationDeg = 0;  // counterclockwise angle of the local x axis from the CRS's x (east) axis, about the
                             // origin [degrees], in (-180, 180]; 0 for rasters
    int rootLevel = 0;       // domain side = finestCellM * 2^rootLevel, 0..kMaxRootLevel
    int minLevel = 0;        // every cell's level lies in [minLevel, maxLevel]
    int maxLevel = 0;
    std::string crsWkt;   // "" = local metres with no CRS
    std::string crsName;  // crsWkt's name as ingest's GDAL gave it, "WGS 84 / UTM zone 32N (EPSG:32632)";
                          // "" with no CRS, and in files of format 1.0 (grid_file.h)
    std::vector<LayerInfo> layers{{"elevation", "m"}};
    IngestStats stats;
    std::vector<StepInfo> steps;  // every water step of the scenario; empty: none, or one step at time 0 (above)
    size_t step = 0;              // the step the step layers hold, an index into `steps` (0 when `steps` is empty)

    // ---- cells: codes sorted ascending; values[l][i] is layer l of cell i ----
    std::vector<uint64_t> codes;
    std::vector<std::vector<float>> values{std::vector<float>{}};

    size_t cellCount() const { return codes.size(); }
    size_t layerCount() const { return layers.size(); }
    // Index of a layer by name, or -1.
    int findLayer(const std::string& name) const;
    // The first step layer: the index of "water_depth", or layerCount() when the grid has no water.
    size_t firstStepLayer() const;
    // How many water steps the scenario has: steps.size(), or 1 for a grid with water and no `steps`, else 0.
    size_t stepCount() const;
    // The selected step's time [s] (0 without steps).
    double stepTimeS() const { return step < steps.size() ? steps[step].timeS : 0.0; }

    // World (grid CRS) <-> local frame: local = R(-rotation) (world - origin). Without rotation exactly
    // world - origin (and back), so an axis-aligned grid's figures are those of plain subtraction.
    void worldToLocal(double xWorld, double yWorld, double& xLocal, double& yLocal) const;
    void localToWorld(double xLocal, double yLocal, double& xWorld, double& yWorld) const;
    // A direction (a vector, no origin) from local to world axes, and back.
    void localToWorldDir(double dx, double dy, double& wx, double& wy) const;
    void worldToLocalDir(double wx, double wy, double& dx, double& dy) const;
    double domainSizeM() const { return finestCellM * static_cast<double>(uint64_t{1} << rootLevel); }
    double cellSizeM(size_t i) const { return levelSizeM(codeLevel(codes[i])); }
    double levelSizeM(int level) const { return finestCellM * static_cast<double>(uint64_t{1} << level); }
    int level(size_t i) const { return codeLevel(codes[i]); }
    // A cell's closed square, local frame [m]. Every query and every test uses these edges.
    struct Square {
        double x0, y0, x1, y1;
    };
    Square cellSquare(size_t i) const;
    // South-west corner and centre of cell i, local frame [m].
    void cellMinLocal(size_t i, double& x, double& y) const;
    void cellCenterLocal(size_t i, double& x, double& y) const;

    // Appends a cell; cells must arrive in strictly increasing code order (asserted).
    void appendCell(uint32_t ix, uint32_t iy, int level, const float* layerValues);

    // ---- queries (local frame, metres) ----
    // The cell whose half-open square [min, min + size) contains (x, y), or nullopt for a hole or a
    // point outside the domain. O(log n).
    std::optional<uint32_t> locate(double xLocal, double yLocal) const;
    // The Morton key of the finest cell whose half-open square contains (x, y), with locate()'s edge rule, or
    // nullopt outside the domain (geometry only: no cells needed).
    std::optional<uint64_t> finestKeyAt(double xLocal, double yLocal) const;
    // Appends to `out` every cell whose closed square meets the closed box. O(log n + k) per
    // quadtree level touched by the box boundary.
    void cellsInBox(double xMin, double yMin, double xMax, double yMax, std::vector<uint32_t>& out) const;
    // Appends every cell whose closed square meets the closed disk (centre, radius).
    void cellsInDisk(double cx, double cy, double radius, std::vector<uint32_t>& out) const;
    // Appends the cells whose squares touch cell i's square (share an edge or a corner), i excluded.
    void neighbours(uint32_t i, std::vector<uint32_t>& out) const;

    // Counts of cells per level, index = level (size maxLevel + 1).
    std::vector<uint64_t> cellsPerLevel() const;
    // Bounding box (local) of all cells; all zero for an empty grid.
    void boundsLocal(double& xMin, double& yMin, double& xMax, double& yMax) const;

    // Identity of the tree alone (geometry + codes): influence caches key on it, so a new water
    // time step on the same tree reuses its cache.
    uint64_t structureHash() const;
    // Identity of everything the surface depends on (structure + layer names + values).
    uint64_t contentHash() const;

    // Checks every invariant (sorted, aligned, inside the domain, no overlap, levels in range,
    // sizes consistent, finite values). Returns "" when valid, else what is wrong.
    std::string validate() const;
    // The geometry and layer rules alone (what a streaming writer needs before any cell).
    std::string validateShape() const;

    // Position in finest units of cell i's south-west corner.
    static uint32_t keyX(uint64_t code) { return mortonX(codeKey(code)); }
    static uint32_t keyY(uint64_t code) { return mortonY(codeKey(code)); }

private:
    Square squareOf(uint64_t key, int level) const;
    template <typename Pred, typename Emit>
    void visitNodes(Pred&& nodeMeets, Emit&& emit, std::vector<uint32_t>& out) const;
};

// The rules of Grid::validate() for cells that arrive one at a time (writers that never hold a whole
// grid). `shape` supplies the geometry and layers; its own cells are ignored.
class CellStreamCheck {
public:
    explicit CellStreamCheck(const Grid& shape) : shape_(shape) {}
    // "" if the cell may follow the ones before it, else what is wrong with it.
    std::string next(uint64_t code, const float* layerValues);
    // A batch of cells (layerValues: an array per layer, as long as codes): "" if they may all follow the ones before,
    // else what is wrong with the first that may not (the state then as next() leaves it there). One tight loop for the
    // cells that pass; next() words the problem.
    std::string nextBatch(std::span<const uint64_t> codes, const std::vector<std::span<const float>>& layerValues);
    uint64_t count() const { return count_; }
    // Where the cells so far leave the check, so that another process can check the cells after them (GridFilePart).
    struct State {
        uint64_t nextFree = 0, count = 0;
    };
    State save() const { return {nextFree_, count_}; }
    void resume(const State& s) { nextFree_ = s.nextFree, count_ = s.count; }

private:
    const Grid& shape_;
    uint64_t nextFree_ = 0;  // first key not covered by the previous cell
    uint64_t count_ = 0;
};

// A grid's two hashes (Grid::structureHash, Grid::contentHash) as known without hashing its cells again (each costs a
// pass over every cell): from a file that checked them when it was read, or computed once for many uses.
struct GridHashes {
    uint64_t structure = 0, content = 0;
};

// Grid::structureHash and Grid::contentHash, computed incrementally: codes in order, and each
// layer's values in order (layers may interleave).
class GridHasher {
public:
    GridHasher(const Grid& shape, uint64_t cellCount);
    void addCodes(std::span<const uint64_t> codes);
    void addValues(size_t layer, std::span<const float> values);
    uint64_t structureHash() const;
    uint64_t contentHash() const;
    uint64_t layerDigest(size_t layer) const { return layers_[layer].digest(); }
    // The running hashes (structure, then each layer), for another process to go on with (GridFilePart).
    std::vector<Hash64::State> save() const;
    void resume(const std::vector<Hash64::State>& states);  // throws hc::Error unless 1 + layers states

private:
    const Grid& shape_;
    Hash64 structure_;
    std::vector<Hash64> layers_;
};

// Grid::contentHash from its parts: the structure hash, then per layer in order its name and the Hash64 digest of
// its values (GridHasher's rule; lets a file compute the hash of each water step without holding the step densely).
uint64_t combineContentHash(uint64_t structureHash, std::span<const std::pair<std::string, uint64_t>> layerDigests);
// The Hash64 digest of a dense layer of `cellCount` values that are 0 except at the ascending indices `at`.
uint64_t sparseLayerDigest(uint64_t cellCount, std::span<const uint32_t> at, std::span<const float> values);

}  // namespace hc
