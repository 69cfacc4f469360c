#include "resample.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "heightcast/grid/parallel.h"

namespace hc::ingest::detail {
namespace {

float sampleBilinear(const SourceBand& s, double col, double row) {
    const float nan = std::numeric_limits<float>::quiet_NaN();
    if (!(col >= 0 && row >= 0 && col < static_cast<double>(s.width) && row < static_cast<double>(s.height))) return nan;
    // Pixel centres sit at +0.5; clamp the 2x2 stencil to the raster at its edges.
    double u = col - 0.5, v = row - 0.5;
    auto i0 = static_cast<long>(std::floor(u)), j0 = static_cast<long>(std::floor(v));
    double fx = u - static_cast<double>(i0), fy = v - static_cast<double>(j0);
    auto cl = [](long i, size_t n) { return static_cast<size_t>(std::clamp<long>(i, 0, static_cast<long>(n) - 1)); };
    size_t x0 = cl(i0, s.width), x1 = cl(i0 + 1, s.width), y0 = cl(j0, s.height), y1 = cl(j0 + 1, s.height);
    float a = s.at(x0, y0), b = s.at(x1, y0), c = s.at(x0, y1), d = s.at(x1, y1);
    if (std::isnan(a) || std::isnan(b) || std::isnan(c) || std::isnan(d))
        return s.at(static_cast<size_t>(col), static_cast<size_t>(row));  // nearest: nodata stays nodata
    double top = a + (b - a) * fx, bottom = c + (d - c) * fx;
    return static_cast<float>(top + (bottom - top) * fy);
}

}  // namespace

void resample(const SourceBand& source, const TargetToSource& map, Raster& target, int lattice, unsigned threads) {
    const size_t w = target.width, h = target.height;
    target.values.assign(w * h, std::numeric_limits<float>::quiet_NaN());
    const auto step = static_cast<size_t>(std::max(lattice, 1));
    const size_t lw = (w + step - 1) / step + 1, lh = (h + step - 1) / step + 1;
    // Exact map at lattice nodes (pixel centres of every step-th row and column).
    struct Node {
        double col, row;
        bool ok;
    };
    std::vector<Node> nodes(lw * lh);
    parallelFor(lh, 8, threads, [&](size_t b, size_t e, unsigned) {
        for (size_t j = b; j < e; ++j)
            for (size_t i = 0; i < lw; ++i) {
                double x = target.westWorld + (static_cast<double>(i * step) + 0.5) * target.pixelSizeM;
                double y = target.northWorld - (static_cast<double>(j * step) + 0.5) * target.pixelSizeM;
                Node& n = nodes[j * lw + i];
                n.ok = map(x, y, n.col, n.row);
            }
    });
    parallelFor(h, 32, threads, [&](size_t b, size_t e, unsigned) {
        for (size_t r = b; r < e; ++r) {
            size_t j = r / step;
            double fy = static_cast<double>(r - j * step) / static_cast<double>(step);
            for (size_t c = 0; c < w; ++c) {
                size_t i = c / step;
                double fx = static_cast<double>(c - i * step) / static_cast<double>(step);
                const Node& n00 = nodes[j * lw + i];
                const Node& n10 = nodes[j * lw + i + 1];
                const Node& n01 = nodes[(j + 1) * lw + i];
                const Node& n11 = nodes[(j + 1) * lw + i + 1];
                double col, row;
                if (fx == 0 && fy == 0) {
                    if (!n00.ok) continue;
                    col = n00.col;
                    row = n00.row;
                } else if (n00.ok && n10.ok && n01.ok && n11.ok) {
                    col = (n00.col * (1 - fx) + n10.col * fx) * (1 - fy) + (n01.col * (1 - fx) + n11.col * fx) * fy;
                    row = (n00.row * (1 - fx) + n10.row * fx) * (1 - fy) + (n01.row * (1 - fx) + n11.row * fx) * fy;
                } else {  // near the edge of the map's domain: evaluate exactly
                    double x = target.westWorld + (static_cast<double>(c) + 0.5) * target.pixelSizeM;
                    double y = target.northWorld - (static_cast<double>(r) + 0.5) * target.pixelSizeM;
                    if (!map(x, y, col, row)) continue;
                }
                target.values[r * w + c] = sampleBilinear(source, col, row);
            }
        }
    });
}

}  // namespace hc::ingest::detail
