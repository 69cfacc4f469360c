// heightcast/core/quantile.h: the q-quantile of a sample, as the benchmarks and the error check report them.
#pragma once

#include <algorithm>
#include <cstddef>
#include <vector>

namespace hc {

// The element at rank round(q (n - 1)) of `v` in ascending order (q in [0, 1]: 0.5 the median, 0.99 the 99th
// percentile); 0 for an empty sample. Takes the sample by value: nth_element reorders it.
inline double quantile(std::vector<double> v, double q) {
    if (v.empty()) return 0;
    const size_t k = std::min(v.size() - 1, size_t(q * double(v.size() - 1) + 0.5));
    std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(k), v.end());
    return v[k];
}

}  // namespace hc
