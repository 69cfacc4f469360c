#include <cmath>

#include "heightcast/core/exr.h"
#include "heightcast/export/export.h"

namespace hc::exporting {

void writeExr(const SampledRaster& r, const std::string& path) {
    std::vector<float> coverage(r.values.size());
    for (size_t i = 0; i < r.values.size(); ++i) coverage[i] = std::isnan(r.values[i]) ? 0.0f : 1.0f;
    const exr::FloatChannel channels[] = {{r.layer, r.values}, {"A", coverage}};
    const exr::Attribute attributes[] = {
        {"heightcast.gridOriginX", r.originWorldX},
        {"heightcast.gridOriginY", r.originWorldY},
        {"heightcast.rasterNorthWestX", r.westWorld},
        {"heightcast.rasterNorthWestY", r.northWorld},
        {"heightcast.pixelSizeM", r.pixelSizeM},
        {"heightcast.crsWkt", r.crsWkt},
        {"heightcast.layer", r.layer},
        {"heightcast.units", r.units},
    };
    exr::writeFloatImage(path, r.width, r.height, channels, attributes);
}

}  // namespace hc::exporting
