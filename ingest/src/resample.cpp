#include "resample.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>

#include "heightcast/core/parallel.h"

namespace hc::ingest::detail {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

float sampleBilinear(const SourceView& s, double col, double row) {
    if (!(col >= 0 && row >= 0 && col < static_cast<double>(s.width) && row < static_cast<double>(s.height)))
        return kNaN;
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
    if (std::isnan(s.at(static_cast<size_t>(col), static_cast<size_t>(row)))) return kNaN;
    double wt[4] = {(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy};
    float vals[4] = {a, b, c, d};
    double sum = 0, weight = 0;
    for (int k = 0; k < 4; ++k)
        if (!std::isnan(vals[k])) sum += wt[k] * vals[k], weight += wt[k];
    return weight > 0 ? static_cast<float>(sum / weight) : s.at(static_cast<size_t>(col), static_cast<size_t>(row));
}

struct Node {
    double col, row;
    bool ok;
};

// World position of the centre of target pixel (c, r) (fractional allowed).
void centre(const Raster& t, double c, double r, double& x, double& y) {
    x = t.westWorld + (c + 0.5) * t.pixelSizeM;
    y = t.northWorld - (r + 0.5) * t.pixelSizeM;
}

// Lattice nodes (step-th rows and columns of the whole target) of rows j0..j1 and columns i0..i1: the map exactly.
std::vector<Node> nodesOf(const Raster& t, const TargetToSource& map, size_t step, size_t i0, size_t i1, size_t j0,
                          size_t j1, unsigned threads) {
    const size_t lw = i1 - i0 + 1;
    std::vector<Node> nodes((j1 - j0 + 1) * lw);
    parallelFor(j1 - j0 + 1, 8, threads, [&](size_t b, size_t e, unsigned) {
        for (size_t j = b; j < e; ++j)
            for (size_t i = 0; i < lw; ++i) {
                double x, y;
                centre(t, double((i0 + i) * step), double((j0 + j) * step), x, y);
                Node& n = nodes[j * lw + i];
                n.ok = map(x, y, n.col, n.row);
            }
    });
    return nodes;
}

// The source position of target pixel (c, r) of a window whose lattice nodes are `nodes` (columns i0.., rows j0..,
// lw a row): the exact map at a node, bilinear between four nodes, exact again where a node lies outside the map's
// domain. False where the pixel has no source position.
bool sourceOf(const Raster& t, const TargetToSource& map, size_t step, const std::vector<Node>& nodes, size_t i0,
              size_t j0, size_t lw, size_t c, size_t r, double& col, double& row) {
    const size_t j = r / step, i = c / step;
    const double fy = static_cast<double>(r - j * step) / static_cast<double>(step);
    const double fx = static_cast<double>(c - i * step) / static_cast<double>(step);
    const Node& n00 = nodes[(j - j0) * lw + (i - i0)];
    const Node& n10 = nodes[(j - j0) * lw + (i - i0) + 1];
    const Node& n01 = nodes[(j - j0 + 1) * lw + (i - i0)];
    const Node& n11 = nodes[(j - j0 + 1) * lw + (i - i0) + 1];
    if (fx == 0 && fy == 0) {
        if (!n00.ok) return false;
        col = n00.col;
        row = n00.row;
    } else if (n00.ok && n10.ok && n01.ok && n11.ok) {
        col = (n00.col * (1 - fx) + n10.col * fx) * (1 - fy) + (n01.col * (1 - fx) + n11.col * fx) * fy;
        row = (n00.row * (1 - fx) + n10.row * fx) * (1 - fy) + (n01.row * (1 - fx) + n11.row * fx) * fy;
    } else {  // near the edge of the map's domain: evaluate exactly
        double x, y;
        centre(t, double(c), double(r), x, y);
        if (!map(x, y, col, row)) return false;
    }
    return true;
}

// The lattice rows and columns a window of the target needs: every pixel's four nodes.
void windowLattice(size_t step, size_t col0, size_t row0, size_t w, size_t h, size_t& i0, size_t& i1, size_t& j0,
                   size_t& j1) {
    i0 = col0 / step, i1 = (col0 + w - 1) / step + 1;
    j0 = row0 / step, j1 = (row0 + h - 1) / step + 1;
}

}  // namespace

int latticeStep(const Raster& target, const TargetToSource& map, int lattice, double maxErrorPx, unsigned threads) {
    const size_t w = target.width, h = target.height;
    // Exact map at lattice nodes (the centres of every step-th row and column). The step halves until
    // interpolating between nodes stays within maxErrorPx of the exact map at every lattice-cell centre.
    // Row by row of lattice cells (two rows of nodes at a time), so that no lattice of the whole target is held.
    size_t step = static_cast<size_t>(std::max(lattice, 1));
    for (; step > 1; step /= 2) {
        const size_t lw = (w + step - 1) / step + 1, lh = (h + step - 1) / step + 1;
        std::vector<double> worst(resolveThreads(threads), 0.0);
        parallelFor(lh - 1, 8, threads, [&](size_t b, size_t e, unsigned worker) {
            std::vector<Node> rows = nodesOf(target, map, step, 0, lw - 1, b, b, 1);
            for (size_t j = b; j < e; ++j) {
                std::vector<Node> next = nodesOf(target, map, step, 0, lw - 1, j + 1, j + 1, 1);
                for (size_t i = 0; i + 1 < lw; ++i) {
                    const Node *a = &rows[i], *bb = a + 1, *c = &next[i], *d = c + 1;
                    if (!(a->ok && bb->ok && c->ok && d->ok)) continue;
                    double x, y, col, row;
                    centre(target, double(i * step) + 0.5 * double(step), double(j * step) + 0.5 * double(step), x, y);
                    if (!map(x, y, col, row)) continue;
                    double ic = 0.25 * (a->col + bb->col + c->col + d->col),
                           ir = 0.25 * (a->row + bb->row + c->row + d->row);
                    worst[worker] = std::max({worst[worker], std::abs(ic - col), std::abs(ir - row)});
                }
                rows.swap(next);
            }
        });
        if (*std::max_element(worst.begin(), worst.end()) <= maxErrorPx) break;
    }
    return static_cast<int>(step);
}

namespace {

// The source pixels [c0, c1] x [r0, r1] that target pixels [col0, col0 + w) x [row0, row0 + h) read, from the window's
// lattice nodes (columns i0..i1, rows j0..j1); false when none lies on the source.
bool sourceWindowOf(const Raster& target, const TargetToSource& map, size_t s, const std::vector<Node>& nodes,
                    size_t i0, size_t i1, size_t j0, size_t j1, size_t col0, size_t row0, size_t w, size_t h,
                    size_t sourceWidth, size_t sourceHeight, size_t& c0, size_t& r0, size_t& c1, size_t& r1,
                    unsigned threads) {
    if (sourceWidth == 0 || sourceHeight == 0) return false;
    struct Box {
        double cMin = HUGE_VAL, cMax = -HUGE_VAL, rMin = HUGE_VAL, rMax = -HUGE_VAL;
    };
    // A pixel between four nodes the map reaches lies within their box (bilinear weights are convex), so each lattice
    // cell's nodes bound its pixels; only pixels of cells with a node outside the map's domain are mapped one by one.
    const size_t lw = i1 - i0 + 1;
    std::vector<Box> boxes(resolveThreads(threads));
    parallelFor(j1 - j0, 8, threads, [&](size_t b, size_t e, unsigned worker) {
        Box& box = boxes[worker];
        auto add = [&](double col, double row) {
            box.cMin = std::min(box.cMin, col), box.cMax = std::max(box.cMax, col);
            box.rMin = std::min(box.rMin, row), box.rMax = std::max(box.rMax, row);
        };
        for (size_t j = b; j < e; ++j)
            for (size_t i = 0; i + 1 < lw; ++i) {
                const Node* n[4] = {&nodes[j * lw + i], &nodes[j * lw + i + 1], &nodes[(j + 1) * lw + i],
                                    &nodes[(j + 1) * lw + i + 1]};
                if (n[0]->ok && n[1]->ok && n[2]->ok && n[3]->ok) {
                    for (const Node* q : n) add(q->col, q->row);
                    continue;
                }
                // The window's pixels of this lattice cell, as resampleWindow maps them.
                const size_t rLo = std::max(row0, (j0 + j) * s), rHi = std::min(row0 + h, (j0 + j + 1) * s);
                const size_t cLo = std::max(col0, (i0 + i) * s), cHi = std::min(col0 + w, (i0 + i + 1) * s);
                for (size_t r = rLo; r < rHi; ++r)
                    for (size_t c = cLo; c < cHi; ++c) {
                        double col, row;
                        if (sourceOf(target, map, s, nodes, i0, j0, lw, c, r, col, row)) add(col, row);
                    }
            }
    });
    Box all;
    for (const Box& b : boxes)
        all.cMin = std::min(all.cMin, b.cMin), all.cMax = std::max(all.cMax, b.cMax),
        all.rMin = std::min(all.rMin, b.rMin), all.rMax = std::max(all.rMax, b.rMax);
    // Clipped to the source: positions outside it read nothing (sampleBilinear gives NaN there).
    all.cMin = std::max(all.cMin, 0.0), all.rMin = std::max(all.rMin, 0.0);
    all.cMax = std::min(all.cMax, std::nextafter(double(sourceWidth), 0.0));
    all.rMax = std::min(all.rMax, std::nextafter(double(sourceHeight), 0.0));
    if (!(all.cMin <= all.cMax && all.rMin <= all.rMax)) return false;
    // sampleBilinear reads the 2 x 2 stencil about (col - 0.5, row - 0.5) and the pixel under (col, row).
    auto lo = [](double v) { return size_t(std::max(0.0, std::floor(v - 0.5))); };
    auto hi = [](double v, size_t n) { return std::min(n - 1, size_t(std::max(0L, long(std::floor(v - 0.5)) + 1))); };
    c0 = lo(all.cMin), r0 = lo(all.rMin);
    c1 = std::max(hi(all.cMax, sourceWidth), std::min(sourceWidth - 1, size_t(all.cMax)));
    r1 = std::max(hi(all.rMax, sourceHeight), std::min(sourceHeight - 1, size_t(all.rMax)));
    return true;
}

}  // namespace

void resampleWindow(const TargetToSource& map, const Raster& target, int step, size_t col0, size_t row0, size_t w,
                    size_t h, size_t sourceWidth, size_t sourceHeight,
                    const std::function<SourceView(size_t c0, size_t r0, size_t c1, size_t r1)>& read, float* out,
                    unsigned threads) {
    std::fill(out, out + w * h, kNaN);
    if (w == 0 || h == 0) return;
    const size_t s = size_t(step);
    size_t i0, i1, j0, j1;
    windowLattice(s, col0, row0, w, h, i0, i1, j0, j1);
    const std::vector<Node> nodes = nodesOf(target, map, s, i0, i1, j0, j1, threads);
    size_t c0 = 0, r0 = 0, c1 = 0, r1 = 0;
    if (!sourceWindowOf(target, map, s, nodes, i0, i1, j0, j1, col0, row0, w, h, sourceWidth, sourceHeight, c0, r0, c1,
                        r1, threads))
        return;
    const SourceView source = read(c0, r0, c1, r1);
    parallelFor(h, 32, threads, [&](size_t b, size_t e, unsigned) {
        for (size_t r = row0 + b; r < row0 + e; ++r)
            for (size_t c = col0; c < col0 + w; ++c) {
                double col, row;
                if (!sourceOf(target, map, s, nodes, i0, j0, i1 - i0 + 1, c, r, col, row)) continue;
                out[(r - row0) * w + (c - col0)] = sampleBilinear(source, col, row);
            }
    });
}

int resample(const SourceBand& source, const TargetToSource& map, Raster& target, int lattice, double maxErrorPx,
             unsigned threads) {
    const int step = latticeStep(target, map, lattice, maxErrorPx, threads);
    target.values.assign(target.width * target.height, kNaN);
    const SourceView whole{source.values.data(), 0, 0, source.width, source.width, source.height};
    resampleWindow(
        map, target, step, 0, 0, target.width, target.height, source.width, source.height,
        [&](size_t, size_t, size_t, size_t) { return whole; }, target.values.data(), threads);
    return step;
}

}  // namespace hc::ingest::detail
