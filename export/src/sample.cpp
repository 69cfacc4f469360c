#include <cmath>
#include <limits>

#include "heightcast/export/export.h"
#include "heightcast/core/error.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/progress.h"

namespace hc::exporting {

size_t SampledRaster::definedCount() const {
    size_t n = 0;
    for (float v : values) n += !std::isnan(v);
    return n;
}

SampledRaster planRaster(const Grid& g, double resolutionM, std::optional<BoxWorld> box, size_t maxPixels) {
    if (!(resolutionM > 0) || !std::isfinite(resolutionM)) throw Error("--resolution must be a positive number of metres");
    if (!box) {
        double x0, y0, x1, y1;
        g.boundsLocal(x0, y0, x1, y1);
        box = BoxWorld{g.originWorldX + x0, g.originWorldY + y0, g.originWorldX + x1, g.originWorldY + y1};
    }
    if (!(box->xMin < box->xMax && box->yMin < box->yMax)) throw Error("--bbox must have XMIN < XMAX and YMIN < YMAX");
    const double w = std::ceil((box->xMax - box->xMin) / resolutionM - 1e-9);
    const double h = std::ceil((box->yMax - box->yMin) / resolutionM - 1e-9);
    if (w * h > static_cast<double>(maxPixels))
        throw Error("the export would be " + std::to_string(static_cast<long long>(w)) + " x " + std::to_string(static_cast<long long>(h)) +
                    " pixels, more than " + std::to_string(maxPixels) + ": choose a coarser --resolution or a smaller --bbox");
    // Does the box meet the grid at all?
    double x0, y0, x1, y1;
    g.boundsLocal(x0, y0, x1, y1);
    if (box->xMax <= g.originWorldX + x0 || box->xMin >= g.originWorldX + x1 || box->yMax <= g.originWorldY + y0 ||
        box->yMin >= g.originWorldY + y1)
        throw Error("the requested area lies outside the grid: the surface is undefined everywhere in it");
    SampledRaster r;
    r.width = static_cast<size_t>(w);
    r.height = static_cast<size_t>(h);
    r.westWorld = box->xMin;
    r.northWorld = box->yMax;
    r.pixelSizeM = resolutionM;
    r.originWorldX = g.originWorldX;
    r.originWorldY = g.originWorldY;
    r.crsWkt = g.crsWkt;
    return r;
}

SampledRaster sampleSurface(const influence::SurfaceEvaluator& eval, const influence::Layer& layer, const std::string& layerName,
                            double resolutionM, std::optional<BoxWorld> box, bool gradients, unsigned threads, bool progress,
                            size_t maxPixels) {
    const Grid& g = eval.grid();
    SampledRaster r = planRaster(g, resolutionM, box, maxPixels);
    r.layer = layerName;
    r.units = layer.kind == influence::Layer::Cells ? g.layers[layer.index].units : "m";
    const float nan = std::numeric_limits<float>::quiet_NaN();
    r.values.assign(r.width * r.height, nan);
    if (gradients) {
        r.gradX.assign(r.values.size(), nan);
        r.gradY.assign(r.values.size(), nan);
    }
    // Local coordinates of the first pixel centre: the world offsets are subtracted once, in double.
    const double x0 = r.westWorld - g.originWorldX + 0.5 * resolutionM;
    const double y0 = r.northWorld - g.originWorldY - 0.5 * resolutionM;
    Progress bar("sampling " + layerName, r.height, progress);
    parallelFor(r.height, 8, threads, [&](size_t b, size_t e, unsigned) {
        for (size_t row = b; row < e; ++row) {
            const double y = y0 - static_cast<double>(row) * resolutionM;
            for (size_t col = 0; col < r.width; ++col) {
                const double x = x0 + static_cast<double>(col) * resolutionM;
                const size_t i = row * r.width + col;
                if (gradients) {
                    if (auto v = eval.valueGradient(x, y, layer)) {
                        r.values[i] = static_cast<float>(v->value);
                        r.gradX[i] = static_cast<float>(v->dx);
                        r.gradY[i] = static_cast<float>(v->dy);
                    }
                } else if (auto v = eval.value(x, y, layer)) {
                    r.values[i] = static_cast<float>(*v);
                }
            }
        }
        bar.advance(e - b);
    });
    bar.finish();
    return r;
}

}  // namespace hc::exporting
