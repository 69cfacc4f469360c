#version 430
// render/gl/shaders/raycast.comp: one ray per pixel through the cascades (docs/design.md section 5 step 4),
// mirroring render/src/raycast.cpp: traverse() (hierarchical max-mipmap traversal, exact
// ray/bilinear-patch intersection, the solid-terrain rules), hitIn() (a cascade's slab and texture
// clip) and castRay() (near to far, blending in the overlaps). As on the CPU, terrain and water are
// walked in one pass over both maxima; rays start where their tile's beam allows (beams.comp).
//
// Precision: the ray starts at the eye (t = 0 at the camera) and the cascade origins come in eye
// relative (GpuCascade::x0Eye), so every float here is a distance within the scene, never a
// coordinate of the grid's CRS: at the 100 km a scene may span, float resolves 8 mm, and a texture
// coordinate u = -x0Eye / s + t du (at most a few thousand texels) 1e-4 texel. Heights stay in the
// local z frame as on the CPU (elevations below 9 km: 0.5 mm). The CPU casts in double; the two agree
// to about 1e-7 of the distance (tests/render_gl_test.cpp).
layout(local_size_x = HC_GROUP_2D, local_size_y = HC_GROUP_2D) in;

layout(std430, binding = HC_BIND_HEIGHTS) readonly buffer HeightBlock { float heights[]; };
layout(std430, binding = HC_BIND_PIXELS) writeonly buffer PixelBlock { GpuPixel pixels[]; };

struct PatchHit {
    bool hit;
    bool underground;  // the ray met the terrain first from below: it starts inside the block
    float t;
    float gx, gy;      // surface slope dz/dx, dz/dy at the hit [m/m]
    bool wall;         // a cut face of the terrain block (raycast.cpp): its normal in wn
    vec3 wn;
    bool water;        // the hit is on the water surface
};

struct Hit {
    bool hit;
    float t;
    vec3 n;
    float depth;
    bool water;
    int cascade;
    bool wall;
};

// What a ray has met so far, over its cascades (raycast.cpp RayState).
struct RayState {
    bool touchedTerrain, touchedWater, underWater;
};

float mipValue(int k, bool water, int level, uint index) {
    return heights[(water ? cascades[k].waterMip[level] : cascades[k].terrainMip[level]) + index];
}

PatchHit noPatchHit() { return PatchHit(false, false, 0.0, 0.0, 0.0, false, vec3(0.0), false); }

// Does patch (iu, iv) of cascade k's heightfield at `base` have four defined corners? (patchDefined())
bool patchDefined(int k, uint base, int iu, int iv) {
    const int n = cascades[k].n;
    if (iu < 0 || iv < 0 || iu >= n - 1 || iv >= n - 1) return false;
    const uint r0 = base + uint(iv * n + iu);
    return heights[r0] > -kInf && heights[r0 + 1u] > -kInf && heights[r0 + uint(n)] > -kInf && heights[r0 + uint(n) + 1u] > -kInf;
}

// A ray in cascade k's texture coordinates u = (x - x0) / s, v = (y - y0) / s: at t [m along the ray] it is at
// (u0 + du t, v0 + dv t), height eyeZ + d.z t.
struct TexelRay {
    vec3 d;
    float u0, v0, du, dv, invDu, invDv;
};

