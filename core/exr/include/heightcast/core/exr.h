// heightcast/core/exr.h: float images to OpenEXR files, the one OpenEXR writer of heightcast (hc-export's
// rasters, hc-render's frame layers). OpenEXR itself stays inside exr.cpp.
#pragma once

#include <cstddef>
#include <span>
#include <string>
#include <variant>

namespace hc::exr {

// One FLOAT channel: width * height values, row-major, row 0 the top row of the image (OpenEXR's y runs down).
// The values are borrowed for the call only.
struct FloatChannel {
    std::string name;
    std::span<const float> values;
};

// A typed header attribute: OpenEXR's double, int or string attribute, by the value's type.
struct Attribute {
    std::string name;
    std::variant<double, int, std::string> value;
};

// Writes a width x height image of FLOAT `channels` with `attributes` in its header to `path`, ZIP
// compression (lossless, 16 scanlines per block). Channel names are distinct and not empty; each channel
// holds exactly width * height values (both asserted). Written to a temporary file beside `path` and renamed
// into place (hc::AtomicPath): on failure nothing is left under `path`. Throws hc::Error
// "PATH: cannot write OpenEXR: ..." when the file cannot be written or the image is larger than OpenEXR
// takes (2^31 - 1 pixels per side).
void writeFloatImage(const std::string& path, size_t width, size_t height, std::span<const FloatChannel> channels,
                     std::span<const Attribute> attributes);

}  // namespace hc::exr
