// heightcast/ingest/raster.h: the working raster every ingest stage hands to the next.
//
// North-up, square pixels, in the grid CRS (metres). Row 0 is the northern-most row; column 0 the
// western-most. A pixel is the square [west + col * pixelSizeM, ...) x (..., north - row * pixelSizeM].
// NaN marks nodata: a hole, never a value. Plain data; move it, don't copy it.
#pragma once

#include <cmath>
#include <cstddef>
#include <string>
#include <vector>

namespace hc::ingest {

struct Raster {
    size_t width = 0;
    size_t height = 0;
    double westWorld = 0;       // x of the west edge, grid CRS [m]
    double northWorld = 0;      // y of the north edge, grid CRS [m]
    double pixelSizeM = 1;      // pixel side [m]
    std::string crsWkt;         // "" = local metres, no CRS
    std::string crsName;        // crsWkt's name as GDAL gives it (LoadReport::gridCrsName); "" with no CRS
    std::vector<float> values;  // width * height, row-major, NaN = nodata
    // Empty, or (width * height) the source value minus values[i] [m]: what float32 lost of a source that
    // holds more precision (Float64, Int32). The build checks its tolerance against values + roundingM.
    std::vector<float> roundingM;

    float at(size_t col, size_t row) const { return values[row * width + col]; }
    float& at(size_t col, size_t row) { return values[row * width + col]; }
    double southWorld() const { return northWorld - static_cast<double>(height) * pixelSizeM; }
    size_t validCount() const {
        size_t n = 0;
        for (float v : values) n += !std::isnan(v);
        return n;
    }
};

}  // namespace hc::ingest
