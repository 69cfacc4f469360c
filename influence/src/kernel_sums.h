// influence/src/kernel_sums.h: the weighted sums of the exact evaluators' batch paths (SurfaceEvaluator::values in
// surface.cpp, the surface pyramid's builder in pyramid.cpp), in double, vectorised across candidate cells: the
// candidates gathered once into a structure of arrays, then summed at every point that shares them. Compile the
// callers with -fno-trapping-math (influence/CMakeLists.txt) or the masked loop does not vectorise.
#pragma once

#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace hc::influence::detail {

// exp(x) for x in [-745, 0], branch-free so that loops over it vectorise (std::exp is a call per
// element). Cody-Waite reduction x = n ln2 + r, |r| <= ln2 / 2, then exp(r) by its Taylor polynomial
// to degree 13 (truncation error < 2e-17 relative, below double's epsilon) and 2^n from exponent bits.
// Within 2 ulp of std::exp over the range the kernel uses (tested in influence_test).
inline double expNonPositive(double x) {
    x = std::max(x, -708.0);  // 2^n stays a normal number
    constexpr double kLog2e = 1.4426950408889634, kLn2Hi = 0.6931471803691238, kLn2Lo = 1.9082149292705877e-10;
    constexpr double kShifter = 0x1.8p52;  // adding it rounds to an integer held in the low mantissa bits
    const double t = x * kLog2e + kShifter;
    const double n = t - kShifter;
    const double r = (x - n * kLn2Hi) - n * kLn2Lo;
    const double p =
        1.0 +
        r * (1.0 +
             r * (0.5 +
                  r * (1.0 / 6 +
                       r * (1.0 / 24 +
                            r * (1.0 / 120 +
                                 r * (1.0 / 720 +
                                      r * (1.0 / 5040 +
                                           r * (1.0 / 40320 +
                                                r * (1.0 / 362880 + r * (1.0 / 3628800 +
                                                                         r * (1.0 / 39916800 +
                                                                              r * (1.0 / 479001600 +
                                                                                   r * (1.0 / 6227020800.0)))))))))))));
    const int64_t bits = (std::bit_cast<int64_t>(t) - std::bit_cast<int64_t>(kShifter) + 1023) << 52;
    return p * std::bit_cast<double>(bits);
}

constexpr size_t kLanes = 4;  // doubles per AVX2 register

// Candidate cells of some points: centres (in the points' frame), kernel 1 / (2 sigma^2 c^2), squared radius,
// value and water level relative to the caller's bases, 1 for a wet cell (0 and level 0 for a dry one). Padded to
// whole vectors of kLanes with entries that never count.
struct Gathered {
    std::vector<double> ex, ey, a, r2, rel0, rel1, wet;
    size_t padded = 0;
    // Room for m candidates, every entry zero (padding: r2 = -1, so d2 < r2 never holds).
    void reset(size_t m) {
        padded = (m + kLanes - 1) / kLanes * kLanes;
        for (auto* v : {&ex, &ey, &a, &rel0, &rel1, &wet}) v->assign(padded, 0.0);
        r2.assign(padded, -1.0);
    }
};

// The truncated Gaussian weights w_i at (px, py) (kernel.h; `tail` = exp(-R^2 / 2)) summed: sum w rel0, sum w rel1,
// sum w and sum of the wet weights.
struct KernelSums {
    double num0, num1, den, denWet;
};
inline KernelSums sumKernels(const Gathered& g, double px, double py, double tail) {
    double num0[kLanes] = {}, num1[kLanes] = {}, den[kLanes] = {}, denWet[kLanes] = {};
    const double* __restrict ex = g.ex.data();
    const double* __restrict ey = g.ey.data();
    const double* __restrict ca = g.a.data();
    const double* __restrict cr2 = g.r2.data();
    const double* __restrict r0 = g.rel0.data();
    const double* __restrict r1 = g.rel1.data();
    const double* __restrict wet = g.wet.data();
    // Branch-free, kLanes partial sums, so that the loop vectorises.
    for (size_t base = 0; base < g.padded; base += kLanes)
        for (size_t l = 0; l < kLanes; ++l) {
            const size_t idx = base + l;
            const double dx = px - ex[idx], dy = py - ey[idx];
            const double d2 = dx * dx + dy * dy;
            // Beyond the radius the mask zeroes the weight (and expNonPositive clamps the exponent, so nothing
            // overflows there).
            const double w = std::max(expNonPositive(-d2 * ca[idx]) - tail, 0.0) * static_cast<double>(d2 < cr2[idx]);
            num0[l] += w * r0[idx];
            num1[l] += w * r1[idx];  // r1 is 0 for dry cells
            den[l] += w;
            denWet[l] += w * wet[idx];
        }
    KernelSums s{0, 0, 0, 0};
    for (size_t l = 0; l < kLanes; ++l) s.num0 += num0[l], s.num1 += num1[l], s.den += den[l], s.denWet += denWet[l];
    return s;
}

}  // namespace hc::influence::detail
