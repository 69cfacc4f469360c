#include "heightcast/influence/surface.h"

#include <cmath>

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
    cx_.resize(n);
    cy_.resize(n);
    r2_.resize(n);
    a_.resize(n);
    const double sigma = lists.params().sigma;
    for (size_t i = 0; i < n; ++i) {
        grid.cellCenterLocal(i, cx_[i], cy_[i]);
        const double c = grid.cellSizeM(i);
        const double r = lists.params().radiusM(c);
        r2_[i] = r * r;
        a_[i] = 1.0 / (2.0 * sigma * sigma * c * c);
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
        const double dx = x - cx_[i], dy = y - cy_[i];
        const double d2 = dx * dx + dy * dy;
        if (!(d2 < r2_[i])) continue;
        const double e = std::exp(-d2 * a_[i]);
        const double w = e - tail_;
        if (w <= 0) continue;
        const double rel = v[i] - base;
        num += w * rel;
        den += w;
        if (dnum) {
            // dw/dx = e * (-2 a dx): the tail is constant.
            const double gx = -2.0 * a_[i] * e * dx, gy = -2.0 * a_[i] * e * dy;
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

std::optional<double> SurfaceEvaluator::valueBruteForce(double x, double y, const Layer& layer) const {
    if (!grid_.locate(x, y)) return std::nullopt;
    auto one = [&](size_t l) {
        double num = 0, den = 0;
        for (size_t i = 0; i < grid_.cellCount(); ++i) {
            const double dx = x - cx_[i], dy = y - cy_[i];
            const double w = std::max(0.0, std::exp(-(dx * dx + dy * dy) * a_[i]) - tail_);
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
