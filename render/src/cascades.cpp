// render/src/cascades.cpp: cascade fitting (cascades.h): the visible hull, its logarithmic split, and each
// cascade's stable texture placement and visible texels.
#include "heightcast/render/cascades.h"

#include <algorithm>
#include <cmath>

#include <glm/geometric.hpp>

namespace hc::render {
namespace {

struct Plane {
    glm::dvec3 n;
    double d;  // inside: dot(n, p) + d >= 0
    double eval(const glm::dvec3& p) const { return glm::dot(n, p) + d; }
};

Plane planeThrough(const glm::dvec3& normal, const glm::dvec3& point) { return {normal, -glm::dot(normal, point)}; }

// Vertices of the convex polyhedron given by half-spaces: every triple of planes meeting in a
// point inside all of them (220 triples for 12 planes: trivially cheap, and robust).
std::vector<glm::dvec3> polyhedronVertices(const std::vector<Plane>& planes, double scale) {
    std::vector<glm::dvec3> out;
    const size_t m = planes.size();
    const double eps = 1e-9 * scale;
    for (size_t a = 0; a < m; ++a)
        for (size_t b = a + 1; b < m; ++b)
            for (size_t c = b + 1; c < m; ++c) {
                const glm::dvec3 &na = planes[a].n, &nb = planes[b].n, &nc = planes[c].n;
                const glm::dvec3 bc = glm::cross(nb, nc);
                const double det = glm::dot(na, bc);
                if (std::abs(det) < 1e-12) continue;
                // p = (-da (nb x nc) - db (nc x na) - dc (na x nb)) / det
                const glm::dvec3 p =
                    (bc * -planes[a].d + glm::cross(nc, na) * -planes[b].d + glm::cross(na, nb) * -planes[c].d) / det;
                bool inside = true;
                for (const Plane& pl : planes) inside &= pl.eval(p) >= -eps;
                if (inside) out.push_back(p);
            }
    return out;
}

// Keeps the part of a convex polygon where dot(p, dir) lies in [lo, hi], in `out`; `half` holds the polygon clipped
// at lo. Both keep their storage from call to call (placeTexture clips a polygon for every texel row: allocating the
// vectors anew cost more than clipping).
void clipSlab(const std::vector<glm::dvec2>& poly, const glm::dvec2& dir, double lo, double hi,
              std::vector<glm::dvec2>& half, std::vector<glm::dvec2>& out) {
    auto clip = [&](const std::vector<glm::dvec2>& in, double sign, double bound, std::vector<glm::dvec2>& kept) {
        kept.clear();
        const size_t m = in.size();
        for (size_t i = 0; i < m; ++i) {
            const glm::dvec2& a = in[i];
            const glm::dvec2& b = in[(i + 1) % m];
            const double fa = sign * (glm::dot(a, dir) - bound), fb = sign * (glm::dot(b, dir) - bound);
            if (fa >= 0) kept.push_back(a);
            if ((fa >= 0) != (fb >= 0)) {
                const double t = fa / (fa - fb);
                kept.push_back(a + t * (b - a));
            }
        }
    };
    clip(poly, 1.0, lo, half);
    clip(half, -1.0, hi, out);
}

std::vector<glm::dvec2> clipSlab(const std::vector<glm::dvec2>& poly, const glm::dvec2& dir, double lo, double hi) {
    std::vector<glm::dvec2> half, out;
    clipSlab(poly, dir, lo, hi, half, out);
    return out;
}

// The potentially visible area: the view frustum intersected with the scene's box, projected to the ground
// (local xy), as a convex hull.
std::vector<glm::dvec2> visibleHull(const ViewVolume& v) {
    // The frustum's six planes (normals pointing inwards) and the box's six.
    const glm::dvec3& e = v.eyeLocal;
    std::vector<Plane> planes;
    planes.push_back(planeThrough(v.forward, e + v.forward * v.nearM));
    planes.push_back(planeThrough(-v.forward, e + v.forward * v.farM));
    // Side planes through the eye: left/right contain up, bottom/top contain right. Each normal is
    // turned to face a point surely inside (on the axis, between near and far).
    const glm::dvec3 inside = e + v.forward * (0.5 * (v.nearM + v.farM));
    auto inward = [&](const glm::dvec3& n) {
        Plane pl = planeThrough(n, e);
        if (pl.eval(inside) < 0) pl = planeThrough(-n, e);
        return pl;
    };
    for (double sx : {-1.0, 1.0}) planes.push_back(inward(glm::cross(v.up, v.forward + v.right * (sx * v.tanHalfX))));
    for (double sy : {-1.0, 1.0}) planes.push_back(inward(glm::cross(v.forward + v.up * (sy * v.tanHalfY), v.right)));
    for (int axis = 0; axis < 3; ++axis) {
        glm::dvec3 n{0, 0, 0};
        n[axis] = 1;
        planes.push_back(planeThrough(n, v.boxMin));
        n[axis] = -1;
        planes.push_back(planeThrough(n, v.boxMax));
    }
    const double scale = std::max({v.farM, std::abs(v.boxMax.x - v.boxMin.x), std::abs(v.boxMax.y - v.boxMin.y), 1.0});
    std::vector<glm::dvec2> ground;
    for (const glm::dvec3& p : polyhedronVertices(planes, scale)) ground.push_back({p.x, p.y});
    return convexHull(ground);
}

// The split offsets along the view direction: n, the logarithmic splits, f (count + 1 values).
std::vector<double> splitOffsets(double n, double f, int count, double finestCellM) {
    // Guard n -> 0 (and n < 0: the camera stands over the visible area): the logarithmic split needs
    // a positive near offset. Below about one finest cell (or 1/1000 of the range) more cascades
    // would only split sub-texel distances.
    const double nGuard = std::max({n, finestCellM, (f - std::min(n, 0.0)) * 1e-3});
    const double fGuard = std::max(f, nGuard * 1.0001);
    std::vector<double> bounds{n};
    for (int k = 1; k < count; ++k) bounds.push_back(nGuard * std::pow(fGuard / nGuard, double(k) / count));
    bounds.push_back(f);
    return bounds;
}

// Under an error budget (ViewVolume): the coarsest pyramid level whose error is within it, then (`capped`) coarser
// while the extent needs more texels than allowed; how many levels above it texels may be interpolated from. Returns
// the level.
int budgetLevel(Cascade& c, const ViewVolume& v, double extent, bool capped) {
    const std::vector<double>& e = c.levelErrorM;
    const int top = int(e.size()) - 1;
    int t = -kFinerTexelLevels;
    while (t < top && levelErrorM(e, t + 1) <= c.budgetM) ++t;
    while (capped && t < top && std::ceil(extent / (v.finestCellM * std::exp2(t))) + 3 > v.maxTexelsPerSide) ++t;
    int up = 0;  // levels up a texel may be interpolated from: their error within the budget too
    while (t + up < top && levelErrorM(e, t) + levelErrorM(e, t + up + 1) <= c.budgetM) ++up;
    c.interpolateLevels = up;
    return t;
}

// The texture's side for an extent at a spacing: three texels beyond it, rounded up to a multiple of 64 (see below).
int sideFor(double extent, double texelM) { return (int(std::ceil(extent / texelM)) + 3 + 63) / 64 * 64; }

// Places cascade c's texture over its polygon (texel size from the ladder, or the error budget's level; corner on the
// lattice) and finds its visible texels. `measure`: ask levelErrorIn for the error under the polygon's box (else
// c.levelErrorM is already set).
void placeTexture(Cascade& c, const ViewVolume& v, int texelsPerSide, bool measure = true) {
    const double finestCellM = v.finestCellM;
    const int stepsPerOctave = v.ladderStepsPerOctave;
    const bool coarser = v.coarserTexels;
    double bx0 = HUGE_VAL, by0 = HUGE_VAL, bx1 = -HUGE_VAL, by1 = -HUGE_VAL;
    for (const glm::dvec2& p : c.polygon) {
        bx0 = std::min(bx0, p.x);
        by0 = std::min(by0, p.y);
        bx1 = std::max(bx1, p.x);
        by1 = std::max(by1, p.y);
    }
    const double extent = std::max(bx1 - bx0, by1 - by0);
    if (v.levelErrorIn && measure) c.levelErrorM = v.levelErrorIn(bx0, by0, bx1, by1);  // the ground under it
    c.n = texelsPerSide;
    c.texelM = ladderTexelSize(extent, texelsPerSide, finestCellM);
    if (stepsPerOctave == 1) {
        // The pyramid's spacings: the largest power of two of the finest cell not above the 8-step size (never
        // coarser texels than without a pyramid), with as many texels as the extent then needs (up to about 2N); or
        // the smallest not below it, which N texels cover.
        const double t = std::log2(c.texelM / finestCellM);
        c.texelM = finestCellM * std::exp2(coarser ? std::ceil(t - 1e-9) : std::floor(t + 1e-9));
        // The side is rounded up to a multiple of 64 texels: as the camera moves the extent changes a little every
        // frame. Exact sides changed every 4-6 frames of a 20 m-a-frame flight at 105 M cells, and a cascade whose side
        // changed then kept none of its texels (a far cascade's millions of texels evaluated afresh). It keeps them now
        // (CascadeCache), but into new storage, where the same side moves them in place.
        if (!coarser) c.n = sideFor(extent, c.texelM);
    }
    // Under an error budget the spacing is the budget's level. Off the pyramid's ladder (the GL backend in memory sums
    // every texel from the kernels, at any spacing) never finer than N texels cover: where they cannot meet the budget
    // that is as near as they come.
    if (c.budgetM > 0 && !c.levelErrorM.empty()) {
        if (stepsPerOctave == 1) {
            c.texelM = finestCellM * std::exp2(budgetLevel(c, v, extent, true));
            c.n = sideFor(extent, c.texelM);
        } else if (const double s = finestCellM * std::exp2(budgetLevel(c, v, extent, false)); s > c.texelM) {
            c.texelM = s;
            c.n = std::min(c.n, sideFor(extent, c.texelM));
        }
    }
    // Corner on the lattice, one texel outside the box so every patch of the box is whole.
    c.x0 = (std::floor(bx0 / c.texelM) - 1) * c.texelM;
    c.y0 = (std::floor(by0 / c.texelM) - 1) * c.texelM;
    c.rows.assign(size_t(c.n), Cascade::RowSpan{});
    // Visible texels: the polygon dilated by 1.5 texels (so every patch a ray can reach inside
    // the polygon has four known corners). Row by row, the dilation's x-range is the polygon
    // clipped to the band [y - m, y + m], widened by m.
    const double m = 1.5 * c.texelM;
    const glm::dvec2 yAxis{0, 1};
    std::vector<glm::dvec2> half, band;
    for (int j = 0; j < c.n; ++j) {
        const double y = c.y0 + j * c.texelM;
        clipSlab(c.polygon, yAxis, y - m, y + m, half, band);
        if (band.empty()) continue;
        double xl = HUGE_VAL, xr = -HUGE_VAL;
        for (const glm::dvec2& p : band) xl = std::min(xl, p.x), xr = std::max(xr, p.x);
        const int i0 = std::max(0, int(std::floor((xl - m - c.x0) / c.texelM)));
        const int i1 = std::min(c.n - 1, int(std::ceil((xr + m - c.x0) / c.texelM)));
        c.rows[size_t(j)] = {i0, i1};
    }
}

// Cascade c's polygon: the hull's slab [splitNear, farWithOverlap] along the view, the first (k = 0) reaching back to
// the eye and past it. `eyeOffset`: the eye's offset along the view direction (the slab's are relative to it).
std::vector<glm::dvec2> slabPolygon(const CascadeFit& fit, size_t k, const Cascade& c, double eyeOffset) {
    const double lo = k == 0 ? -HUGE_VAL : c.splitNear;
    return clipSlab(fit.hull, fit.dir, eyeOffset + lo, eyeOffset + c.farWithOverlap);
}

// Under an error budget neighbouring cascades often come out at the same spacing, or nearly (a loose budget: all of
// them). One cascade over both then holds about the same texels, and a ray walks one texture instead of crossing from
// one into the next (its set-up, clip and walk again; commit d250930 measured the gain). The merged cascade takes the
// spacing the budget allows over both: its error per level is the larger of the two (each was measured over its part's
// box, and the merged visible texels lie in those parts), its budget the tighter. It replaces the two
// - at their common spacing: its texels are theirs (the same lattice, the same samples), so no texel is worse; or
// - at a spacing that meets the budget (not coarsened by the cap on texels a side) and is no finer than the finer of
//   theirs, with no more than kMergeTexels times their visible texels together (a small near cascade at the far
//   one's spacing, say).
// `eyeOffset`: as in slabPolygon.
constexpr double kMergeTexels = 1.1;

void mergeCascades(CascadeFit& fit, const ViewVolume& v, int texelsPerSide, double eyeOffset) {
    std::vector<Cascade>& cs = fit.cascades;
    for (size_t k = 0; k + 1 < cs.size();) {
        const Cascade &a = cs[k], &b = cs[k + 1];
        Cascade m;
        if (!a.empty() && !b.empty() && a.levelErrorM.size() == b.levelErrorM.size()) {
            m.splitNear = a.splitNear, m.splitFar = b.splitFar, m.farWithOverlap = b.farWithOverlap;
            m.polygon = slabPolygon(fit, k, m, eyeOffset);
            m.nearestM = std::min(a.nearestM, b.nearestM);
            m.budgetM = std::min(a.budgetM, b.budgetM);
            m.levelErrorM.resize(a.levelErrorM.size());
            for (size_t l = 0; l < m.levelErrorM.size(); ++l)
                m.levelErrorM[l] = std::max(a.levelErrorM[l], b.levelErrorM[l]);
        }
        if (m.polygon.size() >= 3) placeTexture(m, v, texelsPerSide, false);
        bool merge = false;
        if (!m.empty() && m.texelM == a.texelM && m.texelM == b.texelM) {
            merge = true;
        } else if (!m.empty() && m.texelM >= std::min(a.texelM, b.texelM)) {
            // The level at or above the spacing (the 8-step ladder's lie between two).
            const int t = int(std::ceil(std::log2(m.texelM / v.finestCellM) - 1e-9));
            merge = levelErrorM(m.levelErrorM, t) <= m.budgetM &&
                    double(m.visibleTexels()) <= kMergeTexels * double(a.visibleTexels() + b.visibleTexels());
        }
        if (!merge) {
            ++k;
            continue;
        }
        cs[k] = std::move(m);
        cs.erase(cs.begin() + std::ptrdiff_t(k) + 1);
    }
}

}  // namespace

std::vector<glm::dvec2> convexHull(std::vector<glm::dvec2> p) {
    // Sorted by x, then y (as std::array's lexicographic order was).
    std::sort(p.begin(), p.end(),
              [](const glm::dvec2& a, const glm::dvec2& b) { return a.x < b.x || (a.x == b.x && a.y < b.y); });
    p.erase(std::unique(p.begin(), p.end()), p.end());
    if (p.size() < 3) return p;
    auto turn = [](const glm::dvec2& o, const glm::dvec2& a, const glm::dvec2& b) {
        return (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x);
    };
    std::vector<glm::dvec2> h(2 * p.size());
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
    fit.hull = visibleHull(v);
    if (fit.hull.size() < 3) return fit;  // nothing of the scene is in view

    const glm::dvec2 eye{v.eyeLocal};
    double n = HUGE_VAL, f = -HUGE_VAL;
    for (const glm::dvec2& p : fit.hull) {
        const double o = glm::dot(p - eye, fit.dir);
        n = std::min(n, o);
        f = std::max(f, o);
    }
    fit.nearOffset = n;
    fit.farOffset = f;
    const std::vector<double> bounds = splitOffsets(n, f, count, v.finestCellM);
    // Offsets relative to the eye; clip the hull (absolute) with the slab shifted by dot(eye, dir).
    const double eyeOffset = glm::dot(eye, fit.dir);
    for (int k = 0; k < count; ++k) {
        Cascade c;
        c.splitNear = bounds[size_t(k)];
        c.splitFar = bounds[size_t(k) + 1];
        const double width = c.splitFar - std::max(c.splitNear, 0.0);
        c.farWithOverlap = k + 1 < count ? c.splitFar + std::max(0.1 * width, 4 * v.finestCellM) : c.splitFar;
        c.polygon = slabPolygon(fit, size_t(k), c, eyeOffset);
        // The nearest point: the camera's height over the highest terrain, or the slab's near offset.
        c.nearestM = std::max({k == 0 ? 0.0 : c.splitNear, v.eyeLocal.z - v.boxMax.z, v.nearM, 1e-3});
        const double screenBudget = v.maxErrorPx * v.pixelRad * c.nearestM;
        c.budgetM = v.maxErrorM > 0 && v.maxErrorPx > 0 ? std::min(v.maxErrorM, screenBudget)
                                                        : std::max(v.maxErrorM, screenBudget);
        if (c.polygon.size() >= 3) placeTexture(c, v, texelsPerSide);
        fit.cascades.push_back(std::move(c));
    }
    if (v.maxErrorM > 0 || v.maxErrorPx > 0) mergeCascades(fit, v, texelsPerSide, eyeOffset);
    return fit;
}

}  // namespace hc::render
