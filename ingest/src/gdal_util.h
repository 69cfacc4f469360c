// GDAL plumbing private to ingest/: one-time registration, quiet error capture, owned handles.
#pragma once

#include <memory>
#include <string>

#include <gdal_priv.h>
#include <ogr_spatialref.h>

namespace hc::ingest::detail {

// Registers drivers once and routes GDAL's own messages into CPLGetLastErrorMsg (our errors quote
// it) instead of letting GDAL print "ERROR 1: ..." lines of its own.
void ensureGdal();
std::string lastGdalError();

struct DatasetCloser {
    void operator()(GDALDataset* ds) const { GDALClose(GDALDataset::ToHandle(ds)); }
};
using DatasetPtr = std::unique_ptr<GDALDataset, DatasetCloser>;

// Opens a raster read-only; throws hc::Error naming `path` (and `role`, e.g. "water raster").
DatasetPtr openRaster(const std::string& path, const std::string& role);

// A number for messages ("0.3048006096" at precision 10), and a lower-case copy of a string.
std::string fmt(double v, int precision = 6);
std::string lower(std::string s);

// Short name of a CRS ("WGS 84 / UTM zone 32N"), or "" for none.
std::string crsName(const OGRSpatialReference* srs);
std::string toWkt(const OGRSpatialReference& srs);

// One window of a bilinear warp with GDAL's exact transformer: band `band` of `src` onto a virtual raster of
// width x height pixels on geotransform `gt`, the kernel's scale fixed at `scale` (GDAL's XSCALE and YSCALE: output
// pixels per source pixel, at most 1; GDAL's own estimate varies from chunk to chunk). The window uses the whole
// virtual raster's pixel coordinates, so any window holds the same bits as the whole.
struct WindowWarp {
    GDALDataset* src = nullptr;
    int band = 1;
    bool hasSrcNoData = false;
    double srcNoData = 0;  // the source's nodata value (NaN for none in a float source)
    double gt[6] = {0, 1, 0, 0, 0, -1};
    size_t width = 0, height = 0;
    std::string
        dstSrs;  // the target CRS as the transformer takes it (DST_SRS: PROJ text or WKT); empty: the source's frame
    std::string dstWkt;  // the same as WKT, for the virtual raster; empty with dstSrs
    double scale = 1;
    unsigned threads = 0;
    std::string setupError, warpError;  // messages' prefixes: the transform cannot be made; the warp failed
    // Pixels [c0, c0 + w) x [r0, r0 + h) into out (w h, row-major), which the caller filled: where nothing lands it
    // keeps its values. Throws hc::Error.
    void into(size_t c0, size_t r0, size_t w, size_t h, float* out) const;
};

// Seconds per unit of a CF time coordinate ("hours since 2020-01-01 00:00:00": 3600), or 0 when the units are not
// a CF time (no "since", or a unit other than seconds, minutes, hours, days). Months and years are refused (0):
// CF's are not fixed lengths.
double cfSecondsPerUnit(const std::string& units);

}  // namespace hc::ingest::detail
