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
#include <cstdint>
#include <vector>

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

namespace hc::render {

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
