#include "heightcast/influence/surface.h"

#include <algorithm>
#include <cmath>

#include "heightcast/grid/parallel.h"

#include "heightcast/grid/error.h"

namespace hc::influence {

Layer Layer::byName(const Grid& grid, const std::string& name) {
    Layer l;
    if (name == "water_surface") {
        if (grid.findLayer("water_depth") < 0) throw Error("layer water_surface needs a water_depth layer, and the grid has none");
        l.kind = WaterSurface;
        return l;
    }
    int i = grid.findLayer(name);
    if (i < 0) {
        std::string have;
        for (const auto& g : grid.layers) have += (have.empty() ? "" : ", ") + g.name;
        if (grid.findLayer("water_depth") >= 0) have += ", water_surface";
        throw Error("no layer '" + name + "' in the grid (it has: " + have + ")");
    }
    l.index = static_cast<size_t>(i);
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

// The sums run over values relative to the containing cell's own value v_k:
//   v(p) = v_k + sum_i w_i (v_i - v_k) / sum_i w_i
// Equal to the plain weighted mean in exact arithmetic, but a constant field comes out exactly
// constant, and centimetre relief at 8000 m keeps its digits (no large products to cancel).
void SurfaceEvaluator::sums(size_t k, double x, double y, size_t l, double& num, double& den, double* dnum, double* dden) const {
    const float* v = grid_.values[l].data();
    const double base = v[k];
    num = den = 0;
    double gnx = 0, gny = 0, gdx = 0, gdy = 0;
    for (uint32_t i : lists_.list(k)) {
        const Kernel& q = k_[i];
        const double dx = x - q.cx, dy = y - q.cy;
        const double d2 = dx * dx + dy * dy;
        if (!(d2 < q.r2)) continue;
        const double e = std::exp(-d2 * q.a);
        const double w = e - tail_;
        if (w <= 0) continue;
        const double rel = v[i] - base;
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

std::optional<ValueGradient> SurfaceEvaluator::evaluate(double x, double y, const Layer& layer, bool gradient) const {
    const std::optional<uint32_t> k = grid_.locate(x, y);
    if (!k) return std::nullopt;
    auto one = [&](size_t l) {
        double num, den, dn[2], dd[2];
        sums(*k, x, y, l, num, den, gradient ? dn : nullptr, gradient ? dd : nullptr);
        ValueGradient r{static_cast<double>(grid_.values[l][*k]) + num / den, 0, 0};
        if (gradient) {  // quotient rule (the base value is a constant)
            r.dx = (dn[0] * den - num * dd[0]) / (den * den);
            r.dy = (dn[1] * den - num * dd[1]) / (den * den);
        }
        return r;
    };
    if (layer.kind == Layer::Cells) return one(layer.index);
    ValueGradient depth = one(static_cast<size_t>(depthLayer_));
    if (!(depth.value > 0)) return std::nullopt;  // dry: no water surface here
    ValueGradient z = one(0);
    return ValueGradient{z.value + depth.value, z.dx + depth.dx, z.dy + depth.dy};
}

std::optional<double> SurfaceEvaluator::value(double x, double y, const Layer& layer) const {
    auto r = evaluate(x, y, layer, false);
    if (!r) return std::nullopt;
    return r->value;
}

std::optional<ValueGradient> SurfaceEvaluator::valueGradient(double x, double y, const Layer& layer) const {
    return evaluate(x, y, layer, true);
}

std::vector<std::optional<double>> SurfaceEvaluator::values(std::span<const std::array<double, 2>> pts, const Layer& layer,
                                                            unsigned threads) const {
    std::vector<std::optional<double>> out(pts.size());
    // Sort by containing cell; points in holes keep their nullopt.
    std::vector<std::pair<uint32_t, uint32_t>> order;  // (cell, point)
    order.reserve(pts.size());
    std::vector<std::vector<std::pair<uint32_t, uint32_t>>> parts(resolveThreads(threads));
    parallelFor(pts.size(), 16384, threads, [&](size_t b, size_t e, unsigned w) {
        for (size_t i = b; i < e; ++i)
            if (auto k = grid_.locate(pts[i][0], pts[i][1])) parts[w].emplace_back(*k, static_cast<uint32_t>(i));
    });
    for (auto& p : parts) order.insert(order.end(), p.begin(), p.end());
    std::sort(order.begin(), order.end());
    parallelFor(order.size(), 4096, threads, [&](size_t b, size_t e, unsigned) {
        for (size_t j = b; j < e; ++j) {
            const uint32_t i = order[j].second;
            if (auto r = evaluate(pts[i][0], pts[i][1], layer, false)) out[i] = r->value;
        }
    });
    return out;
}

std::optional<double> SurfaceEvaluator::valueBruteForce(double x, double y, const Layer& layer) const {
    if (!grid_.locate(x, y)) return std::nullopt;
    auto one = [&](size_t l) {
        double num = 0, den = 0;
        for (size_t i = 0; i < grid_.cellCount(); ++i) {
            const double dx = x - k_[i].cx, dy = y - k_[i].cy;
            const double w = std::max(0.0, std::exp(-(dx * dx + dy * dy) * k_[i].a) - tail_);
            num += w * grid_.values[l][i];
            den += w;
        }
        return num / den;
    };
    if (layer.kind == Layer::Cells) return one(layer.index);
    double depth = one(static_cast<size_t>(depthLayer_));
    if (!(depth > 0)) return std::nullopt;
    return one(0) + depth;
}

}  // namespace hc::influence
