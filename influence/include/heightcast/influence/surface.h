// heightcast/influence/surface.h: the exact smooth surface (docs/design.md section 3), the reference
// every faster path is tested against.
//
//   v(p) = sum_i w_i(p) v_i / sum_i w_i(p)     over the influence list of the cell containing p
//
// in double precision (evaluated relative to the containing cell's value: surface.cpp). Outside every cell (holes,
// outside the domain) the surface is undefined: std::nullopt, never 0, never NaN. Inside a cell the cell's own weight
// is at least exp(-1 / (4 sigma^2)) - exp(-R^2 / 2) > 0, so the denominator cannot vanish.
#pragma once

#include <array>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "heightcast/grid/grid.h"
#include "heightcast/influence/influence.h"

namespace hc::influence {

// What to evaluate. Elevation and any other grid layer are smoothed cell values (section 4). With a
// water_depth layer, water is the water level field of docs/design.md section 6, built from wet cells only
// (wet: depth > 0), normalised over the wet weights:
//
//   level(p) = sum_{wet i} w_i(p) (z_i + d_i) / sum_{wet i} w_i(p)
//
// so a flood whose cells all lie at one level L is exactly L wherever it is drawn (dry neighbours bring
// no terrain into it). Water is drawn at p when both
//   - wet cells dominate the weights: sum_{wet i} w_i(p) >= 1/2 sum_i w_i(p) (kWetShareMin), and
//   - the level lies above the smooth terrain z(p) (section 4's elevation).
// WaterSurface is level(p) there and undefined elsewhere; WaterDepth is level(p) - z(p) there and 0 on
// dry land (undefined only in holes and outside the grid, like the elevation).
// A further step layer (after water_depth: velocity magnitude, ..., docs/design.md section 6) has values on wet cells
// only, so it is a WaterCells field: the wet cells' values normalised over the wet weights, as the level is,
//
//   u(p) = sum_{wet i} w_i(p) u_i / sum_{wet i} w_i(p)
//
// defined where water is drawn (the two conditions above) and undefined elsewhere (dry cells bring no zeros in).
struct Layer {
    enum Kind { Cells, WaterSurface, WaterDepth, WaterCells } kind = Cells;
    size_t index = 0;  // grid layer, for Cells and WaterCells

    // "elevation", any other layer name, or "water_surface" / "water_depth" (the water level field
    // above; a grid without a water_depth layer has neither). Throws hc::Error naming the layers the grid
    // has when it has no such layer.
    static Layer byName(const Grid& grid, const std::string& name);
};

// The wet weight share from which water is drawn (docs/design.md section 6): at least half the weight at a
// point comes from wet cells. Every evaluator (exact, batch, CPU and GL approximation) uses it.
constexpr double kWetShareMin = 0.5;

struct ValueGradient {
    double value;   // [layer units]
    double dx, dy;  // d value / d x, d value / d y [layer units per metre]
};

class SurfaceEvaluator {
public:
    // Both must outlive the evaluator. Throws hc::Error if the lists are not the grid's.
    SurfaceEvaluator(const Grid& grid, const InfluenceLists& lists);

    std::optional<double> value(double xLocal, double yLocal, const Layer& layer) const;
    std::optional<ValueGradient> valueGradient(double xLocal, double yLocal, const Layer& layer) const;
    // Many points at once (what hc-probe does): each point is located, the points are evaluated in the
    // grid's storage order (neighbouring points share cache lines of lists and cells: much faster than
    // random order, docs/benchmarks.md) on `threads` workers, and the results come back in the input order.
    std::vector<std::optional<double>> values(std::span<const std::array<double, 2>> pointsLocal, const Layer& layer,
                                              unsigned threads = 0) const;
    // The same by brute force over every cell (tests only: O(n) per point).
    std::optional<double> valueBruteForce(double xLocal, double yLocal, const Layer& layer) const;

    const Grid& grid() const { return grid_; }

private:
    // Weighted sums at p over cell k's list of v_i - base: v the grid layer `l`; or, with `depth`, over the wet
    // cells only (d_i > 0), of the water level z_i + d_i (l = 0, addDepth) or of layer l's values. Also the gradient
    // sums if asked.
    void sums(size_t k, double x, double y, size_t l, const float* depth, bool addDepth, double base, double& num,
              double& den, double* dnum, double* dden) const;
    // The level (or, with l > 0, layer l's value) of cell k if it is wet, else of the first wet cell of its list;
    // NaN if none is wet.
    double levelBase(size_t k, size_t l = 0) const;
    std::optional<ValueGradient> evaluate(double x, double y, const Layer& layer, bool gradient) const;

    const Grid& grid_;
    const InfluenceLists& lists_;
    double tail_;
    // Per cell, packed in one record so a random list entry costs one cache line, not four:
    // centre [m local], squared radius, 1 / (2 sigma^2 c^2).
    struct Kernel {
        double cx, cy, r2, a;
    };
    std::vector<Kernel> k_;
    int depthLayer_ = -1;
};

}  // namespace hc::influence
