// heightcast/scenes/scenes.h: synthetic stand-ins for the technical report's four flood scenes, generated
// deterministically (fixed seeds, no input files): hc-bench renders them, tests reuse them.
//
// The report (its performance table) renders four real flood simulations on a GTX 1080:
//   Marchfeld      82.9 x 57.1 km, cells 3 - 96 m,    7.46 M cells: approximation 15.1 ms, ray casting 5.1 ms
//   Petzenkirchen  15.4 x 16.0 km, cells 0.75 - 96 m, 1.81 M cells:                20.8 ms,              4.3 ms
//   Wachau         24.1 x 16.5 km, cells 3 - 96 m,    1.95 M cells:                 5.3 ms,              4.3 ms
//   Florence       44.6 x 28.2 km, cells 3 - 96 m,    4.53 M cells:                 1.5 ms,              2.8 ms
// We do not have those data sets; each Scenario here has the same extents, cell sizes and cell counts:
//   terrain   a smooth landscape: large-scale relief (a few sinusoids of 6-30 km wavelength) rising from a
//             meandering river valley (a flat floodplain with a gentle downstream slope and low undulations,
//             smooth valley sides, a parabolic channel), with smaller hills (plane waves of 150-900 m) on the
//             uplands; hundreds of metres of relief in Wachau and Florence, tens in Marchfeld.
//   water     layer water_depth: a flood level a few metres above the floodplain; depth = level - terrain where
//             positive, 0 where dry. The channel is always wet; the floodplain's undulations make the flood's
//             edge irregular.
//   grid      a quadtree built top-down in Morton order (Grid::appendCell): a node of the domain is split while
//             it is larger than the finest size and (it is coarser than 96 m, or it straddles a wet/dry edge
//             or a channel bank, or the terrain or the water depth varies over it by more than a threshold T,
//             measured at its 3 x 3 corner / edge / centre points). A leaf's values are terrain and depth at its
//             centre. T is one of a fixed set of thresholds (1 mm to 10 km, 0.2 % apart), calibrated per
//             scenario by counting cells at every threshold of the set in one walk of the tree (a node is a leaf
//             for T between its own split value and its ancestors' least one): a fixed sample of 1/8 of the 768 m
//             tiles (all tiles of a small domain) is walked down in T until it holds 1.3x the target, then every
//             tile once from there, which gives the exact count at each threshold above and each tile's count
//             near the target. T is the threshold whose count is nearest the target (the report's count divided
//             by `scale`, or a count asked for): within a fraction of a percent. If even T = 10 km
//             gives too many cells (the forced wet-edge and bank cells alone exceed the target: a large scale),
//             the finest size doubles until it fits (Generated::finestRaised); if the domain holds fewer than
//             1.5 times the count at the finest size (a count above the report's), it halves until it does
//             (Generated::finestLowered). The grid is sized once from the exact count per tile and every tile
//             writes its cells in place: generating holds 16 bytes a cell (code + two floats) and little else,
//             or streams them into a file a batch of tiles at a time (generateToFile).
//   camera    a fixed oblique view a user would pick over the flood: 1.5 km above the river, 10 % of the way
//             downstream, looking 4.1 km along it (where the centre ray meets the valley floor) at pitch -20
//             degrees, 50 degree vertical field of view.
// Local coordinates: metres from the domain's south-west corner, x east (downstream), y north.
#pragma once

#include <cmath>
#include <cstdint>
#include <string>
#include <span>
#include <string_view>
#include <vector>

#include "heightcast/grid/grid.h"
#include "heightcast/influence/kernel.h"
#include "heightcast/render/camera.h"

