// tests/image_compare.h: rendered pictures compared by their colours.
#pragma once

#include <cmath>
#include <cstddef>

#include "heightcast/render/renderer.h"

namespace hc::test {

// The peak signal-to-noise ratio of b's sRGB bytes against a's [dB] (a and b of one size); 99 where they are equal.
inline double psnr(const render::Frame& a, const render::Frame& b) {
    double se = 0;
    for (size_t i = 0; i < a.rgb.size(); ++i) se += std::pow(double(a.rgb[i]) - double(b.rgb[i]), 2);
    const double mse = se / double(a.rgb.size());
    return mse == 0 ? 99.0 : 10 * std::log10(255.0 * 255.0 / mse);
}

}  // namespace hc::test
