// heightcast/core/rounded.h: a figure rounded to the precision a table prints it with, for JSON outputs
// (hc-render --timings, hc-bench --json): the file carries each figure's precision, not every bit of a timer.
#pragma once

#include <charconv>
#include <system_error>

namespace hc {

// `v` printed with `digits` decimals (std::chars_format::fixed) or significant digits (general), read back.
inline double rounded(double v, std::chars_format style, int digits) {
    char text[64];
    const auto printed = std::to_chars(text, text + sizeof text, v, style, digits);
    double back = v;
    if (printed.ec == std::errc{}) std::from_chars(text, printed.ptr, back);
    return back;
}

}  // namespace hc
