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

// Seconds per unit of a CF time coordinate ("hours since 2020-01-01 00:00:00": 3600), or 0 when the units are not
// a CF time (no "since", or a unit other than seconds, minutes, hours, days). Months and years are refused (0):
// CF's are not fixed lengths.
double cfSecondsPerUnit(const std::string& units);

}  // namespace hc::ingest::detail
