#include <cmath>
#include <memory>

#include <cpl_error.h>
#include <gdal_priv.h>
#include <ogr_spatialref.h>

#include "heightcast/export/export.h"
#include "heightcast/core/atomic_file.h"
#include "heightcast/core/error.h"

namespace hc::exporting {

void writeGeoTiff(const SampledRaster& r, const std::string& path) {
    GDALAllRegister();
    // GDAL's messages go into ours (CPLGetLastErrorMsg), not onto the terminal; scoped to this call.
    CPLPushErrorHandler(CPLQuietErrorHandler);
    struct PopHandler {
        ~PopHandler() { CPLPopErrorHandler(); }
    } pop;
    auto gdalMessage = [] {
        const char* m = CPLGetLastErrorMsg();
        return std::string(m && *m ? m : "no detail from GDAL");
    };
    constexpr double kNodata = -3.4028234663852886e+38;
    AtomicPath out(path);
    GDALDriver* drv = GetGDALDriverManager()->GetDriverByName("GTiff");
    if (!drv) throw Error(path + ": GDAL has no GTiff driver");
    const char* options[] = {"COMPRESS=DEFLATE", "PREDICTOR=3", "TILED=YES", "BIGTIFF=IF_SAFER", nullptr};
    CPLErrorReset();
    {
        std::unique_ptr<GDALDataset> ds(drv->Create(out.temp().c_str(), static_cast<int>(r.width),
                                                    static_cast<int>(r.height), 1, GDT_Float32,
                                                    const_cast<char**>(options)));
        if (!ds) throw Error(path + ": cannot create a GeoTIFF: " + gdalMessage());
        double gt[6] = {r.westWorld, r.pixelSizeM, 0, r.northWorld, 0, -r.pixelSizeM};
        ds->SetGeoTransform(gt);
        if (!r.crsWkt.empty()) {
            OGRSpatialReference srs;
            if (srs.importFromWkt(r.crsWkt.c_str()) != OGRERR_NONE || ds->SetSpatialRef(&srs) != CE_None)
                throw Error(path + ": cannot store the grid's CRS: " + gdalMessage());
        }
        GDALRasterBand* band = ds->GetRasterBand(1);
        band->SetNoDataValue(kNodata);
        band->SetDescription(r.layer.c_str());
        band->SetUnitType(r.units.c_str());
        std::vector<float> row(r.width);
        for (size_t y = 0; y < r.height; ++y) {
            for (size_t x = 0; x < r.width; ++x) {
                float v = r.values[y * r.width + x];
                row[x] = std::isnan(v) ? static_cast<float>(kNodata) : v;
            }
            if (band->RasterIO(GF_Write, 0, static_cast<int>(y), static_cast<int>(r.width), 1, row.data(),
                               static_cast<int>(r.width), 1, GDT_Float32, 0, 0, nullptr) != CE_None)
                throw Error(path + ": write failed: " + gdalMessage());
        }
        ds->SetMetadataItem("heightcast_layer", r.layer.c_str());
        CPLErrorReset();
        ds->FlushCache(true);
        if (CPLGetLastErrorType() >= CE_Failure) throw Error(path + ": write failed: " + gdalMessage());
    }  // closing the dataset writes the last tiles
    if (CPLGetLastErrorType() >= CE_Failure) throw Error(path + ": write failed: " + gdalMessage());
    out.commit();
}

}  // namespace hc::exporting
