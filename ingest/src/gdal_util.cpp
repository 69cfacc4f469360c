#include "gdal_util.h"

#include <algorithm>
#include <cctype>
#include <limits>
#include <filesystem>
#include <mutex>
#include <sstream>

#include <cpl_error.h>
#include <gdalwarper.h>

#include "heightcast/core/error.h"
#include "heightcast/core/parallel.h"

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

namespace {

// GDAL's subdataset syntax, DRIVER:"file":name or DRIVER:file:name (NETCDF:"a.nc":elevation,
// HDF5:..., GTIFF_DIR:2:a.tif): returns the file part, or "" when `path` is not of that form. A
// one-letter prefix is a Windows drive, not a driver.
std::string subdatasetFile(const std::string& path) {
    size_t colon = path.find(':');
    if (colon == std::string::npos || colon < 2) return "";
    for (size_t i = 0; i < colon; ++i)
        if (!std::isalnum(static_cast<unsigned char>(path[i])) && path[i] != '_') return "";
    std::string rest = path.substr(colon + 1);
    if (!rest.empty() && rest[0] == '"') {
        size_t end = rest.find('"', 1);
        return end == std::string::npos ? "" : rest.substr(1, end - 1);
    }
    // Unquoted: the first ':'-separated part that is a file (GTIFF_DIR:2:a.tif -> a.tif), else the last.
    std::string part;
    for (size_t start = 0;; start += part.size() + 1) {
        size_t end = rest.find(':', start);
        part = rest.substr(start, end == std::string::npos ? std::string::npos : end - start);
        std::error_code ec;
        if (end == std::string::npos || std::filesystem::exists(part, ec)) return part;
    }
}

// "NETCDF:"f.nc":elevation (desc), ..." for the error of a container without a band of its own.
std::string listSubdatasets(GDALDataset& ds, size_t& count) {
    std::string out;
    count = 0;
    char** md = ds.GetMetadata("SUBDATASETS");
    for (int i = 1;; ++i) {
        const char* name = CSLFetchNameValue(md, ("SUBDATASET_" + std::to_string(i) + "_NAME").c_str());
        if (!name) break;
        const char* desc = CSLFetchNameValue(md, ("SUBDATASET_" + std::to_string(i) + "_DESC").c_str());
        if (++count <= 12)
            out += std::string(count > 1 ? ", " : "") + "'" + name + "'" + (desc ? std::string(" (") + desc + ")" : "");
    }
    if (count > 12) out += ", ... (" + std::to_string(count - 12) + " more)";
    return out;
}

}  // namespace

DatasetPtr openRaster(const std::string& path, const std::string& role) {
    ensureGdal();
    std::error_code ec;
    const bool onDisk = std::filesystem::exists(path, ec);
    if (path.rfind("/vsi", 0) != 0 && !onDisk) {  // GDAL virtual paths (/vsizip/...) are not on disk
        std::string file = subdatasetFile(path);
        if (file.empty()) throw Error(path + ": no such file (" + role + ")");
        if (file.rfind("/vsi", 0) != 0 && !std::filesystem::exists(file, ec))
            throw Error(path + ": no such file " + file + " (" + role + ")");
    }
    if (onDisk && std::filesystem::is_directory(path, ec))
        throw Error(path + ": is a directory, not a raster (" + role + ")");
    CPLErrorReset();
    auto* ds = GDALDataset::Open(path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY | GDAL_OF_VERBOSE_ERROR);
    if (!ds) {
        std::string why = lastGdalError();
        // DRIVER:"file":name naming no subdataset of an existing file: GDAL says "no such file"; list what there is.
        if (std::string file = onDisk ? "" : subdatasetFile(path); !file.empty()) {
            if (DatasetPtr container{GDALDataset::Open(file.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY)}) {
                size_t count = 0;
                std::string list = listSubdatasets(*container, count);
                if (count > 0) why = file + " holds no such subdataset; its " + std::to_string(count) + " are: " + list;
            }
        }
        throw Error(path + ": cannot read as a raster (" + role + "): " + why);
    }
    DatasetPtr owned(ds);
    if (ds->GetRasterCount() < 1) {
        size_t count = 0;
        std::string list = listSubdatasets(*ds, count);
        if (count == 0) throw Error(path + ": has no raster band (" + role + ")");
        throw Error(path + ": has no raster band of its own but " + std::to_string(count) +
                    " variables (subdatasets) (" + role +
                    "); give one of them as the input, quoted for the shell: " + list);
    }
    if (ds->GetRasterXSize() < 1 || ds->GetRasterYSize() < 1)
        throw Error(path + ": raster has no pixels (" + role + ")");
    return owned;
}

