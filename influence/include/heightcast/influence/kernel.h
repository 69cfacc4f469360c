// heightcast/influence/kernel.h: the truncated Gaussian of docs/design.md section 3 (report eq. 1).
//
//   w_i(p) = max(0, exp(-(|p_i - p| / c_i)^2 / (2 sigma^2)) - exp(-R^2 / 2))
//
// p_i the centre and c_i the size of cell i [m]; sigma (default 1.0, the report's) and the
// truncation R (default 3.5) are dimensionless. The weight reaches zero at |p_i - p| = R sigma c_i,
// so a cell's influence is an open disk of that radius. Every evaluator (exact, CPU, GL) uses these
// definitions; the influence lists use exactly kernelReaches().
#pragma once

#include <cmath>
#include <cstdint>
#include <string>

namespace hc::influence {

// Kernel ids stored in caches: a cache built for another kernel is refused.
constexpr uint32_t kKernelTruncatedGaussian = 1;

struct KernelParams {
    double sigma = 1.0;       // Gaussian width in cell sizes, > 0
    double truncation = 3.5;  // R: the kernel is cut at R sigma cell sizes
    uint32_t kernelId = kKernelTruncatedGaussian;

    // Radius of a cell's influence disk [m].
    double radiusM(double cellSizeM) const { return truncation * sigma * cellSizeM; }
    // exp(-R^2 / 2): subtracted so the weight is continuous (zero) at the truncation radius.
    double tail() const { return std::exp(-0.5 * truncation * truncation); }
    // "" when usable, else why not: every point of a cell must get a positive weight from the cell
    // itself (the farthest point of its square is sqrt(2)/2 cell sizes from its centre), or the
    // normalising denominator could vanish inside the grid.
    std::string validate() const;
};

inline std::string KernelParams::validate() const {
    if (!(sigma > 0) || !std::isfinite(sigma)) return "sigma must be a positive number";
    if (!(truncation > 0) || !std::isfinite(truncation)) return "truncation R must be a positive number";
    if (truncation * sigma <= std::sqrt(0.5))
        return "R * sigma must exceed sqrt(2)/2 = 0.7071 so that each cell's kernel covers its own square";
    return {};
}

// Does the disk of a cell centred at (cx, cy) with squared radius r2 reach into the closed square
// [x0, x1] x [y0, y1] with a positive weight? (Strict: at exactly the radius the weight is zero.)
inline bool kernelReaches(double cx, double cy, double r2, double x0, double y0, double x1, double y1) {
    const double ax = x0 - cx, bx = cx - x1, ay = y0 - cy, by = cy - y1;
    double dx = ax > bx ? ax : bx;  // distance to the square along x (0 inside its x range)
    double dy = ay > by ? ay : by;
    dx = dx > 0.0 ? dx : 0.0;
    dy = dy > 0.0 ? dy : 0.0;
    return dx * dx + dy * dy < r2;
}

}  // namespace hc::influence
