#include "gdal_util.h"

#include <filesystem>
#include <mutex>

#include <cpl_error.h>

#include "heightcast/grid/error.h"

namespace hc::ingest::detail {

void ensureGdal() {
    static std::once_flag once;
    std::call_once(once, [] {
        GDALAllRegister();
        CPLSetErrorHandler(CPLQuietErrorHandler);
    });
}

std::string lastGdalError() {
    const char* msg = CPLGetLastErrorMsg();
    return (msg && *msg) ? std::string(msg) : std::string("no detail from GDAL");
}

DatasetPtr openRaster(const std::string& path, const std::string& role) {
    ensureGdal();
    if (path.rfind("/vsi", 0) != 0) {  // GDAL virtual paths (/vsizip/...) are not on disk
        std::error_code ec;
        if (!std::filesystem::exists(path, ec)) throw Error(path + ": no such file (" + role + ")");
        if (std::filesystem::is_directory(path, ec)) throw Error(path + ": is a directory, not a raster (" + role + ")");
    }
    CPLErrorReset();
    auto* ds = GDALDataset::Open(path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY | GDAL_OF_VERBOSE_ERROR);
    if (!ds) throw Error(path + ": cannot read as a raster (" + role + "): " + lastGdalError());
    DatasetPtr owned(ds);
    if (ds->GetRasterCount() < 1) throw Error(path + ": has no raster band (" + role + ")");
    if (ds->GetRasterXSize() < 1 || ds->GetRasterYSize() < 1) throw Error(path + ": raster has no pixels (" + role + ")");
    return owned;
}

std::string crsName(const OGRSpatialReference* srs) {
    if (!srs || srs->IsEmpty()) return "";
    const char* name = srs->GetName();
    std::string out = name ? name : "unnamed CRS";
    const char* auth = srs->GetAuthorityName(nullptr);
    const char* code = srs->GetAuthorityCode(nullptr);
    if (auth && code) out += std::string(" (") + auth + ":" + code + ")";
    return out;
}

std::string toWkt(const OGRSpatialReference& srs) {
    char* wkt = nullptr;
    const char* options[] = {"FORMAT=WKT2_2019", nullptr};
    if (srs.exportToWkt(&wkt, options) != OGRERR_NONE || !wkt) {
        CPLFree(wkt);
        throw Error("cannot express the CRS as WKT: " + lastGdalError());
    }
    std::string out(wkt);
    CPLFree(wkt);
    return out;
}

}  // namespace hc::ingest::detail