std::string fmt(double v, int precision) {
    std::ostringstream s;
    s.precision(precision);
    s << v;
    return s.str();
}

std::string lower(std::string s) {
    for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return s;
}

double cfSecondsPerUnit(const std::string& text) {
    const std::string units = lower(text);
    if (units.find(" since ") == std::string::npos) return 0;
    const std::string unit = units.substr(0, units.find(' '));
    if (unit == "seconds" || unit == "second" || unit == "s" || unit == "sec" || unit == "secs") return 1;
    if (unit == "minutes" || unit == "minute" || unit == "min" || unit == "mins") return 60;
    if (unit == "hours" || unit == "hour" || unit == "h" || unit == "hr" || unit == "hrs") return 3600;
    if (unit == "days" || unit == "day" || unit == "d") return 86400;
    return 0;
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

void WindowWarp::into(size_t c0, size_t r0, size_t w, size_t h, float* out) const {
    if (w == 0 || h == 0) return;
    GDALDriver* vrt = GetGDALDriverManager()->GetDriverByName("VRT");
    DatasetPtr dst(vrt->Create("", int(width), int(height), 1, GDT_Float32, nullptr));  // nothing allocated
    if (!dst) throw Error("cannot create a virtual raster: " + lastGdalError());
    double g[6];
    std::copy(gt, gt + 6, g);
    dst->SetGeoTransform(g);
    if (!dstWkt.empty()) dst->SetProjection(dstWkt.c_str());
    dst->GetRasterBand(1)->SetNoDataValue(std::numeric_limits<double>::quiet_NaN());
    char** opts = dstSrs.empty() ? nullptr : CSLSetNameValue(nullptr, "DST_SRS", dstSrs.c_str());
    void* tr = GDALCreateGenImgProjTransformer2(GDALDataset::ToHandle(src), GDALDataset::ToHandle(dst.get()), opts);
    CSLDestroy(opts);
    if (!tr) throw Error(setupError + ": " + lastGdalError());
    std::unique_ptr<void, void (*)(void*)> trOwner(tr, GDALDestroyGenImgProjTransformer);
    GDALWarpOptions* wo = GDALCreateWarpOptions();
    std::unique_ptr<GDALWarpOptions, void (*)(GDALWarpOptions*)> woOwner(wo, GDALDestroyWarpOptions);
    wo->hSrcDS = GDALDataset::ToHandle(src);
    wo->hDstDS = GDALDataset::ToHandle(dst.get());
    wo->nBandCount = 1;
    wo->panSrcBands = static_cast<int*>(CPLMalloc(sizeof(int)));
    wo->panDstBands = static_cast<int*>(CPLMalloc(sizeof(int)));
    wo->panSrcBands[0] = band;
    wo->panDstBands[0] = 1;
    wo->eResampleAlg = GRA_Bilinear;
    wo->eWorkingDataType = GDT_Float32;
    if (hasSrcNoData) {
        wo->padfSrcNoDataReal = static_cast<double*>(CPLMalloc(sizeof(double)));
        wo->padfSrcNoDataReal[0] = srcNoData;
    }
    wo->padfDstNoDataReal = static_cast<double*>(CPLMalloc(sizeof(double)));
    wo->padfDstNoDataReal[0] = std::numeric_limits<double>::quiet_NaN();
    wo->pfnTransformer = GDALGenImgProjTransform;  // exact: no approximation (gdalwarp -et 0)
    wo->pTransformerArg = tr;
    const std::string sc = fmt(scale, 17);
    wo->papszWarpOptions = CSLSetNameValue(wo->papszWarpOptions, "XSCALE", sc.c_str());
    wo->papszWarpOptions = CSLSetNameValue(wo->papszWarpOptions, "YSCALE", sc.c_str());
    wo->papszWarpOptions =
        CSLSetNameValue(wo->papszWarpOptions, "NUM_THREADS", std::to_string(resolveThreads(threads)).c_str());
    GDALWarpOperation op;
    CPLErrorReset();
    if (op.Initialize(wo) != CE_None ||
        op.WarpRegionToBuffer(int(c0), int(r0), int(w), int(h), out, GDT_Float32) != CE_None)
        throw Error(warpError + ": " + lastGdalError());
}

}  // namespace hc::ingest::detail