namespace hc::scenes {

constexpr double kCoarsestM = 96.0;  // every scenario's coarsest cell [m]

// Everything that shapes one synthetic landscape. Lengths in metres, heights in metres above sea level.
struct Landscape {
    double z0;              // floodplain floor at the upstream (west) edge
    double riverSlope;      // floor drop per metre downstream (+x)
    double riverYFraction;  // mean centreline, as a fraction of the extent in y
    double meanderAmp[2], meanderLen[2];
    double floorHalfWidth;  // flat floodplain each side of the centreline
    double sideWidth;       // valley sides, from the floodplain up to the uplands
    double channelHalfWidth, channelDepth;
    double floodHeight;  // water level above the floodplain floor
    double microAmp;     // floodplain undulations (max amplitude)
    double reliefAmp;    // uplands above the floor (mean); large-scale waves add +-50 %
    double hillAmp;      // small-scale hills on the uplands (max amplitude)
    uint64_t seed;
};

struct Scenario {
    const char* name;
    double extentXKm, extentYKm, finestM;
    double reportCellsM;               // the report's cell count, millions
    double gpuApproxMs, gpuRaycastMs;  // the report's GTX 1080 times
    double originX, originY;  // world position of the south-west corner (UTM-like, to exercise the camera maths)
    Landscape land;
};

// The four scenes, in the report's order: Marchfeld, Petzenkirchen, Wachau, Florence.
std::span<const Scenario> scenarios();
// The scenario of that name, or nullptr.
const Scenario* findScenario(std::string_view name);
// The domain's extent [m]: the scenario's, rounded to whole coarsest cells.
double extentXM(const Scenario& sc);
double extentYM(const Scenario& sc);

// The terrain and water of one scenario as smooth functions of the local position [m].
class Terrain {
public:
    explicit Terrain(const Scenario& sc);

    struct Sample {
        float z, depth;  // terrain [m]; water depth [m], 0 where dry
        float bank;      // distance to the nearest channel bank [m] (centreline distance - half width)
    };
    Sample at(double xLocal, double yLocal) const;
    // Centreline y of the river at x [m], and its slope dy/dx.
    void centreline(double xLocal, double& yLocal, double& dydx) const;
    double floorAt(double xLocal) const { return l_.z0 - l_.riverSlope * xLocal; }
    double waterLevelAt(double xLocal) const { return floorAt(xLocal) + l_.floodHeight; }

private:
    struct Wave {  // amp * sin(kx x + ky y + phase)
        double kx, ky, phase, amp;
    };
    static double sum(const std::vector<Wave>& waves, double x, double y);
    Landscape l_;
    double extentY_;
    double meanderPhase_[2] = {};
    std::vector<Wave> large_, hills_, micro_;
};

// How a grid was generated.
struct Calibration {
    double thresholdM = 0;                // the calibrated T
    double calibrationS = 0, buildS = 0;  // wall time finding T, and building the grid
    uint64_t sampleTiles = 0, tiles = 0;
    bool finestRaised = false;   // the finest size was doubled (see the top of this file)
    bool finestLowered = false;  // the finest size was halved (the same)
};

struct Generated : Calibration {
    Grid grid;  // layers elevation and water_depth; origin at the scenario's south-west corner
};

// A grid streamed into a file (generateToFile): what a caller would otherwise read off the grid.
struct GeneratedFile : Calibration {
    Grid shape;  // geometry and layers as Generated::grid, no cells
    uint64_t cells = 0, wetCells = 0;
    std::vector<uint64_t> cellsPerLevel;
    double topM = -HUGE_VAL;  // the highest terrain or water surface [m]
};

// The cell count a scale asks for: the report's count / scale (scale > 0; below 1 is more than the report's).
double targetCells(const Scenario& sc, double scale);
// The scenario's grid with about `targetCells` cells (> 0), on `threads` workers (0 = all cores).
Generated generateCells(const Scenario& sc, double targetCells, unsigned threads);
// The same grid written to the grid file `path` (atomically, with its water as one step), never held whole: tiles are
// built in batches of about `batchCells` cells (at least a tile) and appended in order. Throws hc::Error.
GeneratedFile generateToFile(const Scenario& sc, double targetCells, unsigned threads, const std::string& path,
                             size_t batchCells = size_t(1) << 23);
// generateCells(sc, targetCells(sc, scale), threads).
Generated generate(const Scenario& sc, double scale, unsigned threads);

// The influence lists' size for grid `g` (sigma and R from `params`), estimated before building them, from
// the influencing side: cell i's disk (radius R sigma c_i about its centre) meets the squares of the cells whose
// lists hold i, so the sum of list lengths is the sum over cells of the cells their disks meet; that is counted
// for `sampleCells` cells at a fixed stride (Grid::cellsInDisk) and scaled to every cell. Bytes as
// InfluenceLists::Stats counts them: 8 per offset (cells + 1) and 4 per entry.
struct ListsEstimate {
    double meanLength = 0;  // entries per list
    uint64_t bytes = 0;
};
ListsEstimate estimateInfluenceLists(const Grid& g, const influence::KernelParams& params, size_t sampleCells);

// The fixed oblique camera over the scenario's flood (see the top of this file), for an image of
// width x height pixels; `g` is the scenario's generated grid (its origin places the camera in the world).
render::Camera floodCamera(const Scenario& sc, const Grid& g, int width, int height);

}  // namespace hc::scenes
