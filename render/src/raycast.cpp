// Ray casting through the cascades: hierarchical max-mipmap traversal (Tevs et al. 2008) and exact
// ray/bilinear-patch intersection, cascades near to far, blended in their overlaps. Terrain and water
// share one walk per cascade (nodes skipped above the larger maximum), which on the flood scenes is
// faster than walking each heightfield on its own.
//
// The terrain is a solid block (a block diagram): the smooth surface on top, over the patches whose four
// corner texels are defined; vertical walls where the defined patches end (hole and domain edges), from the
// surface down to the grid's lowest elevation; a flat bottom there. One rule for every ray: it hits the
// first face of the block it meets, whichever face that is; a ray that starts inside the block sees nothing.
#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>

#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <glm/vec2.hpp>

#include "heightcast/render/detail/frame.h"
#include "heightcast/render/water_rule.h"

namespace hc::render::detail {
namespace {

struct PatchHit {
    bool hit = false;
    bool water = false;  // the hit is on the water surface
    bool wall = false;   // the hit is on a cut face of the terrain block: normal in nx, ny, nz
    double nx = 0, ny = 0, nz = 0;
    bool terrainUnderground = false;  // the ray met the terrain first from below: it starts inside it
    bool waterUnderground = false;    // the same for the water surface: the camera is under water
    double t = 0;
    double gx = 0, gy = 0;  // surface rise at the hit per texel along x and y [m] (the slope times the texel size)
};

// What a ray has met so far, over its cascades: each surface's first contact decides whether the ray
// started above it. Under the water surface (a camera in a lake) the water is not drawn at all.
struct RayState {
    bool touchedTerrain = false, touchedWater = false, underWater = false;
};

// A ray in one cascade's texture coordinates u = (x - x0) / s, v = (y - y0) / s: at parameter t [m along the
// ray] it is at (u0 + du t, v0 + dv t), height z0 + dz t [m, local].
struct TexelRay {
    double u0, v0, du, dv;
    double z0, dz;
    double texelM;  // s
    double zAt(double t) const { return z0 + dz * t; }
};

// Ray `i` of `setups` in cascade c (setUpRays: u0 = (o.x - x0) / s, du = d.x / s, and likewise in v).
TexelRay texelRay(const Cascade& c, const RaySetups::Cascade& setup, size_t i, const glm::dvec3& o,
                  const glm::dvec3& d) {
    return {setup.u0, setup.v0, setup.du[i], setup.dv[i], o.z, d.z, c.texelM};
}

// The part of a ray over one patch: parameters [t, t + len].
struct RaySpan {
    double t, len;
};

// Patch (iu, iv) of a heightfield, spanning texels iu..iu+1 by iv..iv+1, with its corner heights [m].
struct PatchCorners {
    int iu, iv;
    double h00, h10, h01, h11;  // h10 at texel (iu + 1, iv), h01 at (iu, iv + 1)
};

// The corners of patch (iu, iv) of `hf` if it has a surface (four defined corners); outside the texture it has none.
[[gnu::always_inline]] inline std::optional<PatchCorners> cornersOf(const Heightfield& hf, int iu, int iv) {
    if (iu < 0 || iv < 0 || iu >= hf.n - 1 || iv >= hf.n - 1) return std::nullopt;
    const size_t n = size_t(hf.n);
    const float* r0 = &hf.h[size_t(iv) * n + size_t(iu)];
    const PatchCorners p{iu, iv, r0[0], r0[1], r0[n], r0[n + 1]};
    if (!(std::isfinite(p.h00) && std::isfinite(p.h10) && std::isfinite(p.h01) && std::isfinite(p.h11)))
        return std::nullopt;
    return p;
}
bool patchDefined(const Heightfield& hf, int iu, int iv) { return cornersOf(hf, iu, iv).has_value(); }

// Whether patch (iu, iv), inside the texture, may have a surface: false where its max-mipmap node (the largest of its
// four corners) is -inf, which no finite corner gives (std::max never prefers -inf to a number): all four undefined,
// so cornersOf() has none. One load where cornersOf() makes four and tests them: on a flood scene most patches a walk
// reaches are dry, and the water's test of each was a twentieth of ray casting's instructions.
bool mayHaveSurface(const Heightfield& hf, int iu, int iv) {
    return hf.mip[0][size_t(iv) * size_t(hf.n - 1) + size_t(iu)] != -std::numeric_limits<float>::infinity();
}

// Whether the water at the corners `w` stands above the terrain at each (water::standsAbove).
bool standsAbove(const PatchCorners& w, const Heightfield& terrain) {
    const size_t n = size_t(terrain.n);
    const float* t0 = &terrain.h[size_t(w.iv) * n + size_t(w.iu)];
    return water::standsAbove(float(w.h00), t0[0]) && water::standsAbove(float(w.h10), t0[1]) &&
           water::standsAbove(float(w.h01), t0[n]) && water::standsAbove(float(w.h11), t0[n + 1]);
}

// Where a ray first meets a bilinear patch within its span. Below: the ray enters the patch at or under the
// surface (tau = 0).
enum class Contact { None, Below, Hit };
struct PatchContact {
    Contact kind = Contact::None;
    double tau = -1;            // from span.t (Hit, Below)
    double gx = 0, gy = 0;      // surface rise there per texel along x and y [m] (normalOfSlope divides)
    bool enteredAbove = false;  // the ray entered the patch above its surface (RayState's `touched`)
};

[[gnu::always_inline]] inline PatchContact patchContact(const PatchCorners& p, const TexelRay& ray,
                                                        const RaySpan& span) {
    PatchContact out;
    const double h00 = p.h00, h10 = p.h10, h01 = p.h01, h11 = p.h11;
    const double du = ray.du, dv = ray.dv;
    const double a0 = ray.u0 + du * span.t - p.iu, b0 = ray.v0 + dv * span.t - p.iv, z0 = ray.zAt(span.t);
    const double e = h00 - h10 - h01 + h11;
    // f(tau) = z(tau) - bilinear(tau), tau from t: C + B tau + A tau^2.
    const double C = z0 - (h00 + (h10 - h00) * a0 + (h01 - h00) * b0 + e * a0 * b0);
    const double B = ray.dz - (h10 - h00) * du - (h01 - h00) * dv - e * (a0 * dv + b0 * du);
    const double A = -e * du * dv;
    auto slope = [&](double at) {
        const double a = std::clamp(a0 + du * at, 0.0, 1.0), b = std::clamp(b0 + dv * at, 0.0, 1.0);
        out.gx = (h10 - h00) + e * b;
        out.gy = (h01 - h00) + e * a;
    };
    if (C <= 0) {  // at or under the surface where the ray enters the patch: the caller's rules decide
        out.kind = Contact::Below;
        out.tau = 0;
        slope(0);
        return out;
    }
    double tau = -1;
    if (std::abs(A) < 1e-12 * (std::abs(B) + 1e-300)) {
        if (B < 0) tau = -C / B;
    } else {
        const double disc = B * B - 4 * A * C;
        if (disc >= 0) {
            const double q = -0.5 * (B + std::copysign(std::sqrt(disc), B));
            double r1 = q / A, r2 = q != 0 ? C / q : r1;
            if (r1 > r2) std::swap(r1, r2);
            tau = r1 >= 0 ? r1 : r2;  // C > 0: the first root is where the ray goes under
        }
    }
    out.enteredAbove = true;
    out.tau = tau;
    if (!(tau >= 0 && tau <= span.len)) return out;
    out.kind = Contact::Hit;
    slope(tau);
    return out;
}

// patchContact with patch (iu, iv) of `hf`: none where the patch has no surface.
[[gnu::always_inline]] inline PatchContact patchContact(const Heightfield& hf, int iu, int iv, const TexelRay& ray,
                                                        const RaySpan& span) {
    const std::optional<PatchCorners> p = cornersOf(hf, iu, iv);
    return p ? patchContact(*p, ray, span) : PatchContact{};
}

// Narrows [tIn, tOut] to where the ray can meet the block of a cascade whose highest point is zTop; false when
// nothing is left. A ray above the whole cascade never hits it; nor does the part of a ray above the cascade's
// highest point, where the walk would only skip nodes: start where a falling ray comes down to that height,
// stop where a rising one climbs above it (a hair early and late, for rounding). tTop and tFloor: where the ray is at
// heights zTop and zFloor, (z - z0) / dz (setUpRays), when dz != 0.
bool clipToHeights(const TexelRay& ray, double zTop, double zFloor, double tTop, double tFloor, double& tIn,
                   double& tOut) {
    if (std::min(ray.zAt(tIn), ray.zAt(tOut)) > zTop) return false;
    if (ray.dz != 0) {
        const double margin = 1e-9 * (1.0 + std::abs(tTop));
        if (ray.dz < 0)
            tIn = std::max(tIn, tTop - margin);
        else
            tOut = std::min(tOut, tTop + margin);
        if (!(tIn < tOut)) return false;
    }
    // Likewise under the block's bottom there is nothing to hit but the bottom, where a rising ray comes up
    // through it: start there; a falling ray ends there. (Without this a ray under the block walked every
    // patch at the finest level: 6.3 s for a 480 x 300 frame from a camera under a domain edge.)
    if (ray.dz != 0) {
        const double margin = 1e-9 * (1.0 + std::abs(tFloor));
        if (ray.dz > 0)
            tIn = std::max(tIn, tFloor - margin);
        else
            tOut = std::min(tOut, tFloor + margin);
        return tIn < tOut;
    }
    return !(ray.z0 < zFloor);
}

// The patch a ray came from into patch (iu, iv): across the edge it crossed last.
struct From {
    bool acrossU;
    int u, v;
};
From cameFrom(const TexelRay& ray, int iu, int iv) {
    const double u0 = ray.u0, v0 = ray.v0, du = ray.du, dv = ray.dv;
    const double invDu = du != 0 ? 1.0 / du : 0.0, invDv = dv != 0 ? 1.0 / dv : 0.0;
    const double enterU = du > 0 ? (iu - u0) * invDu : du < 0 ? (iu + 1 - u0) * invDu : -HUGE_VAL;
    const double enterV = dv > 0 ? (iv - v0) * invDv : dv < 0 ? (iv + 1 - v0) * invDv : -HUGE_VAL;
    const bool acrossU = enterU >= enterV;
    return From{acrossU, acrossU ? iu - (du > 0 ? 1 : -1) : iu, acrossU ? iv : iv - (dv > 0 ? 1 : -1)};
}

// One ray's walk through one cascade (traverse()): what every patch it reaches needs.
struct PatchWalk {
    const CascadeTextures& tex;
    const TexelRay& ray;
    double tStart;  // where the walk began: a contact from below there is the ray's first in this cascade
    double zFloor;  // the terrain block's bottom
    bool water;     // the water surface is drawn for this ray (until it is found under it)
    RayState& st;
    PatchHit& res;  // traverse()'s result, written in place (a copy of it out cost a store-forwarding stall)

