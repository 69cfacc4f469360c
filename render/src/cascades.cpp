#include "heightcast/render/cascades.h"

#include <algorithm>
#include <cmath>

namespace hc::render {
namespace {

struct Plane {
    Vec3 n;
    double d;  // inside: dot(n, p) + d >= 0
    double eval(const Vec3& p) const { return n[0] * p[0] + n[1] * p[1] + n[2] * p[2] + d; }
};

Vec3 add(const Vec3& a, const Vec3& b, double s = 1) { return {a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]}; }
Vec3 cross(const Vec3& a, const Vec3& b) {
    return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

Plane planeThrough(const Vec3& normal, const Vec3& point) { return {normal, -dot(normal, point)}; }

// Vertices of the convex polyhedron given by half-spaces: every triple of planes meeting in a
// point inside all of them (220 triples for 12 planes: trivially cheap, and robust).
std::vector<Vec3> polyhedronVertices(const std::vector<Plane>& planes, double scale) {
    std::vector<Vec3> out;
    const size_t m = planes.size();
    const double eps = 1e-9 * scale;
    for (size_t a = 0; a < m; ++a)
        for (size_t b = a + 1; b < m; ++b)
            for (size_t c = b + 1; c < m; ++c) {
                const Vec3 &na = planes[a].n, &nb = planes[b].n, &nc = planes[c].n;
                const Vec3 bc = cross(nb, nc);
                const double det = dot(na, bc);
                if (std::abs(det) < 1e-12) continue;
                // p = (-da (nb x nc) - db (nc x na) - dc (na x nb)) / det
                Vec3 p = add(add(Vec3{bc[0] * -planes[a].d, bc[1] * -planes[a].d, bc[2] * -planes[a].d}, cross(nc, na), -planes[b].d),
                             cross(na, nb), -planes[c].d);
                p = {p[0] / det, p[1] / det, p[2] / det};
                bool inside = true;
                for (const Plane& pl : planes) inside &= pl.eval(p) >= -eps;
                if (inside) out.push_back(p);
            }
    return out;
}

// Keeps the part of a convex polygon where dot(p, dir) lies in [lo, hi].
std::vector<Vec2> clipSlab(const std::vector<Vec2>& poly, const Vec2& dir, double lo, double hi) {
    auto clip = [&](const std::vector<Vec2>& in, double sign, double bound) {
        std::vector<Vec2> out;
        const size_t m = in.size();
        for (size_t i = 0; i < m; ++i) {
            const Vec2& a = in[i];
            const Vec2& b = in[(i + 1) % m];
            const double fa = sign * (a[0] * dir[0] + a[1] * dir[1] - bound), fb = sign * (b[0] * dir[0] + b[1] * dir[1] - bound);
            if (fa >= 0) out.push_back(a);
            if ((fa >= 0) != (fb >= 0)) {
                const double t = fa / (fa - fb);
                out.push_back({a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])});
            }
        }
        return out;
    };
    return clip(clip(poly, 1.0, lo), -1.0, hi);
}

}  // namespace

std::vector<Vec2> convexHull(std::vector<Vec2> p) {
    std::sort(p.begin(), p.end());
    p.erase(std::unique(p.begin(), p.end()), p.end());
    if (p.size() < 3) return p;
    auto turn = [](const Vec2& o, const Vec2& a, const Vec2& b) {
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]);
    };
    std::vector<Vec2> h(2 * p.size());
    size_t k = 0;
    for (size_t i = 0; i < p.size(); ++i) {
        while (k >= 2 && turn(h[k - 2], h[k - 1], p[i]) <= 0) --k;
        h[k++] = p[i];
    }
    for (size_t i = p.size() - 1, t = k + 1; i > 0; --i) {
        while (k >= t && turn(h[k - 2], h[k - 1], p[i - 1]) <= 0) --k;
        h[k++] = p[i - 1];
    }
    h.resize(k - 1);
    return h;
}

double ladderTexelSize(double extentM, int texelsPerSide, double finestCellM) {
    // Smallest s = finest * 2^(q/8) with (N - 1) s >= extent + 2 s (room to snap the corner to the
    // lattice): at most 9 % of the texture is lost to the ladder's steps.
    const double need = extentM / (texelsPerSide - 3);
    double q = std::ceil(8.0 * std::log2(need / finestCellM) - 1e-9);
    double s = finestCellM * std::exp2(q / 8.0);
    while ((texelsPerSide - 3) * s < extentM) s = finestCellM * std::exp2(++q / 8.0);  // rounding guard
    return s;
}

