// tests/surface_bound.h: how far a bilinear patch over texels of the exact surface may stray from that surface, the
// bound the renderers' hits are checked against (render_hits_test, render_gl_test and the rest of the render tests).
#pragma once

#include <algorithm>
#include <cmath>
#include <optional>
#include <utility>

#include "heightcast/influence/surface.h"

namespace hc::test {

// The discretisation bound at a hit. The bilinear interpolant of a C^2 function sampled every s
// metres errs by at most s^2 / 8 (max|v_xx| + max|v_yy|) over the patch (the ray meets that
// interpolant exactly). The maxima are estimated by central differences of the exact surface over
// one texel at the hit and half a texel around it, doubled for safety; plus 5 mm for float32
// storage of texels and positions. Next to a hole or the domain's edge the differences do not exist: nullopt, no
// claim (a caller counts such a pixel as unchecked, never as checked).
inline std::optional<double> bilinearBound(const influence::SurfaceEvaluator& eval, const influence::Layer& layer,
                                           double x, double y, double s) {
    double vxxMax = 0, vyyMax = 0;
    for (const auto& offset : {std::pair{0.0, 0.0}, {0.5, 0.0}, {-0.5, 0.0}, {0.0, 0.5}, {0.0, -0.5}}) {
        const double px = x + offset.first * s, py = y + offset.second * s;
        auto v = [&](double dx, double dy) { return eval.value(px + dx, py + dy, layer); };
        auto c = v(0, 0), xp = v(s, 0), xm = v(-s, 0), yp = v(0, s), ym = v(0, -s);
        if (!c || !xp || !xm || !yp || !ym) return std::nullopt;
        vxxMax = std::max(vxxMax, std::abs(*xp - 2 * *c + *xm) / (s * s));
        vyyMax = std::max(vyyMax, std::abs(*yp - 2 * *c + *ym) / (s * s));
    }
    return 2.0 * s * s / 8.0 * (vxxMax + vyyMax) + 5e-3;
}

}  // namespace hc::test