// Patch (iu, iv) of cascade k's terrain or (water) water surface over [t, t + len], under the rules of raycast.cpp's
// PatchWalk: 0 when the ray goes on past it, 1 when res holds the hit (on the surface, a wall or the block's bottom),
// 2 when the ray meets this surface first from below (the terrain: it starts inside the block and sees nothing; the
// water: it is under the water, which is then not drawn for it).
int patchTest(int k, bool water, int iu, int iv, TexelRay r, float t, float len, float tStart, float slack, inout bool touched,
              inout PatchHit res) {
    const int n = cascades[k].n;
    const uint base = water ? cascades[k].waterOffset : cascades[k].terrainOffset;
    const uint r0 = base + uint(iv * n + iu);
    const float h00 = heights[r0], h10 = heights[r0 + 1u], h01 = heights[r0 + uint(n)], h11 = heights[r0 + uint(n) + 1u];
    if (!(h00 > -kInf && h10 > -kInf && h01 > -kInf && h11 > -kInf)) return 0;
    const vec3 d = r.d;
    const float du = r.du, dv = r.dv;
    const float a0 = r.u0 + du * t - float(iu), b0 = r.v0 + dv * t - float(iv), z0 = frame.eyeZ + d.z * t;
    const float e = h00 - h10 - h01 + h11;
    // f(tau) = z(tau) - bilinear(tau), tau from t: C + B tau + A tau^2.
    const float C = z0 - (h00 + (h10 - h00) * a0 + (h01 - h00) * b0 + e * a0 * b0);
    const float B = d.z - (h10 - h00) * du - (h01 - h00) * dv - e * (a0 * dv + b0 * du);
    const float A = -e * du * dv;
    float tau = -1.0;
    // Under the terrain block's bottom: nothing in this patch but the bottom, if the ray rises through it (the water
    // lies on top of the block).
    const bool under = C <= 0.0 && z0 < frame.zFloor;
    if (under && !water) {
        const float tauF = d.z > 0.0 ? (frame.zFloor - z0) / d.z : kInf;
        if (tauF <= len) {
            res.hit = res.wall = true;
            res.t = t + tauF;
            res.wn = vec3(0.0, 0.0, -1.0);
            return 1;
        }
    }
    if (C <= 0.0 && !under && t > tStart) {
        // Through which edge did the ray come in? The one it crossed last.
        const float enterU = du > 0.0 ? (float(iu) - r.u0) * r.invDu : du < 0.0 ? (float(iu + 1) - r.u0) * r.invDu : -kInf;
        const float enterV = dv > 0.0 ? (float(iv) - r.v0) * r.invDv : dv < 0.0 ? (float(iv + 1) - r.v0) * r.invDv : -kInf;
        const bool acrossU = enterU >= enterV;
        const int fromU = acrossU ? iu - (du > 0.0 ? 1 : -1) : iu, fromV = acrossU ? iv : iv - (dv > 0.0 ? 1 : -1);
        if (!patchDefined(k, base, fromU, fromV)) {
            if (water) return 2;  // under the water through its edge: not drawn for this ray (traverse())
            // From a hole or outside: the wall on that edge.
            res.hit = res.wall = true;
            res.t = t;
            res.wn = acrossU ? vec3(du > 0.0 ? -1.0 : 1.0, 0.0, 0.0) : vec3(0.0, dv > 0.0 ? -1.0 : 1.0, 0.0);
            return 1;
        }
    }
    if (under) {
    } else if (C <= 0.0) {
        if (!touched && C < -slack) return 2;
        tau = 0.0;
    } else if (abs(A) <= 1e-12 * abs(B)) {
        if (B < 0.0) tau = -C / B;
    } else {
        const float disc = B * B - 4.0 * A * C;
        if (disc >= 0.0) {
            const float q = -0.5 * (B + (B < 0.0 ? -sqrt(disc) : sqrt(disc)));
            float r1 = q / A, r2 = q != 0.0 ? C / q : r1;
            if (r1 > r2) {
                const float tmp = r1;
                r1 = r2;
                r2 = tmp;
            }
            tau = r1 >= 0.0 ? r1 : r2;  // C > 0: the first root is where the ray goes under
        }
    }
    if (!under) touched = true;
    if (!(tau >= 0.0 && tau <= len)) return 0;
    const float a = clamp(a0 + du * tau, 0.0, 1.0), b = clamp(b0 + dv * tau, 0.0, 1.0);
    const float s = cascades[k].texelF;
    res.hit = true;
    res.t = t + tau;
    res.gx = ((h10 - h00) + e * b) / s;
    res.gy = ((h01 - h00) + e * a) / s;
    return 1;
}