CascadeFit fitCascades(const ViewVolume& v, int count, int texelsPerSide) {
    CascadeFit fit;
    fit.dir = {std::sin(v.yawRad), std::cos(v.yawRad)};
    // The frustum's six planes (normals pointing inwards) and the box's six.
    const Vec3& e = v.eyeLocal;
    std::vector<Plane> planes;
    planes.push_back(planeThrough(v.forward, add(e, v.forward, v.nearM)));
    planes.push_back(planeThrough({-v.forward[0], -v.forward[1], -v.forward[2]}, add(e, v.forward, v.farM)));
    // Side planes through the eye: left/right contain up, bottom/top contain right. Each normal is
    // turned to face a point surely inside (on the axis, between near and far).
    const Vec3 inside = add(e, v.forward, 0.5 * (v.nearM + v.farM));
    auto inward = [&](Vec3 n) {
        Plane pl = planeThrough(n, e);
        if (pl.eval(inside) < 0) pl = planeThrough({-n[0], -n[1], -n[2]}, e);
        return pl;
    };
    for (double sx : {-1.0, 1.0}) planes.push_back(inward(cross(v.up, add(v.forward, v.right, sx * v.tanHalfX))));
    for (double sy : {-1.0, 1.0}) planes.push_back(inward(cross(add(v.forward, v.up, sy * v.tanHalfY), v.right)));
    for (int axis = 0; axis < 3; ++axis) {
        Vec3 n{0, 0, 0};
        n[axis] = 1;
        planes.push_back(planeThrough(n, v.boxMin));
        n[axis] = -1;
        planes.push_back(planeThrough(n, v.boxMax));
    }
    const double scale = std::max({v.farM, std::abs(v.boxMax[0] - v.boxMin[0]), std::abs(v.boxMax[1] - v.boxMin[1]), 1.0});
    std::vector<Vec2> ground;
    for (const Vec3& p : polyhedronVertices(planes, scale)) ground.push_back({p[0], p[1]});
    fit.hull = convexHull(ground);
    if (fit.hull.size() < 3) return fit;  // nothing of the scene is in view

    double n = HUGE_VAL, f = -HUGE_VAL;
    for (const Vec2& p : fit.hull) {
        const double o = (p[0] - e[0]) * fit.dir[0] + (p[1] - e[1]) * fit.dir[1];
        n = std::min(n, o);
        f = std::max(f, o);
    }
    fit.nearOffset = n;
    fit.farOffset = f;
    // Guard n -> 0 (and n < 0: the camera stands over the visible area): the logarithmic split needs
    // a positive near offset. Below about one finest cell (or 1/1000 of the range) more cascades
    // would only split sub-texel distances.
    const double nGuard = std::max({n, v.finestCellM, (f - std::min(n, 0.0)) * 1e-3});
    const double fGuard = std::max(f, nGuard * 1.0001);
    std::vector<double> bounds{n};
    for (int k = 1; k < count; ++k) bounds.push_back(nGuard * std::pow(fGuard / nGuard, double(k) / count));
    bounds.push_back(f);
    // Offsets relative to the eye; clip the hull (absolute) with the slab shifted by dot(eye, dir).
    const double eyeOffset = e[0] * fit.dir[0] + e[1] * fit.dir[1];
    for (int k = 0; k < count; ++k) {
        Cascade c;
        c.splitNear = bounds[k];
        c.splitFar = bounds[k + 1];
        const double width = c.splitFar - std::max(c.splitNear, 0.0);
        c.farWithOverlap = k + 1 < count ? c.splitFar + std::max(0.1 * width, 4 * v.finestCellM) : c.splitFar;
        const double lo = k == 0 ? -HUGE_VAL : c.splitNear;  // the first cascade takes everything nearer
        c.polygon = clipSlab(fit.hull, fit.dir, eyeOffset + lo, eyeOffset + c.farWithOverlap);
        if (c.polygon.size() >= 3) {
            double bx0 = HUGE_VAL, by0 = HUGE_VAL, bx1 = -HUGE_VAL, by1 = -HUGE_VAL;
            for (const Vec2& p : c.polygon) {
                bx0 = std::min(bx0, p[0]);
                by0 = std::min(by0, p[1]);
                bx1 = std::max(bx1, p[0]);
                by1 = std::max(by1, p[1]);
            }
            c.n = texelsPerSide;
            c.texelM = ladderTexelSize(std::max(bx1 - bx0, by1 - by0), texelsPerSide, v.finestCellM);
            // Corner on the lattice, one texel outside the box so every patch of the box is whole.
            c.x0 = (std::floor(bx0 / c.texelM) - 1) * c.texelM;
            c.y0 = (std::floor(by0 / c.texelM) - 1) * c.texelM;
            c.rows.assign(size_t(c.n), Cascade::RowSpan{});
            // Visible texels: the polygon dilated by 1.5 texels (so every patch a ray can reach inside
            // the polygon has four known corners). Row by row, the dilation's x-range is the polygon
            // clipped to the band [y - m, y + m], widened by m.
            const double m = 1.5 * c.texelM;
            const Vec2 yAxis{0, 1};
            for (int j = 0; j < c.n; ++j) {
                const double y = c.y0 + j * c.texelM;
                const std::vector<Vec2> band = clipSlab(c.polygon, yAxis, y - m, y + m);
                if (band.empty()) continue;
                double xl = HUGE_VAL, xr = -HUGE_VAL;
                for (const Vec2& p : band) xl = std::min(xl, p[0]), xr = std::max(xr, p[0]);
                const int i0 = std::max(0, int(std::floor((xl - m - c.x0) / c.texelM)));
                const int i1 = std::min(c.n - 1, int(std::ceil((xr + m - c.x0) / c.texelM)));
                c.rows[size_t(j)] = {i0, i1};
            }
        }
        fit.cascades.push_back(std::move(c));
    }
    return fit;
}

}  // namespace hc::render
