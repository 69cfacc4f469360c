// render/src/ray_setup.cpp: what each ray's walk through each cascade needs from its direction alone
// (detail::setUpRays, frame.h: RaySetups), for a rectangle of rays at once, in vector registers; raycast.cpp's walks
// read it.
#include <cmath>
#include <vector>

#include <glm/geometric.hpp>
#include <glm/vec2.hpp>

#include "heightcast/render/detail/frame.h"

namespace hc::render::detail {

namespace {

// The constants of setUpSpans: one cascade's, the same for every ray (they start at the eye).
struct SpanConstants {
    double nearM, farM;
    double dirX, dirY;            // the fit's view direction
    double loNum, hiNum;          // lo - at0, hi - at0: the cascade's slab along the view, from the eye's offset
    double flatCap;               // a ray along the slab: +inf when the eye lies in it, else -inf (nothing there)
    double xLoNum, xHiNum, xCap;  // x0 - o.x, (x0 + ext) - o.x; a ray without x motion: +inf inside, -inf outside
    double yLoNum, yHiNum, yCap;
    double s;                     // the texel size
    double topDryNum, topWetNum;  // the cascade's highest point without water and with it, less o.z
};

// The spans, steps and crossings of n rays in one cascade (RaySetups), in the operations of a walk's set-up
// (raycast.cpp: hitIn()'s clips, traverse()'s texel ray and clipToHeights()), in vector registers: a lane's value
// differs from those of that code only where the ray has nothing in the cascade (t1 = -inf there, where those returned
// at once). Every condition is a select of two values computed in full: this file is built without floating-point traps
// (render/CMakeLists.txt).
void setUpSpans(size_t n, const double* __restrict dx, const double* __restrict dy, const double* __restrict dz,
                const SpanConstants& k, double* __restrict t0s, double* __restrict t1s, double* __restrict dus,
                double* __restrict dvs, double* __restrict idus, double* __restrict idvs, double* __restrict topDry,
                double* __restrict topWet) {
    for (size_t i = 0; i < n; ++i) {
        const double x = dx[i], y = dy[i];
        double t0 = k.nearM, t1 = k.farM;
        // The slab: where dot(xy - eye, dir) lies in [lo, hi]; a ray along it keeps its whole length or has nothing.
        const double rate = x * k.dirX + y * k.dirY;
        auto clip = [&](double loNum, double hiNum, double rateOrStep, bool none, double cap) {
            const double a = loNum / rateOrStep, b = hiNum / rateOrStep;
            const bool swap = a > b;
            const double lo = swap ? b : a, hi = swap ? a : b;
            const double m0 = t0 < lo ? lo : t0, m1 = hi < t1 ? hi : t1;  // std::max(t0, lo), std::min(t1, hi)
            const double c1 = cap < t1 ? cap : t1;
            t0 = none ? t0 : m0;
            t1 = none ? c1 : m1;
        };
        clip(k.loNum, k.hiNum, rate, std::abs(rate) < 1e-15, k.flatCap);
        // The texture's patch domain, in x and in y.
        clip(k.xLoNum, k.xHiNum, x, std::abs(x) < 1e-300, k.xCap);
        clip(k.yLoNum, k.yHiNum, y, std::abs(y) < 1e-300, k.yCap);
        t0s[i] = t0, t1s[i] = t1;
        const double du = x / k.s, dv = y / k.s;
        const double iu = 1.0 / du, iv = 1.0 / dv;
        dus[i] = du, dvs[i] = dv;
        idus[i] = du != 0 ? iu : 0.0, idvs[i] = dv != 0 ? iv : 0.0;
        topDry[i] = k.topDryNum / dz[i], topWet[i] = k.topWetNum / dz[i];
    }
}

void floorDepths(size_t n, const double* __restrict dz, double num, double* __restrict out) {
    for (size_t i = 0; i < n; ++i) out[i] = num / dz[i];
}

}  // namespace

void setUpRays(const RayContext& ctx, size_t n, const double* dx, const double* dy, const double* dz, RaySetups& out) {
    const auto& cs = ctx.fit->cascades;
    const glm::dvec3& o = ctx.eyeLocal;
    out.cascades.resize(cs.size());
    out.tFloor.resize(n);
    floorDepths(n, dz, ctx.zFloor - o.z, out.tFloor.data());
    const glm::dvec2 dir = ctx.fit->dir;
    const double eyeOffset = glm::dot(glm::dvec2(o), dir);
    const double at0 = glm::dot(glm::dvec2(o), dir) - eyeOffset;  // the eye's offset from itself: 0, as hitIn had it
    for (size_t k = 0; k < cs.size(); ++k) {
        const Cascade& c = cs[k];
        if (c.empty()) continue;  // hitIn returns before its setup
        RaySetups::Cascade& r = out.cascades[k];
        for (std::vector<double>* v : {&r.t0, &r.t1, &r.du, &r.dv, &r.invDu, &r.invDv, &r.tTopDry, &r.tTopWet})
            v->resize(n);
        const double s = c.texelM;
        r.u0 = (o.x - c.x0) / s, r.v0 = (o.y - c.y0) / s;
        const double lo = k == 0 ? -HUGE_VAL : c.splitNear, hi = c.farWithOverlap;
        const double ext = (c.n - 1) * c.texelM;
        SpanConstants sc{};
        sc.nearM = ctx.nearM, sc.farM = ctx.farM, sc.dirX = dir.x, sc.dirY = dir.y;
        sc.loNum = lo - at0, sc.hiNum = hi - at0, sc.flatCap = at0 >= lo && at0 <= hi ? HUGE_VAL : -HUGE_VAL;
        sc.xLoNum = c.x0 - o.x, sc.xHiNum = c.x0 + ext - o.x,
        sc.xCap = o.x < c.x0 || o.x > c.x0 + ext ? -HUGE_VAL : HUGE_VAL;
        sc.yLoNum = c.y0 - o.y, sc.yHiNum = c.y0 + ext - o.y,
        sc.yCap = o.y < c.y0 || o.y > c.y0 + ext ? -HUGE_VAL : HUGE_VAL;
        sc.s = s;
        // traverse()'s maxAt(top, 0) without water and with it (clipToHeights' zTop).
        const CascadeTextures& tex = (*ctx.tex)[k];
        const Heightfield& hf = tex.terrain;
        if (!hf.mip.empty()) {
            const size_t top = hf.mip.size() - 1;
            const float dry = hf.mip[top][0];
            float wet = dry;
            if (tex.hasWater && !tex.water.mip.empty())
                wet = tex.bothMip.size() == hf.mip.size() ? tex.bothMip[top][0]
                                                          : std::max(hf.mip[top][0], tex.water.mip[top][0]);
            sc.topDryNum = double(dry) - o.z, sc.topWetNum = double(wet) - o.z;
        }
        setUpSpans(n, dx, dy, dz, sc, r.t0.data(), r.t1.data(), r.du.data(), r.dv.data(), r.invDu.data(),
                   r.invDv.data(), r.tTopDry.data(), r.tTopWet.data());
    }
}

}  // namespace hc::render::detail