// traverse() of raycast.cpp: the first point in [tIn, tOut] where the ray from the eye along d meets cascade k's
// terrain or, unless the ray is under water (st.underWater), its water surface, in one walk over both: a node is
// skipped where the ray passes above the larger of the two maxima by more than the slack, and each patch reached is
// intersected with each surface the ray comes down to there, the terrain first, then the water before the terrain's
// hit (the water wins a tie: it lies on top). Texture coordinates u = (x - x0) / s, v = (y - y0) / s. The terrain is the
// solid block of raycast.cpp, with its walls and bottom; res.underground when the ray starts inside it. Each surface
// used to be walked on its own, the water up to the terrain's hit (on a flooded scene the water's walk was a large
// share of llvmpipe's ray casting, docs/benchmarks.md); a surface's patch test runs where that walk would have reached
// it, so the hits are the same.
//
// tFrom > tIn: a bound from the ray's beam (beams.comp) before which the ray stays above every node's maximum by more
// than the slack below, so that the walk from tIn would skip every node before it without a contact. The walk then
// starts at level 0 at the patch under tFrom, at the t the walk from tIn would enter it with (the same expressions), so
// that its hit is the same.
PatchHit traverse(int k, vec3 d, float tIn, float tOut, inout RayState st, float tFrom) {
    PatchHit res = noPatchHit();
    const float tStart = tIn;
    // Under the block's bottom there is nothing to hit but the bottom, where a rising ray comes up through it:
    // start there; a falling ray ends there (traverse() of raycast.cpp). The water lies above the block's bottom.
    if (d.z != 0.0) {
        const float tFloor = (frame.zFloor - frame.eyeZ) / d.z, margin = 1e-6 * (1.0 + abs(tFloor));
        if (d.z > 0.0) tIn = max(tIn, tFloor - margin);
        else tOut = min(tOut, tFloor + margin);
    } else if (frame.eyeZ < frame.zFloor) {
        return res;
    }
    if (!(tIn < tOut)) return res;
    bool water = frame.hasWater != 0 && !st.underWater;
    const float s = cascades[k].texelF;
    TexelRay r;
    r.d = d;
    r.u0 = -cascades[k].x0Eye / s, r.v0 = -cascades[k].y0Eye / s, r.du = d.x / s, r.dv = d.y / s;
    r.invDu = r.du != 0.0 ? 1.0 / r.du : 0.0, r.invDv = r.dv != 0.0 ? 1.0 / r.dv : 0.0;
    const float u0 = r.u0, v0 = r.v0, du = r.du, dv = r.dv, invDu = r.invDu, invDv = r.invDv;
    const int top = cascades[k].levels - 1;
    const int patches = cascades[k].n - 1;
    const float eyeZ = frame.eyeZ;
    const float topMax = water ? max(mipValue(k, false, top, 0u), mipValue(k, true, top, 0u)) : mipValue(k, false, top, 0u);
    // A ray above the whole cascade never hits it.
    if (min(eyeZ + d.z * tIn, eyeZ + d.z * tOut) > topMax) return res;
    int level = top;
    float t = tIn;
    // The CPU nudges by 1e-9 of the range in double; in float the nudge must exceed a few ulps of t
    // (1.2e-7 relative) and stay far below a texel (t / s is at most a few thousand).
    const float tiny = 1e-6 * (1.0 + abs(tOut));
    if (tFrom > tIn) {
        if (!(tFrom < tOut)) return res;  // the beam meets nothing of this cascade within the ray's span
        const float tp = min(tFrom + tiny, tOut);
        const float pu = u0 + du * tp, pv = v0 + dv * tp;
        if (pu >= 0.0 && pv >= 0.0 && pu < float(patches) && pv < float(patches)) {
            // Entered across the later of its two edges, a node's exit below, nudged as after a skip.
            const int iu = int(pu), iv = int(pv);
            const float enterU = du > 0.0 ? (float(iu) - u0) * invDu : du < 0.0 ? (float(iu + 1) - u0) * invDu : -kInf;
            const float enterV = dv > 0.0 ? (float(iv) - v0) * invDv : dv < 0.0 ? (float(iv + 1) - v0) * invDv : -kInf;
            t = max(max(enterU, enterV) + tiny, tIn);
            level = 0;
        }
    }
    // Heights along the ray carry float rounding of a few ulps of the eye height and of the surface
    // (about 1e-7 of each). Empty space is skipped only beyond that slack, and a first contact from
    // below within it is the ray arriving at the surface, not starting under it: otherwise a rounding in
    // the skip test lets a ray slip under a flat water surface and the solid-surface rule then hides the
    // water for the rest of the ray. (raycast.cpp has no slack: in double the rounding is 1e-9 of this.)
    const float slack = 1e-6 * (abs(eyeZ) + abs(topMax)) + 1e-3;
    for (int guard = 0; guard < (1 << 16) && t <= tOut; ++guard) {
        const float tp = min(t + tiny, tOut);
        const float pu = u0 + du * tp, pv = v0 + dv * tp;
        const int span = 1 << level;
        const int side = cascades[k].mipSide[level];
        if (!(pu >= 0.0 && pv >= 0.0 && pu < float(patches) && pv < float(patches))) break;  // left the texture
        const int iu = int(pu) >> level, iv = int(pv) >> level;
        if (iu >= side || iv >= side) break;
        float tExitU = kInf, tExitV = kInf;
        if (du > 0.0) tExitU = (float((iu + 1) * span) - u0) * invDu;
        if (du < 0.0) tExitU = (float(iu * span) - u0) * invDu;
        if (dv > 0.0) tExitV = (float((iv + 1) * span) - v0) * invDv;
        if (dv < 0.0) tExitV = (float(iv * span) - v0) * invDv;
        const float tExit = max(min(min(tOut, tExitU), tExitV), t);
        // Does the next node have another parent? Only then is a coarser level worth a look.
        const bool exitU = tExitU <= tExitV;
        const int idx = exitU ? iu : iv;
        const bool forward = exitU ? du > 0.0 : dv > 0.0;
        const bool leavesParent = forward ? (idx & 1) == 1 : (idx & 1) == 0;
        const uint node = uint(iv * side + iu);
        const float terrainMax = mipValue(k, false, level, node);
        const float waterMax = water ? mipValue(k, true, level, node) : -kInf;
        const float zLow = min(eyeZ + d.z * t, eyeZ + d.z * tExit);
        if (zLow > max(terrainMax, waterMax) + slack) {  // empty space: skip the node, and look at a coarser level next
            t = tExit + tiny;
            if (leavesParent) level = min(level + 1, top);
            continue;
        }
        if (level > 0) {
            --level;
            continue;
        }
        // A patch: exact intersection with the bilinear surfaces the ray comes down to here, the terrain first, then
        // the water up to the terrain's hit (one call site: a second copy of the test made llvmpipe's walk slower).
        PatchHit th = noPatchHit();
        int tr = 0;
        for (int surface = 0; surface < (water ? 2 : 1); ++surface) {
            const bool w = surface == 1;
            const float tEnd = w && tr == 1 ? th.t : tExit;
            if (min(eyeZ + d.z * t, eyeZ + d.z * tEnd) > (w ? waterMax : terrainMax) + slack) continue;  // not down to it here
            PatchHit ph = noPatchHit();
            bool touched = w ? st.touchedWater : st.touchedTerrain;
            const int got = patchTest(k, w, iu, iv, r, t, tEnd - t, tStart, slack, touched, ph);
            if (w) st.touchedWater = touched;
            else st.touchedTerrain = touched;
            if (!w) {
                if (got == 2) {
                    res.underground = true;
                    return res;
                }
                tr = got, th = ph;
            } else if (got == 2) {
                st.underWater = true;  // not drawn for this ray, in this cascade and the next
                water = false;
            } else if (got == 1) {
                ph.water = true;
                return ph;
            }
        }
        if (tr == 1) return th;
        t = tExit + tiny;
        if (leavesParent) level = min(level + 1, top);
    }
    return res;
}

