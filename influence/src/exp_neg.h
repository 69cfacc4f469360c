// influence/src/exp_neg.h: the vectorisable exponential of the exact evaluators (surface.cpp, pyramid.cpp).
#pragma once

#include <algorithm>
#include <bit>
#include <cstdint>

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
        1.0 + r * (1.0 + r * (0.5 + r * (1.0 / 6 + r * (1.0 / 24 + r * (1.0 / 120 + r * (1.0 / 720 + r * (1.0 / 5040 + r * (1.0 / 40320 +
        r * (1.0 / 362880 + r * (1.0 / 3628800 + r * (1.0 / 39916800 + r * (1.0 / 479001600 + r * (1.0 / 6227020800.0)))))))))))));
    const int64_t bits = (std::bit_cast<int64_t>(t) - std::bit_cast<int64_t>(kShifter) + 1023) << 52;
    return p * std::bit_cast<double>(bits);
}

}  // namespace hc::influence::detail
