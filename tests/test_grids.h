// Grids the tests share: real rasters ingested in memory, and the synthetic cell-size-ratio-128 grid.
#pragma once

#include <cmath>
#include <random>
#include <string>

#include "heightcast/grid/grid.h"
#include "heightcast/ingest/build.h"
#include "heightcast/ingest/ingest.h"

namespace hc::test {

// A raster ingested with the tool's defaults except the tolerance, an optional bathtub water level
// and an optional source CRS.
inline Grid ingestFile(const std::string& path, double toleranceM, double waterLevelM = NAN,
                       const std::string& sourceSrs = "") {
    ingest::Options o;
    o.input = path;
    o.toleranceM = toleranceM;
    o.sourceSrs = sourceSrs;
    if (!std::isnan(waterLevelM)) o.water = ingest::WaterSource::Level, o.waterLevelM = waterLevelM;
    ingest::LoadReport r;
    return ingest::ingest(o, r);
}

// A raster of width x height pixels of pixelSizeM [m], its north-west corner at (westWorld, northWorld), pixel
// (col, row) = value(col, row), row 0 north; value is called row by row, west to east.
template <typename F>
inline ingest::Raster makeRaster(size_t width, size_t height, double pixelSizeM, double westWorld, double northWorld,
                                 F&& value) {
    ingest::Raster r;
    r.width = width;
    r.height = height;
    r.pixelSizeM = pixelSizeM;
    r.westWorld = westWorld;
    r.northWorld = northWorld;
    r.values.resize(width * height);
    for (size_t row = 0; row < height; ++row)
        for (size_t col = 0; col < width; ++col) r.at(col, row) = value(col, row);
    return r;
}

// Cell-size ratio 128 (the report's Petzenkirchen extreme, 0.75 - 96 m): a gentle plane that merges
// into 96 m cells (level 7) beside a rough strip of 0.75 m cells, and a nodata hole at columns
// 500..519, rows 100..139 of the 640 x 512 raster (row 0 north).
inline Grid ratio128Grid() {
    std::mt19937 rng(3);
    const ingest::Raster r = makeRaster(640, 512, 0.75, 1000, 5000, [&](size_t col, size_t row) {
        const bool rough = col >= 300 && col < 316 && row >= 128 && row < 384;
        const bool hole = col >= 500 && col < 520 && row >= 100 && row < 140;
        return hole ? NAN : rough ? 200.0f + static_cast<float>(rng() % 1000) * 0.01f : 100.0f + 0.001f * float(col);
    });
    ingest::BuildOptions b;
    b.toleranceM = 0.5;
    b.maxLevel = 7;
    return ingest::buildGrid(r, nullptr, b);
}

}  // namespace hc::test