Hit noHit() { return Hit(false, 0.0, vec3(0.0), 0.0, false, -1, false); }

// hitIn() of raycast.cpp: cascade k's hit between the offsets lo and hi (from the eye, along the
// horizontal view direction), on the terrain or the water in front of it; tFrom as in traverse().
Hit hitIn(int k, vec3 d, float lo, float hi, inout RayState st, inout bool underground, float tFrom) {
    Hit h = noHit();
    if (cascades[k].n == 0) return h;
    float t0 = frame.nearM, t1 = frame.farM;
    // The slab clip of setUpSpans() (ray_setup.cpp): the eye is the origin, so the offset at t = 0 is 0.
    const float rate = d.x * frame.dirX + d.y * frame.dirY;
    if (abs(rate) < 1e-15) {
        if (!(0.0 >= lo && 0.0 <= hi)) return h;
    } else {
        float a = lo / rate, b = hi / rate;
        if (a > b) {
            const float tmp = a;
            a = b;
            b = tmp;
        }
        t0 = max(t0, a);
        t1 = min(t1, b);
    }
    // Clip to the texture's patch domain.
    const float ext = float(cascades[k].n - 1) * cascades[k].texelF;
    for (int axis = 0; axis < 2; ++axis) {
        const float lo0 = axis == 0 ? cascades[k].x0Eye : cascades[k].y0Eye;
        const float da = d[axis];
        if (abs(da) < 1e-30) {
            if (0.0 < lo0 || 0.0 > lo0 + ext) return h;
            continue;
        }
        float a = lo0 / da, b = (lo0 + ext) / da;
        if (a > b) {
            const float tmp = a;
            a = b;
            b = tmp;
        }
        t0 = max(t0, a);
        t1 = min(t1, b);
    }
    if (!(t0 < t1) || !(tFrom < t1)) return h;  // past tFrom the beam meets nothing of this cascade (traverse())
    const PatchHit best = traverse(k, d, t0, t1, st, tFrom);
    if (best.underground) {
        underground = true;
        return h;
    }
    if (!best.hit) return h;
    h.hit = true;
    h.t = best.t;
    h.water = best.water;
    h.wall = best.wall;
    h.n = best.wall ? best.wn : vec3(-best.gx, -best.gy, 1.0) / sqrt(best.gx * best.gx + best.gy * best.gy + 1.0);
    h.cascade = k;
    if (h.water) {  // depth at the hit: bilinear from the depth texture
        const float s = cascades[k].texelF;
        const int n = cascades[k].n;
        const float u = (d.x * h.t - cascades[k].x0Eye) / s, v = (d.y * h.t - cascades[k].y0Eye) / s;
        const int i = clamp(int(floor(u)), 0, n - 2), j = clamp(int(floor(v)), 0, n - 2);
        const float a = clamp(u - float(i), 0.0, 1.0), b = clamp(v - float(j), 0.0, 1.0);
        const uint r0 = cascades[k].depthOffset + uint(j * n + i);
        h.depth = (1.0 - b) * ((1.0 - a) * heights[r0] + a * heights[r0 + 1u]) + b * ((1.0 - a) * heights[r0 + uint(n)] + a * heights[r0 + uint(n) + 1u]);
    }
    return h;
}