    // Patch (iu, iv) over `segment`, intersected with both surfaces under the block's rules (traverse()): true
    // when that ends the walk, the result in res; false when the ray goes on past the patch.
    bool endsAt(int iu, int iv, const RaySpan& segment) {
        // Where the water of all four texels stands above their terrain (water_rule.h: not at a shore, where the
        // terrain may rise through the water), the water's bilinear surface is above the terrain's everywhere in the
        // patch. A ray that enters the patch above the water then enters above the terrain too, and meets the water
        // first (the water wins a tie below), or neither: the terrain's intersection can be skipped: a share of the
        // patch tests on every flood scene, the frames byte-identical. The GL walk (raycast.comp) intersects both.
        if (water) {
            if (const std::optional<PatchCorners> wc =
                    mayHaveSurface(tex.water, iu, iv) ? cornersOf(tex.water, iu, iv) : std::nullopt;
                wc && standsAbove(*wc, tex.terrain)) {
                const PatchContact cw = patchContact(*wc, ray, segment);
                if (cw.kind != Contact::Below) {
                    st.touchedTerrain = st.touchedWater = true;  // entered above both (patchContact: C > 0)
                    if (cw.kind != Contact::Hit) return false;
                    res.hit = res.water = true;
                    res.t = segment.t + cw.tau, res.gx = cw.gx, res.gy = cw.gy;
                    return true;
                }
            }
        }
        PatchContact ct = patchContact(tex.terrain, iu, iv, ray, segment);
        st.touchedTerrain = st.touchedTerrain || ct.enteredAbove;
        if (ct.kind == Contact::Below) {
            const double z0 = ray.zAt(segment.t);
            if (z0 < zFloor) {  // under the block: its bottom, if the ray rises through it over this patch
                const double tauF = ray.dz > 0 ? (zFloor - z0) / ray.dz : HUGE_VAL;
                if (tauF <= segment.len) {
                    res.hit = res.wall = true;
                    res.t = segment.t + tauF, res.nz = -1;
                    return true;
                }
                return false;  // nothing of the block in this patch; the water lies on top of it
            }
            if (segment.t > tStart) {
                const From from = cameFrom(ray, iu, iv);
                if (!patchDefined(tex.terrain, from.u, from.v)) {  // from a hole or outside: the wall on that edge
                    res.hit = res.wall = true;
                    res.t = segment.t;
                    (from.acrossU ? res.nx : res.ny) = (from.acrossU ? ray.du : ray.dv) > 0 ? -1 : 1;
                    return true;
                }
            }
            if (!st.touchedTerrain) {
                res.terrainUnderground = true;
                return true;
            }
            ct.kind = Contact::Hit;  // a seam: the hit is where the ray went under (tau = 0)
        }
        PatchContact cw;
        if (water && mayHaveSurface(tex.water, iu, iv)) {
            cw = patchContact(tex.water, iu, iv, ray, segment);
            st.touchedWater = st.touchedWater || cw.enteredAbove;
            // Under the water surface at its first contact (a camera in a lake), or come in under it through its
            // edge (from a patch without water, where the level lies above a dry shore): the ray is under the
            // water, which is not drawn for it; it goes on to the ground. (Hitting the edge would draw water below
            // its level: up to 21 m on the hef flood before this rule.)
            if (cw.kind == Contact::Below) {
                const From from = cameFrom(ray, iu, iv);
                const bool throughEdge = segment.t > tStart && !patchDefined(tex.water, from.u, from.v);
                if (!st.touchedWater || throughEdge) {
                    res.waterUnderground = true;
                    water = false;
                    cw.kind = Contact::None;
                } else {
                    cw.kind = Contact::Hit;  // a seam, as for the terrain
                }
            }
        }
        if (cw.kind == Contact::Hit && (ct.kind != Contact::Hit || cw.tau <= ct.tau)) {
            res.hit = res.water = true;
            res.t = segment.t + cw.tau, res.gx = cw.gx, res.gy = cw.gy;
            return true;
        }
        if (ct.kind == Contact::Hit) {
            res.hit = true;
            res.t = segment.t + ct.tau, res.gx = ct.gx, res.gy = ct.gy;
            return true;
        }
        return false;
    }
};

// The first point in [tIn, tOut] where the ray meets the terrain or (when `water`) the water surface of
// cascade `c`, in one walk over both: a node is skipped when the ray passes above the larger of the two
// maxima, and each patch reached is intersected with both surfaces, the earlier hit winning (water on a
// tie, as it lies on top). Texture coordinates: u = (x - x0) / s, v = (y - y0) / s; patch (i, j) spans u in
// [i, i+1], v in [j, j+1].
//
// The terrain block (top of this file). A ray that enters a defined patch at or under its surface, at a
// height between the block's bottom `zFloor` and the surface:
// - coming from a patch without surface (a hole, outside the domain): it hits the wall on that edge, whose
//   normal is horizontal, pointing back across the edge;
// - at the start of its walk through this cascade, having met no surface before (`touched`, over every
//   cascade of the ray): it starts inside the block (a camera under the terrain) and sees nothing;
// - otherwise it has gone under the surface where two discretisations meet (a cascade's seam), and hits
//   where it entered.
// Under the block's bottom it goes on, and hits the bottom where it rises through it under a defined patch.
// The water surface has no walls: under it at its first contact (a camera in a lake), or come in under it
// through its edge, a ray does not draw it and goes on to the ground.
//
// tFrom > tIn: a bound from the ray's beam (Beam) before which the ray comes down to no node's maximum. The walk then
// starts at level 0 at the patch under tFrom, entered where the walk from tIn would enter it: every node before it
// would have been skipped without a contact (a patch's test fails wherever its ancestors' do), so the hit and the
// ray's state are the same.
//
// `setup`, `i`, `tFloor`: the ray's setup in this cascade (RaySetups).
//
// Inlined into hitIn(), as the patch tests are into it: the calls, a dozen arguments and a patch's corners passed
// through memory, were a twentieth of a ray's instructions (docs/benchmarks.md, issue 44).
[[gnu::always_inline]] inline PatchHit traverse(const CascadeTextures& tex, const Cascade& c, const glm::dvec3& o,
                                                const glm::dvec3& d, double tIn, double tOut, double zFloor,
                                                RayState& st, double tFrom, const RaySetups::Cascade& setup, size_t i,
                                                double tFloor) {
    const Heightfield& hf = tex.terrain;
    PatchHit res;  // the one result every path returns (named: built in the caller's slot)
    if (hf.mip.empty() || !(tIn < tOut)) return res;
    const TexelRay ray = texelRay(c, setup, i, o, d);
    PatchWalk walk{tex, ray, tIn, zFloor, tex.hasWater && !st.underWater && !tex.water.mip.empty(), st, res};
    const double u0 = ray.u0, v0 = ray.v0, du = ray.du, dv = ray.dv;
    const double invDu = setup.invDu[i], invDv = setup.invDv[i];  // du != 0 ? 1 / du : 0, and likewise
    const int top = int(hf.mip.size()) - 1;
    const int patches = hf.n - 1;
    const bool both = tex.bothMip.size() == hf.mip.size();  // one load a node (CascadeTextures::bothMip)
    auto maxAt = [&](int level, size_t idx) {
        if (!walk.water) return hf.mip[size_t(level)][idx];
        if (both) return tex.bothMip[size_t(level)][idx];
        return std::max(hf.mip[size_t(level)][idx], tex.water.mip[size_t(level)][idx]);
    };
    if (!clipToHeights(ray, maxAt(top, 0), zFloor, walk.water ? setup.tTopWet[i] : setup.tTopDry[i], tFloor, tIn, tOut))
        return res;
    // The walk carries its node as integers (level, iu, iv) and steps to the neighbour across the edge the ray
    // leaves by, as a grid walk does; each node's exit follows from its integers. It used to find each node
    // again from the ray's point a hair past t, a chain from float to int and back through every visit; now
    // only a descent reads the ray's point, to pick the child it enters.
    // Start three levels below the top (the coarsest nodes are nearly always entered; the walk climbs back
    // when it leaves a parent): a little faster than starting at the top, no more.
    int level = std::max(0, top - 3);
    const double tiny = 1e-9 * (1.0 + std::abs(tOut));
    // The patch under the ray a hair past t (so a node boundary belongs to the node the ray moves into);
    // false once that is outside the texture.
    auto patchAfter = [&](double t, int& pu, int& pv) {
        const double tp = std::min(t + tiny, tOut);
        const double u = u0 + du * tp, v = v0 + dv * tp;
        if (!(u >= 0 && v >= 0 && u < patches && v < patches)) return false;
        pu = int(u), pv = int(v);  // u, v >= 0: truncation is floor
        return true;
    };
    int iu = 0, iv = 0;
    double t = tIn;
    if (tFrom > tIn) {
        if (!(tFrom < tOut)) return res;  // the beam meets nothing of this cascade within the ray's span
        if (patchAfter(tFrom, iu, iv)) {
            // Entered across the later of its two edges: the same expression as the exit of the node before it below.
            const double enterU = du > 0 ? (iu - u0) * invDu : du < 0 ? (iu + 1 - u0) * invDu : -HUGE_VAL;
            const double enterV = dv > 0 ? (iv - v0) * invDv : dv < 0 ? (iv + 1 - v0) * invDv : -HUGE_VAL;
            t = std::max({enterU, enterV, tIn});
            level = 0;
        } else {
            tFrom = tIn;  // rounding at the texture's edge: the whole walk
        }
    }
    if (!(tFrom > tIn)) {
        if (!patchAfter(tIn, iu, iv)) return res;
        iu >>= level, iv >>= level;
    }
    const int stepU = du > 0 ? 1 : -1, stepV = dv > 0 ? 1 : -1;
    const double edgeU = du > 0 ? 1.0 : 0.0,
                 edgeV = dv > 0 ? 1.0 : 0.0;  // the side of a node the ray leaves by, in nodes
    for (int guard = 0; guard < 1 << 20; ++guard) {
        const int side = hf.mipSide[size_t(level)];
        // Left the texture (side >= 1; a negative index wraps to a large unsigned one).
        if (unsigned(iu) >= unsigned(side) || unsigned(iv) >= unsigned(side)) break;
        const double span = double(1 << level);
        // Where the ray leaves this node.
        const double tExitU = du != 0 ? ((iu + edgeU) * span - u0) * invDu : HUGE_VAL;
        const double tExitV = dv != 0 ? ((iv + edgeV) * span - v0) * invDv : HUGE_VAL;
        const double tExit = std::max(std::min({tOut, tExitU, tExitV}), t);
        const float nodeMax = maxAt(level, size_t(iv) * size_t(side) + size_t(iu));
        if (std::min(ray.zAt(t), ray.zAt(tExit)) <= nodeMax) {
            if (level > 0) {  // the child the ray enters: under its point a hair past t, kept within this node
                int pu = iu << level, pv = iv << level;
                patchAfter(t, pu, pv);
                --level;
                iu = std::clamp(pu >> level, 2 * iu, 2 * iu + 1);
                iv = std::clamp(pv >> level, 2 * iv, 2 * iv + 1);
                continue;
            }
            // A patch: exact intersection with its bilinear surfaces.
            if (walk.endsAt(iu, iv, RaySpan{t, tExit - t})) return res;
        }
        // Past the node (empty space, or a patch the ray misses): on to the neighbour across the edge it leaves
        // by, and a level up when that neighbour has another parent.
        if (tExit >= tOut) break;
        t = tExit;
        bool leavesParent;
        if (tExitU <= tExitV) {
            leavesParent = stepU > 0 ? (iu & 1) == 1 : (iu & 1) == 0;
            iu += stepU;
        } else {
            leavesParent = stepV > 0 ? (iv & 1) == 1 : (iv & 1) == 0;
            iv += stepV;
        }
        if (leavesParent && level < top) ++level, iu >>= 1, iv >>= 1;  // >> floors: -1 stays outside
    }
    return res;
}

// The ray's hit in cascade k, into `h` (written in place: castRay's copies of a returned Hit cost a store-forwarding
// stall a ray).
void hitIn(const RayContext& ctx, size_t k, const glm::dvec3& o, const glm::dvec3& d, const RaySetups& setups,
           size_t ray, RayState& st, bool& underground, double tFrom, Hit& h) {
    h = Hit{};
    const Cascade& c = ctx.fit->cascades[k];
    const CascadeTextures& tex = (*ctx.tex)[k];
    if (c.empty()) return;
    const RaySetups::Cascade& setup = setups.cascades[k];
    const double t0 = setup.t0[ray], t1 = setup.t1[ray];  // the ray's span in the cascade's slab and over its patches
    if (!(t0 < t1) || !(tFrom < t1)) return;  // past tFrom the beam meets nothing of this cascade (traverse())
    const PatchHit best = traverse(tex, c, o, d, t0, t1, ctx.zFloor, st, tFrom, setup, ray, setups.tFloor[ray]);
    if (best.terrainUnderground) {
        underground = true;
        return;
    }
    if (best.waterUnderground) st.underWater = true;
    if (!best.hit) return;
    h.hit = true;
    h.t = best.t;
    h.water = best.water;
    h.wall = best.wall;
    h.cascade = int(k);
    if (h.wall) {
        h.nx = best.nx, h.ny = best.ny, h.nz = best.nz;
        return;
    }
    h.slopeOnly = true;  // the normal: normalOfSlope, by the caller
    h.gx = best.gx, h.gy = best.gy, h.texelM = c.texelM;
    if (h.water) {  // depth at the hit: bilinear from the depth texture
        const double u = (o[0] + d[0] * h.t - c.x0) / c.texelM, v = (o[1] + d[1] * h.t - c.y0) / c.texelM;
        const int i = std::clamp(int(std::floor(u)), 0, c.n - 2), j = std::clamp(int(std::floor(v)), 0, c.n - 2);
        const double a = std::clamp(u - i, 0.0, 1.0), b = std::clamp(v - j, 0.0, 1.0);
        const float* r0 = &tex.depth[size_t(j) * size_t(c.n) + size_t(i)];
        h.depth = (1 - b) * ((1 - a) * r0[0] + a * r0[1]) + b * ((1 - a) * r0[c.n] + a * r0[c.n + 1]);
    }
}

}  // namespace

Hit castRay(const RayContext& ctx, const glm::dvec3& dir, const RaySetups& setups, size_t ray, Beam* beam,
            double dirLength) {
    const auto& cs = ctx.fit->cascades;
    RayState st;
    bool underground = false;
    Hit h;  // the one result every path returns (named: built in the caller's slot)
    // Where the beam lets this ray's walk through cascade k start (t = tau |direction|; a hair early for rounding).
    auto from = [&](size_t k) { return beam ? beam->startDepth(k) * dirLength * (1 - 1e-12) : 0.0; };
    for (size_t k = 0; k < cs.size(); ++k) {
        if (beam && beam->passesOver(k)) continue;  // the ray walks nothing there (Beam::passesOver)
        hitIn(ctx, k, ctx.eyeLocal, dir, setups, ray, st, underground, from(k), h);
        if (underground) return h;  // hitIn left it a miss
        if (!h.hit) continue;
        // In the overlap with the next cascade: blend both hits by a convex combination, if they are on the same
        // surface (issue 11: a blend of a ridge in one cascade and the slope behind it in the next, which the
        // coarser texture's ridge let the ray pass to, lands in the air between them). The same surface: the
        // same kind (terrain, water), not a wall (walls stand on each cascade's own lattice), and no farther
        // apart along the ray than a texel of the coarser cascade, so that the chord between them stays within
        // the discretisation bound of the surface. Otherwise the nearer cascade's (finer) hit stands.
        if (k + 1 < cs.size() && !h.wall) {
            const glm::dvec2 eye{ctx.eyeLocal};
            const double off = glm::dot(eye + glm::dvec2(dir) * h.t - eye, ctx.fit->dir);
            const double zoneStart = cs[k].splitFar, zoneEnd = cs[k].farWithOverlap;
            if (off > zoneStart && zoneEnd > zoneStart && !(beam && beam->passesOver(k + 1))) {
                RayState st2 = st;
                st2.touchedTerrain = st2.touchedWater = true;
                bool under2 = false;
                Hit h2;
                hitIn(ctx, k + 1, ctx.eyeLocal, dir, setups, ray, st2, under2, from(k + 1), h2);
                if (h2.hit && h2.water == h.water && !h2.wall &&
                    std::abs(h2.t - h.t) <= std::max(cs[k].texelM, cs[k + 1].texelM)) {
                    for (Hit* x : {&h, &h2})
                        if (x->slopeOnly)
                            normalOfSlope(x->gx, x->gy, x->texelM, x->nx, x->ny, x->nz), x->slopeOnly = false;
                    const double w = std::clamp((off - zoneStart) / (zoneEnd - zoneStart), 0.0, 1.0);
                    h.t = (1 - w) * h.t + w * h2.t;
                    double nx = (1 - w) * h.nx + w * h2.nx, ny = (1 - w) * h.ny + w * h2.ny,
                           nz = (1 - w) * h.nz + w * h2.nz;
                    const double nl = std::sqrt(nx * nx + ny * ny + nz * nz);
                    h.nx = nx / nl, h.ny = ny / nl, h.nz = nz / nl;
                    h.depth = (1 - w) * h.depth + w * h2.depth;
                }
            }
        }
        return h;
    }
    return h;  // a miss: Hit{}, or as the last hitIn left it (a miss)
}

}  // namespace hc::render::detail
