// heightcast/influence/region.h: the exact smooth surface over part of a grid that is never held whole
// (docs/design.md section 4, out of core): the cells whose kernels reach a box, read from the grid file, with their
// influence lists built on the spot. No whole-grid list cache is needed.
//
// Exactness: the weight of a cell is exactly 0 beyond its kernel radius (kernel.h), and a region holds every
// cell whose square lies within that radius of the box. So at a point of the box the cells left out weigh 0,
// the region's list of the cell containing the point holds the same cells of positive weight in the same order
// (each level's cells in Morton order, finer levels first: influence.h), and SurfaceEvaluator over a region
// returns the same bits as over the whole grid and its lists (tests/region_test.cpp checks it on real data).
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "heightcast/grid/grid.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/influence/influence.h"
#include "heightcast/influence/kernel.h"
#include "heightcast/influence/surface.h"

namespace hc::influence {

// Per level 0..rootLevel of `shape`: the kernel radius of a cell of that level [m], the margin a region of
// the surface reads around its box.
std::vector<double> kernelReachM(const Grid& shape, const KernelParams& params);

struct SurfaceRegion {
    Grid grid;             // the cells whose kernels may reach the box (file order)
    InfluenceLists lists;  // theirs, built on `threads` workers: complete for every point of the box
};

// The cells of `file` the surface needs over the closed box (local frame [m]) and their lists. Throws hc::Error.
SurfaceRegion readSurfaceRegion(const GridRegionReader& file, const Grid::Square& box, const KernelParams& params,
                                unsigned threads = 0);

// What valuesFromFile read.
struct RegionReadStats {
    uint64_t regions = 0;        // groups of points, one region read each
    uint64_t cellsRead = 0;      // cells over all regions (a cell near two groups counts twice)
    uint64_t largestRegion = 0;  // cells of the largest region: what bounds the memory
};

// The layer at many points (local frame [m]) of a grid file, as SurfaceEvaluator::values gives it over the whole
// grid (the same bits), in the input order; nullopt where the surface is undefined. Points are grouped by
// quadtree node, at most kRegionPoints points and kRegionCells cells of the file a group, and each group's region
// read, evaluated and dropped in turn: memory follows the group, not the grid.
constexpr uint64_t kRegionPoints = 1u << 16;
constexpr uint64_t kRegionCells = 1u << 18;
std::vector<std::optional<double>> valuesFromFile(const GridRegionReader& file,
                                                  std::span<const std::array<double, 2>> pointsLocal,
                                                  const Layer& layer, const KernelParams& params, unsigned threads = 0,
                                                  RegionReadStats* stats = nullptr);

}  // namespace hc::influence
