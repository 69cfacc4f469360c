// ingest/src/load_water.h: a water step's raster warped onto the terrain's working raster window by window (private to
// ingest/).
#pragma once

#include <cstdint>
#include <string>

#include "gdal_util.h"
#include "heightcast/ingest/ingest.h"

namespace hc::ingest::detail {

// One water step's raster (a depth or surface raster, or one band of a series) warped onto the working raster's lattice
// (bilinear, GDAL's exact transformer). Any window is computed with the whole raster's pixel coordinates and the
// kernel's scale fixed, so it holds the same bits as the whole: one process reads it in strips of rows (loadWater), and
// under mpirun each rank reads only its own windows.
class WaterStepWarp {
public:
    // `frame`: the working raster's geometry and CRS (its values are not read). Adds the CRS warnings to `report`.
    WaterStepWarp(const Options& opt, const Raster& frame, size_t step, LoadReport& report);
    // Depth [m] at the working pixels [c0, c0 + w) x [r0, r0 + h) (row 0 the northern-most, row-major), from the
    // terrain's elevations there (terrainZ, the same layout): NaN where the terrain has a hole, 0 where dry or where
    // the water raster has no data; a negative depth (a depth raster) is counted in `negative` and taken as dry.
    void depth(size_t c0, size_t r0, size_t w, size_t h, const float* terrainZ, float* out, uint64_t& negative) const;
    const std::string& what() const { return what_; }  // the file (and band), for messages

private:
    void warp(size_t c0, size_t r0, size_t w, size_t h, float* out) const;  // the water raster's values, NaN where none
    DatasetPtr ds_;
    std::string what_;
    bool surface_ = false;
    WindowWarp warp_;  // over ds_, set up once: every window warps with the same settings
};

// The step's raster as messages name it: the file, and "(band B, step K)" for a band of a series.
std::string waterStepName(const Options& opt, size_t step);
// "FILE: N pixels of negative depth taken as dry".
std::string negativeDepthWarning(const std::string& what, uint64_t negative);

}  // namespace hc::ingest::detail
