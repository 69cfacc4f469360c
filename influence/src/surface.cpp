#include "heightcast/influence/surface.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>

#include "heightcast/core/parallel.h"

#include "heightcast/core/error.h"
#include "kernel_sums.h"

namespace hc::influence {

Layer Layer::byName(const Grid& grid, const std::string& name) {
    Layer l;
    std::string have;
    for (const auto& g : grid.layers) have += (have.empty() ? "" : ", ") + g.name;
    if (name == "water_surface" || name == "water_depth") {
        if (grid.findLayer("water_depth") < 0)
            throw Error("no layer '" + name + "': the grid has no water (it has: " + have +
                        "; hc-ingest --water, --water-surface or --water-level adds it)");
        l.kind = name == "water_surface" ? WaterSurface : WaterDepth;
        return l;
    }
    int i = grid.findLayer(name);
    if (i < 0) {
        if (grid.findLayer("water_depth") >= 0) have += ", water_surface";
        throw Error("no layer '" + name + "' in the grid (it has: " + have + ")");
    }
    l.index = static_cast<size_t>(i);
    if (l.index > grid.firstStepLayer()) l.kind = WaterCells;  // a step layer after water_depth: wet cells only
    return l;
}

SurfaceEvaluator::SurfaceEvaluator(const Grid& grid, const InfluenceLists& lists)
    : grid_(grid), lists_(lists), tail_(lists.params().tail()) {
    if (lists.cellCount() != grid.cellCount() || lists.gridStructureHash() != grid.structureHash())
        throw Error("influence lists do not belong to this grid");
    const size_t n = grid.cellCount();
    k_.resize(n);
    const double sigma = lists.params().sigma;
    for (size_t i = 0; i < n; ++i) {
        grid.cellCenterLocal(i, k_[i].cx, k_[i].cy);
        const double c = grid.cellSizeM(i);
        const double r = lists.params().radiusM(c);
        k_[i].r2 = r * r;
        k_[i].a = 1.0 / (2.0 * sigma * sigma * c * c);
    }
    depthLayer_ = grid.findLayer("water_depth");
}

// The sums run over values relative to a base, the containing cell's own value v_k:
//   v(p) = v_k + sum_i w_i (v_i - v_k) / sum_i w_i
// Equal to the plain weighted mean in exact arithmetic, but a constant field comes out exactly
// constant, and centimetre relief at 8000 m keeps its digits (no large products to cancel). The water
// level's base is a wet cell's level (levelBase), so a constant level stays exactly constant too.
void SurfaceEvaluator::sums(size_t k, double x, double y, size_t l, const float* depth, bool addDepth, double base,
                            double& num, double& den, double* dnum, double* dden) const {
    const float* v = grid_.values[l].data();
    num = den = 0;
    double gnx = 0, gny = 0, gdx = 0, gdy = 0;
    for (uint32_t i : lists_.list(k)) {
        if (depth && !(depth[i] > 0)) continue;  // the level field takes wet cells only
        const Kernel& q = k_[i];
        const double dx = x - q.cx, dy = y - q.cy;
        const double d2 = dx * dx + dy * dy;
        if (!(d2 < q.r2)) continue;
        const double e = std::exp(-d2 * q.a);
        const double w = e - tail_;
        if (w <= 0) continue;
        const double rel = (depth && addDepth ? double(v[i]) + double(depth[i]) : double(v[i])) - base;
        num += w * rel;
        den += w;
        if (dnum) {
            // dw/dx = e * (-2 a dx): the tail is constant.
            const double gx = -2.0 * q.a * e * dx, gy = -2.0 * q.a * e * dy;
            gnx += gx * rel;
            gny += gy * rel;
            gdx += gx;
            gdy += gy;
        }
    }
    if (dnum) {
        dnum[0] = gnx;
        dnum[1] = gny;
        dden[0] = gdx;
        dden[1] = gdy;
    }
}

double SurfaceEvaluator::levelBase(size_t k, size_t l) const {
    const float* v = grid_.values[l].data();
    const float* d = grid_.values[static_cast<size_t>(depthLayer_)].data();
    auto of = [&](size_t i) { return l == 0 ? double(v[i]) + double(d[i]) : double(v[i]); };
    if (d[k] > 0) return of(k);
    for (uint32_t i : lists_.list(k))
        if (d[i] > 0) return of(i);
    return std::numeric_limits<double>::quiet_NaN();
}

std::optional<ValueGradient> SurfaceEvaluator::evaluate(double x, double y, const Layer& layer, bool gradient) const {
    const std::optional<uint32_t> k = grid_.locate(x, y);
    if (!k) return std::nullopt;
    // The weighted mean of `l` (or, with `depth`, of the wet cells' level) from `base`, and the sum of
    // the weights it took.
    auto one = [&](size_t l, const float* depth, double base, double& den) {
        double num, dn[2], dd[2];
        sums(*k, x, y, l, depth, l == 0, base, num, den, gradient ? dn : nullptr, gradient ? dd : nullptr);
        ValueGradient r{base + num / den, 0, 0};
        if (gradient) {  // quotient rule (the base is a constant)
            r.dx = (dn[0] * den - num * dd[0]) / (den * den);
            r.dy = (dn[1] * den - num * dd[1]) / (den * den);
        }
        return r;
    };
    double denAll, denWet = 0;
    if (layer.kind == Layer::Cells) return one(layer.index, nullptr, grid_.values[layer.index][*k], denAll);
    // Water (docs/design.md section 6, surface.h): the level field of the wet cells, drawn where they hold at
    // least kWetShareMin of the weight and the level lies above the smooth terrain.
    const ValueGradient z = one(0, nullptr, grid_.values[0][*k], denAll);
    const double base = levelBase(*k);
    std::optional<ValueGradient> level;
    if (!std::isnan(base)) {
        const float* depth = grid_.values[static_cast<size_t>(depthLayer_)].data();
        const ValueGradient l = one(0, depth, base, denWet);
        // denWet > 0 before the division counts: with no wet weight at p the quotient is 0 / 0.
        if (denWet > 0 && denWet >= kWetShareMin * denAll && l.value > z.value) level = l;
    }
    if (layer.kind == Layer::WaterSurface) return level;
    if (layer.kind == Layer::WaterCells) {  // the wet cells' values, where water is drawn (surface.h)
        if (!level) return std::nullopt;
        double den = 0;
        return one(layer.index, grid_.values[static_cast<size_t>(depthLayer_)].data(), levelBase(*k, layer.index), den);
    }
    if (!level) return ValueGradient{0, 0, 0};  // dry land: no water, depth 0
    return ValueGradient{level->value - z.value, level->dx - z.dx, level->dy - z.dy};
}

std::optional<double> SurfaceEvaluator::value(double x, double y, const Layer& layer) const {
    auto r = evaluate(x, y, layer, false);
    if (!r) return std::nullopt;
    return r->value;
}

std::optional<ValueGradient> SurfaceEvaluator::valueGradient(double x, double y, const Layer& layer) const {
    return evaluate(x, y, layer, true);
}

std::vector<std::optional<double>> SurfaceEvaluator::values(std::span<const std::array<double, 2>> pts,
                                                            const Layer& layer, unsigned threads) const {
    std::vector<std::optional<double>> out(pts.size());
    if (layer.kind == Layer::WaterCells) {  // rare (a probe of velocity): one point at a time, as value() does
        parallelFor(pts.size(), 1024, threads, [&](size_t b, size_t e, unsigned) {
            for (size_t i = b; i < e; ++i) out[i] = value(pts[i][0], pts[i][1], layer);
        });
        return out;
    }
    // Sort by containing cell; points in holes keep their nullopt.
    std::vector<std::pair<uint32_t, uint32_t>> order;  // (cell, point)
    order.reserve(pts.size());
    const unsigned workers = resolveThreads(threads);
    std::vector<std::vector<std::pair<uint32_t, uint32_t>>> parts(workers);
    parallelFor(pts.size(), 16384, threads, [&](size_t b, size_t e, unsigned w) {
        for (size_t i = b; i < e; ++i)
            if (auto k = grid_.locate(pts[i][0], pts[i][1])) parts[w].emplace_back(*k, static_cast<uint32_t>(i));
    });
    for (auto& p : parts) order.insert(order.end(), p.begin(), p.end());
    std::sort(order.begin(), order.end());

    // The same sums as sums() (relative to the cell's own values), without gradients, vectorised across
    // list entries: the layer asked for; for water, the elevation and the wet cells' level (surface.h).
    const bool water = layer.kind != Layer::Cells;
    const float* v0 = grid_.values[water ? 0 : layer.index].data();
    const float* depth = water ? grid_.values[static_cast<size_t>(depthLayer_)].data() : nullptr;
    std::vector<detail::Gathered> scratch(workers);
    parallelFor(order.size(), 4096, threads, [&](size_t b, size_t e, unsigned worker) {
        detail::Gathered& g = scratch[worker];
        // A chunk may start inside a run of points of one cell: that is fine, the run is gathered twice.
        for (size_t j = b; j < e;) {
            const uint32_t k = order[j].first;
            size_t runEnd = j + 1;
            while (runEnd < e && order[runEnd].first == k) ++runEnd;
            const Kernel& kk = k_[k];
            const double base0 = v0[k], base1 = water ? levelBase(k) : 0.0;
            const bool anyWet = water && !std::isnan(base1);
            const auto list = lists_.list(k);
            g.reset(list.size());
            for (size_t idx = 0; idx < list.size(); ++idx) {
                const uint32_t i = list[idx];
                g.ex[idx] = k_[i].cx - kk.cx;
                g.ey[idx] = k_[i].cy - kk.cy;
                g.a[idx] = k_[i].a;
                g.r2[idx] = k_[i].r2;
                g.rel0[idx] = v0[i] - base0;
                if (anyWet && depth[i] > 0) {
                    g.wet[idx] = 1.0;
                    g.rel1[idx] = double(v0[i]) + double(depth[i]) - base1;
                }
            }
            for (; j < runEnd; ++j) {
                const uint32_t p = order[j].second;
                const double px = pts[p][0] - kk.cx, py = pts[p][1] - kk.cy;
                const detail::KernelSums sum = detail::sumKernels(g, px, py, tail_);
                const double n0 = sum.num0, n1 = sum.num1, d = sum.den, dw = sum.denWet;
                // d >= the cell's own weight at its farthest point (kernel.h): never zero here.
                const double z = base0 + n0 / d;
                if (!water) {
                    out[p] = z;
                    continue;
                }
                // The water rule of surface.h, as in evaluate().
                const double level = base1 + n1 / dw;
                const bool drawn = dw > 0 && dw >= kWetShareMin * d && level > z;
                if (layer.kind == Layer::WaterDepth)
                    out[p] = drawn ? level - z : 0.0;
                else if (drawn)
                    out[p] = level;
            }
        }
    });
    return out;
}

std::optional<double> SurfaceEvaluator::valueBruteForce(double x, double y, const Layer& layer) const {
    if (!grid_.locate(x, y)) return std::nullopt;
    // Plain weighted means over every cell (no base): `wetLevel` takes z + d of the wet cells only.
    const float* depth = depthLayer_ >= 0 ? grid_.values[static_cast<size_t>(depthLayer_)].data() : nullptr;
    auto one = [&](size_t l, bool wet, double& den) {
        double num = 0;
        den = 0;
        for (size_t i = 0; i < grid_.cellCount(); ++i) {
            if (wet && !(depth[i] > 0)) continue;
            const double dx = x - k_[i].cx, dy = y - k_[i].cy;
            const double w = std::max(0.0, std::exp(-(dx * dx + dy * dy) * k_[i].a) - tail_);
            num += w * (double(grid_.values[l][i]) + (wet && l == 0 ? double(depth[i]) : 0.0));
            den += w;
        }
        return num / den;
    };
    double denAll, denWet;
    if (layer.kind == Layer::Cells) return one(layer.index, false, denAll);
    const double z = one(0, false, denAll);
    const double level = one(0, true, denWet);
    const bool drawn = denWet > 0 && denWet >= kWetShareMin * denAll && level > z;
    if (layer.kind == Layer::WaterCells) {
        if (!drawn) return std::nullopt;
        return one(layer.index, true, denWet);
    }
    if (layer.kind == Layer::WaterDepth) return drawn ? level - z : 0.0;
    if (!drawn) return std::nullopt;
    return level;
}

}  // namespace hc::influence
