#include <algorithm>
#include <cmath>
#include <limits>

#include "heightcast/export/export.h"
#include "heightcast/core/error.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/progress.h"
#include "heightcast/influence/region.h"

namespace hc::exporting {

size_t SampledRaster::definedCount() const {
    size_t n = 0;
    for (float v : values) n += !std::isnan(v);
    return n;
}

namespace {

// The request checked against the cells' bounding box (local frame [m]) of the grid `g` (geometry only).
SampledRaster planIn(const Grid& g, double bx0, double by0, double bx1, double by1, double resolutionM,
                     std::optional<BoxWorld> box, size_t maxPixels) {
    if (!(resolutionM > 0) || !std::isfinite(resolutionM))
        throw Error("--resolution must be a positive number of metres");
    // The cells' bounds in the world: for a rotated grid the box around the rotated bounds.
    if (g.rotationDeg != 0) {
        double wx0 = HUGE_VAL, wy0 = HUGE_VAL, wx1 = -HUGE_VAL, wy1 = -HUGE_VAL;
        for (int corner = 0; corner < 4; ++corner) {
            double x = 0, y = 0;
            g.localToWorld(corner & 1 ? bx1 : bx0, corner & 2 ? by1 : by0, x, y);
            wx0 = std::min(wx0, x), wy0 = std::min(wy0, y), wx1 = std::max(wx1, x), wy1 = std::max(wy1, y);
        }
        // Offsets from the origin, so that the unrotated figures are those of plain subtraction.
        bx0 = wx0 - g.originWorldX, by0 = wy0 - g.originWorldY, bx1 = wx1 - g.originWorldX, by1 = wy1 - g.originWorldY;
    }
    if (!box) box = BoxWorld{g.originWorldX + bx0, g.originWorldY + by0, g.originWorldX + bx1, g.originWorldY + by1};
    if (!(box->xMin < box->xMax && box->yMin < box->yMax)) throw Error("--bbox must have XMIN < XMAX and YMIN < YMAX");
    const double w = std::ceil((box->xMax - box->xMin) / resolutionM - 1e-9);
    const double h = std::ceil((box->yMax - box->yMin) / resolutionM - 1e-9);
    if (w * h > static_cast<double>(maxPixels))
        throw Error("the export would be " + std::to_string(static_cast<long long>(w)) + " x " +
                    std::to_string(static_cast<long long>(h)) + " pixels, more than " + std::to_string(maxPixels) +
                    ": choose a coarser --resolution or a smaller --bbox");
    // Does the box meet the grid at all?
    if (box->xMax <= g.originWorldX + bx0 || box->xMin >= g.originWorldX + bx1 || box->yMax <= g.originWorldY + by0 ||
        box->yMin >= g.originWorldY + by1)
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

// Rows [b, e), columns [c0, c1) of r from `eval` (pixel centres; offsets of the first from the grid's origin along
// the CRS's axes: x0, y0; each turned into the grid's local frame, and gradients back to the CRS's axes).
void sampleRows(const influence::SurfaceEvaluator& eval, const influence::Layer& layer, bool gradients, double x0,
                double y0, size_t b, size_t e, size_t c0, size_t c1, SampledRaster& r) {
    const double res = r.pixelSizeM;
    const Grid& g = eval.grid();
    for (size_t row = b; row < e; ++row) {
        const double wy = y0 - static_cast<double>(row) * res;
        for (size_t col = c0; col < c1; ++col) {
            const double wx = x0 + static_cast<double>(col) * res;
            double x = 0, y = 0;
            g.worldToLocalDir(wx, wy, x, y);
            const size_t i = row * r.width + col;
            if (gradients) {
                if (auto v = eval.valueGradient(x, y, layer)) {
                    double gx = 0, gy = 0;
                    g.localToWorldDir(v->dx, v->dy, gx, gy);
                    r.values[i] = static_cast<float>(v->value);
                    r.gradX[i] = static_cast<float>(gx);
                    r.gradY[i] = static_cast<float>(gy);
                }
            } else if (auto v = eval.value(x, y, layer)) {
                r.values[i] = static_cast<float>(*v);
            }
        }
    }
}

// Every value NaN (undefined until sampled), the gradients too if asked; the layer's name and units.
void prepare(SampledRaster& r, const Grid& g, const influence::Layer& layer, const std::string& layerName,
             bool gradients) {
    r.layer = layerName;
    r.units = layer.kind == influence::Layer::Cells ? g.layers[layer.index].units : "m";
    const float nan = std::numeric_limits<float>::quiet_NaN();
    r.values.assign(r.width * r.height, nan);
    if (gradients) {
        r.gradX.assign(r.values.size(), nan);
        r.gradY.assign(r.values.size(), nan);
    }
}

}  // namespace

SampledRaster planRaster(const Grid& g, double resolutionM, std::optional<BoxWorld> box, size_t maxPixels) {
    double x0, y0, x1, y1;
    g.boundsLocal(x0, y0, x1, y1);
    return planIn(g, x0, y0, x1, y1, resolutionM, box, maxPixels);
}

SampledRaster planRaster(const GridFileInfo& file, double resolutionM, std::optional<BoxWorld> box, size_t maxPixels) {
    const auto& b = file.summary.boundsFinest;
    const double f = file.shape.finestCellM;
    return planIn(file.shape, double(b[0]) * f, double(b[1]) * f, double(b[2]) * f, double(b[3]) * f, resolutionM, box,
                  maxPixels);
}

SampledRaster sampleSurface(const influence::SurfaceEvaluator& eval, const influence::Layer& layer,
                            const std::string& layerName, double resolutionM, std::optional<BoxWorld> box,
                            bool gradients, unsigned threads, bool progress, size_t maxPixels) {
    const Grid& g = eval.grid();
    SampledRaster r = planRaster(g, resolutionM, box, maxPixels);
    prepare(r, g, layer, layerName, gradients);
    // The first pixel centre's offsets from the origin: the world offsets are subtracted once, in double.
    const double x0 = r.westWorld - g.originWorldX + 0.5 * resolutionM;
    const double y0 = r.northWorld - g.originWorldY - 0.5 * resolutionM;
    Progress bar("sampling " + layerName, r.height, progress);
    parallelFor(r.height, 8, threads, [&](size_t b, size_t e, unsigned) {
        sampleRows(eval, layer, gradients, x0, y0, b, e, 0, r.width, r);
        bar.advance(e - b);
    });
    bar.finish();
    return r;
}

SampledRaster sampleSurface(const GridRegionReader& file, const influence::KernelParams& params,
                            const influence::Layer& layer, const std::string& layerName, double resolutionM,
                            std::optional<BoxWorld> box, bool gradients, unsigned threads, bool progress,
                            size_t maxPixels) {
    const Grid& g = file.shape();
    SampledRaster r = planRaster(file.info(), resolutionM, box, maxPixels);
    prepare(r, g, layer, layerName, gradients);
    const double x0 = r.westWorld - g.originWorldX + 0.5 * resolutionM;
    const double y0 = r.northWorld - g.originWorldY - 0.5 * resolutionM;
    // Tiles of kExportTileCells^2 finest cells (at least one pixel): a region of at most ~65 k cells plus its kernel
    // margin, whatever the resolution.
    const size_t side =
        size_t(std::clamp(std::floor(double(kExportTileCells) * g.finestCellM / resolutionM), 1.0, 4096.0));
    Progress bar("sampling " + layerName + " out of core", r.height, progress);
    for (size_t band = 0; band < r.height; band += side) {
        const size_t end = std::min(r.height, band + side);
        for (size_t c0 = 0; c0 < r.width; c0 += side) {
            const size_t c1 = std::min(r.width, c0 + side);
            // The tile's pixel centres in the local frame: the box around them (turned, for a rotated grid).
            Grid::Square area{HUGE_VAL, HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
            for (int corner = 0; corner < 4; ++corner) {
                double x = 0, y = 0;
                g.worldToLocalDir(x0 + double(corner & 1 ? c1 - 1 : c0) * resolutionM,
                                  y0 - double(corner & 2 ? end - 1 : band) * resolutionM, x, y);
                area = {std::min(area.x0, x), std::min(area.y0, y), std::max(area.x1, x), std::max(area.y1, y)};
            }
            const influence::SurfaceRegion region = influence::readSurfaceRegion(file, area, params, threads);
            if (region.grid.cellCount() == 0) continue;
            const influence::SurfaceEvaluator eval(region.grid, region.lists);
            parallelFor(end - band, 4, threads, [&](size_t b, size_t e, unsigned) {
                sampleRows(eval, layer, gradients, x0, y0, band + b, band + e, c0, c1, r);
            });
        }
        bar.advance(end - band);
    }
    bar.finish();
    return r;
}

}  // namespace hc::exporting
