// render/src/beam.cpp: a tile's rays as one beam marched over a cascade's max mipmap (detail::Beam, frame.h): the depth
// before which none of its rays can come down to a node's maximum, where raycast.cpp's walks then start.
#include <algorithm>
#include <cmath>
#include <limits>

#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <glm/vec2.hpp>

#include "heightcast/render/detail/frame.h"

namespace hc::render::detail {

Beam::Beam(const RayContext& ctx, const CameraBasis& basis, double sx0, double sy0, double sx1, double sy1, Beam* outer)
    : ctx_(ctx), outer_(outer) {
    const glm::dvec3 corners[4] = {
        basis.forward + sx0 * basis.right + sy0 * basis.up, basis.forward + sx1 * basis.right + sy0 * basis.up,
        basis.forward + sx0 * basis.right + sy1 * basis.up, basis.forward + sx1 * basis.right + sy1 * basis.up};
    lo_ = hi_ = corners[0];
    minDot_ = maxDot_ = glm::dot(glm::dvec2(corners[0]), ctx.fit->dir);
    for (const glm::dvec3& c : corners) {  // every quantity below is linear in (sx, sy): its extremes are at corners
        lo_ = glm::min(lo_, c), hi_ = glm::max(hi_, c);
        maxLen_ = std::max(maxLen_, glm::length(c));
        const double rate = glm::dot(glm::dvec2(c), ctx.fit->dir);
        minDot_ = std::min(minDot_, rate), maxDot_ = std::max(maxDot_, rate);
    }
    width_ = std::max(std::abs(sx1 - sx0), std::abs(sy1 - sy0));
    centreLen_ = glm::length(basis.forward + 0.5 * (sx0 + sx1) * basis.right + 0.5 * (sy0 + sy1) * basis.up);
    depth_.fill(std::numeric_limits<double>::quiet_NaN());
}

double Beam::firstStartDepth(size_t k) {
    if (k >= depth_.size() || k >= ctx_.fit->cascades.size()) return 0;
    if (std::isnan(depth_[k])) depth_[k] = march(k);
    return depth_[k];
}

// The beam's footprint over depths [ta, tb] is inside the box of its corners' at ta and at tb (each ray's point moves
// on a line), and its lowest point is a corner's at ta or tb. A step is passed when that lowest point lies above the
// largest maximum of the nodes under the box (at most 2 x 2 of the level where the box spans two nodes): no ray of the
// beam can come down to a node's maximum there, so each one's walk would skip it. Steps double while they pass and
// halve when they do not, down to about the beam's width (or half a texel); a step of that size that fails ends the
// march.
double Beam::march(size_t k) {
    const Cascade& c = ctx_.fit->cascades[k];
    const CascadeTextures& tex = (*ctx_.tex)[k];
    const Heightfield& hf = tex.terrain;
    if (c.empty() || hf.mip.empty() || hf.n < 2) return 0;
    // The depths at which the beam's rays walk this cascade: t >= near (t = tau |direction|), offsets along the fit's
    // view direction (tau times the rate) within the cascade's slab.
    double tau = ctx_.nearM / maxLen_;
    if (k > 0 && c.splitNear > 0 && maxDot_ > 0) tau = std::max(tau, c.splitNear / maxDot_);
    double tauEnd = ctx_.farM;
    if (c.farWithOverlap > 0 && minDot_ > 0) tauEnd = std::min(tauEnd, c.farWithOverlap / minDot_);
    tau *= 1 - 1e-9;
    if (!(tau < tauEnd)) return 0;
    if (outer_) tau = std::max(tau, outer_->startDepth(k));  // none of the outer beam's rays meets the cascade before
    if (!(tau < tauEnd)) {
        passed_[k] = true;
        return tauEnd;
    }
    const bool water = tex.hasWater && tex.water.mip.size() == hf.mip.size();
    const bool both = water && tex.bothMip.size() == hf.mip.size();
    const int patches = hf.n - 1, top = int(hf.mip.size()) - 1;
    auto maxAt = [&](int level, size_t i) {
        if (both) return tex.bothMip[size_t(level)][i];
        const float m = hf.mip[size_t(level)][i];
        return water ? std::max(m, tex.water.mip[size_t(level)][i]) : m;
    };
    // The largest maximum of the patches under the box [ua, ub] x [va, vb] (texture coordinates): -inf off the texture.
    auto boxMax = [&](double ua, double ub, double va, double vb) {
        const double pad = 1e-6;  // a patch whose edge the box touches is under it (rounding)
        ua -= pad, va -= pad, ub += pad, vb += pad;
        if (!(ub >= 0 && vb >= 0 && ua < patches && va < patches)) return -std::numeric_limits<float>::infinity();
        const int i0 = ua > 0 ? int(ua) : 0, j0 = va > 0 ? int(va) : 0;
        const int i1 = ub < patches - 1 ? int(ub) : patches - 1, j1 = vb < patches - 1 ? int(vb) : patches - 1;
        int level = 0;
        while (level < top && ((i1 >> level) - (i0 >> level) > 1 || (j1 >> level) - (j0 >> level) > 1)) ++level;
        const size_t side = size_t(hf.mipSide[size_t(level)]);
        float m = -std::numeric_limits<float>::infinity();
        for (int j = j0 >> level; j <= j1 >> level; ++j)
            for (int i = i0 >> level; i <= i1 >> level; ++i)
                m = std::max(m, maxAt(level, size_t(j) * side + size_t(i)));
        return m;
    };
    const glm::dvec3& e = ctx_.eyeLocal;
    const double s = c.texelM;
    auto least = [&] { return std::max(tau * width_, 0.5 * s) / centreLen_; };  // [depth]: about the beam's width
    double step = least();
    for (int guard = 0; guard < 100000 && tau < tauEnd; ++guard) {
        const double tb = std::min(tau + step, tauEnd);
        const double zLow = e.z + std::min(tau * lo_.z, tb * lo_.z);
        const double ua = (e.x + std::min(tau * lo_.x, tb * lo_.x) - c.x0) / s,
                     ub = (e.x + std::max(tau * hi_.x, tb * hi_.x) - c.x0) / s;
        const double va = (e.y + std::min(tau * lo_.y, tb * lo_.y) - c.y0) / s,
                     vb = (e.y + std::max(tau * hi_.y, tb * hi_.y) - c.y0) / s;
        const float m = boxMax(ua, ub, va, vb);  // -inf: nothing under the box
        if (m == -std::numeric_limits<float>::infinity() ||
            zLow > m + 1e-9 * (1.0 + std::abs(e.z) + std::abs(zLow) + std::abs(m))) {
            tau = tb;
            step *= 2;
            continue;
        }
        const double smallest = least();
        if (step <= smallest) return tau;
        step = std::max(0.5 * step, smallest);
    }
    // Passed over the whole slab: every ray's span in this cascade ends by tauEnd (t = tau |direction|, up to rounding
    // far inside the 1e-9 margins of the test above), and no node under it was reached.
    passed_[k] = !(tau < tauEnd);
    return std::min(tau, tauEnd);
}

}  // namespace hc::render::detail