// The beams' start depths (beams.comp): per tile of frame.beamTile^2 pixels and cascade, the depth where its rays start
// their walks (t = depth |f + sx r + sy u|; 0: the whole walk) and whether they skip the cascade (1: the march passed
// over its whole slab).
layout(std430, binding = HC_BIND_BEAMS) readonly buffer BeamBlock { vec2 beams[]; };

// castRay() of raycast.cpp. tile: the ray's tile in beams (-1: none); len: |f + sx r + sy u|.
Hit castRay(vec3 d, int tile, float len) {
    RayState st = RayState(false, false, false);
    bool underground = false;
    for (int k = 0; k < frame.cascades; ++k) {
        const int at = tile * kMaxCascades + k;
        if (tile >= 0 && beams[at].y != 0.0) continue;  // the ray walks nothing there
        const float from = tile >= 0 ? beams[at].x * len * (1.0 - 1e-5) : 0.0;
        const float lo = k == 0 ? -kInf : cascades[k].splitNear;
        Hit h = hitIn(k, d, lo, cascades[k].farWithOverlap, st, underground, from);
        if (underground) return noHit();
        if (!h.hit) continue;
        // In the overlap with the next cascade: blend both hits by a convex combination, if they are on the same
        // surface (castRay(): the same kind, no wall, no farther apart than a texel of the coarser cascade).
        if (k + 1 < frame.cascades && !h.wall) {
            const float off = (d.x * frame.dirX + d.y * frame.dirY) * h.t;
            const float zoneStart = cascades[k].splitFar, zoneEnd = cascades[k].farWithOverlap;
            if (off > zoneStart && zoneEnd > zoneStart && !(tile >= 0 && beams[at + 1].y != 0.0)) {
                RayState st2 = st;
                st2.touchedTerrain = true;
                st2.touchedWater = true;
                bool under2 = false;
                const float from2 = tile >= 0 ? beams[at + 1].x * len * (1.0 - 1e-5) : 0.0;
                const Hit h2 = hitIn(k + 1, d, cascades[k + 1].splitNear, cascades[k + 1].farWithOverlap, st2, under2, from2);
                if (h2.hit && h2.water == h.water && !h2.wall && abs(h2.t - h.t) <= max(cascades[k].texelF, cascades[k + 1].texelF)) {
                    const float w = clamp((off - zoneStart) / (zoneEnd - zoneStart), 0.0, 1.0);
                    h.t = (1.0 - w) * h.t + w * h2.t;
                    h.n = normalize((1.0 - w) * h.n + w * h2.n);
                    h.depth = (1.0 - w) * h.depth + w * h2.depth;
                }
            }
        }
        return h;
    }
    return noHit();
}

void main() {
    const uint px = gl_GlobalInvocationID.x, py = gl_GlobalInvocationID.y;
    if (px >= uint(frame.width) || py >= uint(frame.height)) return;
    const uint T = uint(frame.beamTile);
    const int tile = T > 1u ? int((py / T) * ((uint(frame.width) + T - 1u) / T) + px / T) : -1;
    const vec3 d = rayDirection(px, py);
    const Hit h = castRay(d, tile, length(rawDirection(sxOf(float(px)), syOf(float(py)))));
    GpuPixel p;
    p.t = h.hit ? h.t : kInf;
    p.relX = h.hit ? d.x * h.t : 0.0;
    p.relY = h.hit ? d.y * h.t : 0.0;
    p.relZ = h.hit ? d.z * h.t : 0.0;
    p.nx = h.n.x;
    p.ny = h.n.y;
    p.nz = h.n.z;
    p.depth = h.depth;
    p.cascade = h.cascade;
    p.water = h.water ? 1 : 0;
    p.wall = h.hit && h.wall ? 1 : 0;
    pixels[py * uint(frame.width) + px] = p;
}
