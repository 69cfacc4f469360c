// heightcast/render/cascades.h: cascade fitting (docs/design.md section 5 step 1; report section 3).
//
// The view frustum is intersected with the scene's bounding box; the intersection's vertices,
// projected to the ground plane, give a convex hull: the potentially visible area. Along the
// camera's horizontal view direction d (its yaw) the hull spans offsets [n, f] from the camera;
// it is split logarithmically (Zhang et al.) at n (f/n)^(k/K), with n guarded away from zero.
// Each cascade's slab of the hull, its far side widened by an overlap for blending, is fitted into
// a square texture of N x N texels.
//
// Stable fitting: texel sizes come from a fixed ladder s = finest * 2^(q/8) (2^q with a surface pyramid, with
// up to 2N texels a side: ViewVolume::ladderStepsPerOctave) and the texture's
// corner texel sits on the global lattice of multiples of s (local frame). A camera that moves a
// little keeps s, and every texel centre stays on that lattice: sample positions never swim.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <vector>

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

namespace hc::render {

// Under an error budget, texels may be up to this many levels finer than the finest cell (2^-4 of it).
constexpr int kFinerTexelLevels = 4;
// The rendered error at texel level t (spacing finest * 2^t) from a pyramid's per-level errors e (Scene::levelErrorM):
// e[t], the top level's above it, and below level 0 the bilinear error shrinking with the spacing squared (texels
// summed from the kernels: exact at their centres).
inline double levelErrorM(const std::vector<double>& e, int t) {
    if (t >= 0) return e[size_t(std::min(t, int(e.size()) - 1))];
    return std::ldexp(e[0], 2 * t);
}

struct ViewVolume {
    glm::dvec3 eyeLocal;            // camera position relative to the grid origin [m]
    glm::dvec3 forward, right, up;  // camera basis (CameraBasis)
    double tanHalfX, tanHalfY;
    double nearM, farM;         // clip distances along forward
    double yawRad;              // d = (sin yaw, cos yaw)
    glm::dvec3 boxMin, boxMax;  // scene bounds, local [m]
    double finestCellM;
    // Texel sizes per octave of the ladder: 8 (s = finest * 2^(q/8), at most 9 % of a texture lost to the steps)
    // or 1 (s = finest * 2^t, the surface pyramid's spacings, so texel centres are its samples: the largest such
    // s not above the 8-step one, with more texels per side than asked, up to 2N, to cover the same extent).
    int ladderStepsPerOctave = 8;
    bool coarserTexels =
        false;  // with 1 step per octave: the smallest power of two not below the 8-step size, N texels
    // The error budget (RenderOptions::maxErrorM, maxErrorPx; 0: none), on either ladder, with levelErrorIn (the
    // rendered error at each pyramid level's spacing over the cascade's ground): each cascade takes the coarsest level
    // within its budget, the world one or the screen one at its nearest point (pixelRad: a pixel's angle [rad]), with
    // as many texels as its extent then needs, up to maxTexelsPerSide (coarser where those cannot cover it); off the
    // ladder (8 steps) never finer than N texels cover.
    double maxErrorM = 0, maxErrorPx = 0, pixelRad = 0;
    // The rendered error per level over a box [x0, x1] x [y0, y1] of local metres, asked for each cascade's polygon:
    // with a pyramid measured (Scene::levelErrorM); without one, under a budget, predicted (predictLevelErrorM);
    // else empty.
    std::function<std::vector<double>(double x0, double y0, double x1, double y1)> levelErrorIn;
    int maxTexelsPerSide = 8192;
};

// An inclusive span [first, last] of texel columns in a row; empty when last < first. The one span type of render/:
// a cascade's visible texels, and the texels a frame keeps, evaluates and copies (detail/frame.h).
struct TexelSpan {
    int first = 0, last = -1;
    bool empty() const { return last < first; }
    int count() const { return last < first ? 0 : last - first + 1; }
};

struct Cascade {
    double splitNear = 0, splitFar = 0;  // this cascade's share of [n, f] along d (offsets from the eye)
    double farWithOverlap = 0;           // splitFar widened into the next cascade (== splitFar for the last)
    double texelM = 0;                   // s
    double x0 = 0, y0 = 0;               // local position of texel (0, 0)'s centre (a multiple of s)
    int n = 0;                           // texels per side
    double nearestM = 0;                 // a lower bound of the distance from the eye to any point of it [m]
    double budgetM = 0;                  // the error budget at its nearest point (ViewVolume), 0: none
    int interpolateLevels = -1;          // under a budget: the most pyramid levels up a texel may come from, else -1
    std::vector<double> levelErrorM;     // the rendered error per level over the polygon's box (levelErrorIn)
    std::vector<glm::dvec2> polygon;     // the hull's slab [splitNear, farWithOverlap], local xy
    // The visible texels: inside the polygon dilated by 1.5 texels. The polygon is convex, so they are one
    // span of each row: row j's are i in [rows[j].first, rows[j].last] (none when last < first).
    using RowSpan = TexelSpan;
    std::vector<RowSpan> rows;  // n entries
    bool empty() const { return polygon.size() < 3; }
    bool visible(int i, int j) const { return i >= rows[size_t(j)].first && i <= rows[size_t(j)].last; }
    uint64_t visibleTexels() const {
        uint64_t count = 0;
        for (const RowSpan& r : rows) count += uint64_t(std::max(0, r.last - r.first + 1));
        return count;
    }
};

struct CascadeFit {
    glm::dvec2 dir{0, 1};                  // horizontal view direction
    std::vector<glm::dvec2> hull;          // potentially visible area (local xy), counter-clockwise
    double nearOffset = 0, farOffset = 0;  // [n, f] along dir, from the eye
    std::vector<Cascade> cascades;         // near to far
};

// count 1..4 cascades of texelsPerSide texels (more with ladderStepsPerOctave 1). An empty fit (no hull) means
// nothing is visible.
CascadeFit fitCascades(const ViewVolume& view, int count, int texelsPerSide);

// Exposed for tests: the ladder texel size for an extent, and the convex hull.
double ladderTexelSize(double extentM, int texelsPerSide, double finestCellM);
std::vector<glm::dvec2> convexHull(std::vector<glm::dvec2> points);

}  // namespace hc::render
