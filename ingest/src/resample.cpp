#include "resample.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "heightcast/core/parallel.h"

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
    if (!(std::isnan(a) || std::isnan(b) || std::isnan(c) || std::isnan(d))) {
        double top = a + (b - a) * fx, bottom = c + (d - c) * fx;
        return static_cast<float>(top + (bottom - top) * fy);
    }
    // Next to a hole: the hole's edge stays where the nearest pixel puts it, and the value is the
    // bilinear weights renormalised over the valid neighbours (as GDAL's warper does), so no
    // nodata value ever leaks into an average.
    if (std::isnan(s.at(static_cast<size_t>(col), static_cast<size_t>(row)))) return nan;
    double wt[4] = {(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy};
    float vals[4] = {a, b, c, d};
    double sum = 0, weight = 0;
    for (int k = 0; k < 4; ++k)
        if (!std::isnan(vals[k])) sum += wt[k] * vals[k], weight += wt[k];
    return weight > 0 ? static_cast<float>(sum / weight) : s.at(static_cast<size_t>(col), static_cast<size_t>(row));
}

}  // namespace

int resample(const SourceBand& source, const TargetToSource& map, Raster& target, int lattice, double maxErrorPx,
             unsigned threads) {
    const size_t w = target.width, h = target.height;
    target.values.assign(w * h, std::numeric_limits<float>::quiet_NaN());
    struct Node {
        double col, row;
        bool ok;
    };
    auto centre = [&](double c, double r, double& x, double& y) {
        x = target.westWorld + (c + 0.5) * target.pixelSizeM;
        y = target.northWorld - (r + 0.5) * target.pixelSizeM;
    };
    // Exact map at lattice nodes (the centres of every step-th row and column). The step halves until
    // interpolating between nodes stays within maxErrorPx of the exact map at every lattice-cell centre.
    size_t step = static_cast<size_t>(std::max(lattice, 1)), lw = 0, lh = 0;
    std::vector<Node> nodes;
    for (;;) {
        lw = (w + step - 1) / step + 1;
        lh = (h + step - 1) / step + 1;
        nodes.assign(lw * lh, Node{});
        parallelFor(lh, 8, threads, [&](size_t b, size_t e, unsigned) {
            for (size_t j = b; j < e; ++j)
                for (size_t i = 0; i < lw; ++i) {
                    double x, y;
                    centre(double(i * step), double(j * step), x, y);
                    Node& n = nodes[j * lw + i];
                    n.ok = map(x, y, n.col, n.row);
                }
        });
        if (step == 1) break;
        std::vector<double> worst(resolveThreads(threads), 0.0);
        parallelFor(lh - 1, 8, threads, [&](size_t b, size_t e, unsigned worker) {
            for (size_t j = b; j < e; ++j)
                for (size_t i = 0; i + 1 < lw; ++i) {
                    const Node *a = &nodes[j * lw + i], *bb = a + 1, *c = a + lw, *d = c + 1;
                    if (!(a->ok && bb->ok && c->ok && d->ok)) continue;
                    double x, y, col, row;
                    centre(double(i * step) + 0.5 * double(step), double(j * step) + 0.5 * double(step), x, y);
                    if (!map(x, y, col, row)) continue;
                    double ic = 0.25 * (a->col + bb->col + c->col + d->col), ir = 0.25 * (a->row + bb->row + c->row + d->row);
                    worst[worker] = std::max({worst[worker], std::abs(ic - col), std::abs(ir - row)});
                }
        });
        if (*std::max_element(worst.begin(), worst.end()) <= maxErrorPx) break;
        step /= 2;
    }
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
                    double x, y;
                    centre(double(c), double(r), x, y);
                    if (!map(x, y, col, row)) continue;
                }
                target.values[r * w + c] = sampleBilinear(source, col, row);
            }
        }
    });
    return static_cast<int>(step);
}

}  // namespace hc::ingest::detail
