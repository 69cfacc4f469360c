#version 430
// render/gl/shaders/raycast.comp: one ray per pixel through the cascades (DESIGN.md section 5 step 4),
// mirroring render/src/raycast.cpp: traverse() (hierarchical max-mipmap traversal, exact
// ray/bilinear-patch intersection, the solid-terrain rules), hitIn() (a cascade's slab and texture
// clip, terrain then water) and castRay() (near to far, blending in the overlaps). The CPU walks
// terrain and water in one pass (the same first hits, fewer node visits); here each heightfield is
// walked on its own, which the GPU's frame budget has not needed to change.
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
    bool underground;  // the ray met the surface first from below: it starts inside the terrain
    float t;
    float gx, gy;      // surface slope dz/dx, dz/dy at the hit [m/m]
    bool wall;         // a cut face of the terrain block (raycast.cpp): its normal in wn
    vec3 wn;
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

PatchHit noPatchHit() { return PatchHit(false, false, 0.0, 0.0, 0.0, false, vec3(0.0)); }

// Does patch (iu, iv) of cascade k's heightfield at `base` have four defined corners? (patchDefined())
bool patchDefined(int k, uint base, int iu, int iv) {
    const int n = cascades[k].n;
    if (iu < 0 || iv < 0 || iu >= n - 1 || iv >= n - 1) return false;
    const uint r0 = base + uint(iv * n + iu);
    return heights[r0] > -kInf && heights[r0 + 1u] > -kInf && heights[r0 + uint(n)] > -kInf && heights[r0 + uint(n) + 1u] > -kInf;
}

// traverse() of raycast.cpp: the first point in [tIn, tOut] where the ray from the eye along d meets
// heightfield `water` of cascade k. Texture coordinates u = (x - x0) / s, v = (y - y0) / s. The terrain is
// the solid block of raycast.cpp, with its walls and bottom.
PatchHit traverse(int k, bool water, vec3 d, float tIn, float tOut, inout bool touched) {
    PatchHit res = noPatchHit();
    const float tStart = tIn;
    // Under the block's bottom there is nothing to hit but the bottom, where a rising ray comes up through it:
    // start there; a falling ray ends there (traverse() of raycast.cpp).
    if (d.z != 0.0) {
        const float tFloor = (frame.zFloor - frame.eyeZ) / d.z, margin = 1e-6 * (1.0 + abs(tFloor));
        if (d.z > 0.0) tIn = max(tIn, tFloor - margin);
        else tOut = min(tOut, tFloor + margin);
    } else if (frame.eyeZ < frame.zFloor) {
        return res;
    }
    if (!(tIn < tOut)) return res;
    const float s = cascades[k].texelF;
    const int n = cascades[k].n;
    const uint base = water ? cascades[k].waterOffset : cascades[k].terrainOffset;
    const float u0 = -cascades[k].x0Eye / s, v0 = -cascades[k].y0Eye / s, du = d.x / s, dv = d.y / s;
    const float invDu = du != 0.0 ? 1.0 / du : 0.0, invDv = dv != 0.0 ? 1.0 / dv : 0.0;
    const int top = cascades[k].levels - 1;
    const int patches = n - 1;
    const float eyeZ = frame.eyeZ;
    // A ray above the whole cascade never hits it.
    if (min(eyeZ + d.z * tIn, eyeZ + d.z * tOut) > mipValue(k, water, top, 0u)) return res;
    int level = top;
    float t = tIn;
    // The CPU nudges by 1e-9 of the range in double; in float the nudge must exceed a few ulps of t
    // (1.2e-7 relative) and stay far below a texel (t / s is at most a few thousand).
    const float tiny = 1e-6 * (1.0 + abs(tOut));
    // Heights along the ray carry float rounding of a few ulps of the eye height and of the surface
    // (about 1e-7 of each). Empty space is skipped only beyond that slack, and a first contact from
    // below within it is the ray arriving at the surface, not starting under it: otherwise a rounding in
    // the skip test lets a ray slip under a flat water surface and the solid-surface rule then hides the
    // water for the rest of the ray. (raycast.cpp has no slack: in double the rounding is 1e-9 of this.)
    const float slack = 1e-6 * (abs(eyeZ) + abs(mipValue(k, water, top, 0u))) + 1e-3;
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
        const float nodeMax = mipValue(k, water, level, uint(iv * side + iu));
        const float zLow = min(eyeZ + d.z * t, eyeZ + d.z * tExit);
        if (zLow > nodeMax + slack) {  // empty space: skip the node, and look at a coarser level next
            t = tExit + tiny;
            if (leavesParent) level = min(level + 1, top);
            continue;
        }
        if (level > 0) {
            --level;
            continue;
        }
        // A patch: exact intersection with its bilinear surface.
        const uint r0 = base + uint(iv * n + iu);
        const float h00 = heights[r0], h10 = heights[r0 + 1u], h01 = heights[r0 + uint(n)], h11 = heights[r0 + uint(n) + 1u];
        if (h00 > -kInf && h10 > -kInf && h01 > -kInf && h11 > -kInf) {
            const float a0 = u0 + du * t - float(iu), b0 = v0 + dv * t - float(iv), z0 = eyeZ + d.z * t;
            const float e = h00 - h10 - h01 + h11;
            // f(tau) = z(tau) - bilinear(tau), tau from t: C + B tau + A tau^2.
            const float C = z0 - (h00 + (h10 - h00) * a0 + (h01 - h00) * b0 + e * a0 * b0);
            const float B = d.z - (h10 - h00) * du - (h01 - h00) * dv - e * (a0 * dv + b0 * du);
            const float A = -e * du * dv;
            const float len = tExit - t;
            float tau = -1.0;
            // Under the terrain block's bottom: nothing in this patch but the bottom, if the ray rises through it
            // (the water lies on top of the block).
            const bool under = C <= 0.0 && z0 < frame.zFloor;
            if (under && !water) {
                const float tauF = d.z > 0.0 ? (frame.zFloor - z0) / d.z : kInf;
                if (tauF <= len) {
                    res.hit = res.wall = true;
                    res.t = t + tauF;
                    res.wn = vec3(0.0, 0.0, -1.0);
                    return res;
                }
            }
            if (C <= 0.0 && !under) {
                if (t > tStart) {
                    // Through which edge did the ray come in? The one it crossed last.
                    const float enterU = du > 0.0 ? (float(iu) - u0) * invDu : du < 0.0 ? (float(iu + 1) - u0) * invDu : -kInf;
                    const float enterV = dv > 0.0 ? (float(iv) - v0) * invDv : dv < 0.0 ? (float(iv + 1) - v0) * invDv : -kInf;
                    const bool acrossU = enterU >= enterV;
                    const int fromU = acrossU ? iu - (du > 0.0 ? 1 : -1) : iu, fromV = acrossU ? iv : iv - (dv > 0.0 ? 1 : -1);
                    if (!patchDefined(k, base, fromU, fromV)) {
                        if (water) {  // under the water through its edge: not drawn for this ray (traverse())
                            res.underground = true;
                            return res;
                        }
                        // From a hole or outside: the wall on that edge.
                        res.hit = res.wall = true;
                        res.t = t;
                        res.wn = acrossU ? vec3(du > 0.0 ? -1.0 : 1.0, 0.0, 0.0) : vec3(0.0, dv > 0.0 ? -1.0 : 1.0, 0.0);
                        return res;
                    }
                }
            }
            if (under) {
            } else if (C <= 0.0) {
                if (!touched && C < -slack) {
                    res.underground = true;
                    return res;
                }
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
            if (tau >= 0.0 && tau <= len) {
                const float a = clamp(a0 + du * tau, 0.0, 1.0), b = clamp(b0 + dv * tau, 0.0, 1.0);
                res.hit = true;
                res.t = t + tau;
                res.gx = ((h10 - h00) + e * b) / s;
                res.gy = ((h01 - h00) + e * a) / s;
                return res;
            }
        }
        t = tExit + tiny;
        if (leavesParent) level = min(level + 1, top);
    }
    return res;
}

Hit noHit() { return Hit(false, 0.0, vec3(0.0), 0.0, false, -1, false); }

// hitIn() of raycast.cpp: cascade k's hit between the offsets lo and hi (from the eye, along the
// horizontal view direction), terrain first, then water in front of it.
Hit hitIn(int k, vec3 d, float lo, float hi, inout RayState st, inout bool underground) {
    Hit h = noHit();
    if (cascades[k].n == 0) return h;
    float t0 = frame.nearM, t1 = frame.farM;
    // offsetInterval(): the eye is the origin, so the offset at t = 0 is 0.
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
    if (!(t0 < t1)) return h;
    const PatchHit terrain = traverse(k, false, d, t0, t1, st.touchedTerrain);
    if (terrain.underground) {
        underground = true;
        return h;
    }
    PatchHit water = noPatchHit();
    if (frame.hasWater != 0 && !st.underWater) {
        water = traverse(k, true, d, t0, terrain.hit ? terrain.t : t1, st.touchedWater);
        if (water.underground) {
            st.underWater = true;
            water = noPatchHit();
        }
    }
    const PatchHit best = water.hit ? water : terrain;
    if (!best.hit) return h;
    h.hit = true;
    h.t = best.t;
    h.water = water.hit;
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

// castRay() of raycast.cpp.
Hit castRay(vec3 d) {
    RayState st = RayState(false, false, false);
    bool underground = false;
    for (int k = 0; k < frame.cascades; ++k) {
        const float lo = k == 0 ? -kInf : cascades[k].splitNear;
        Hit h = hitIn(k, d, lo, cascades[k].farWithOverlap, st, underground);
        if (underground) return noHit();
        if (!h.hit) continue;
        // In the overlap with the next cascade: blend both hits by a convex combination, if they are on the same
        // surface (castRay(): the same kind, no wall, no farther apart than a texel of the coarser cascade).
        if (k + 1 < frame.cascades && !h.wall) {
            const float off = (d.x * frame.dirX + d.y * frame.dirY) * h.t;
            const float zoneStart = cascades[k].splitFar, zoneEnd = cascades[k].farWithOverlap;
            if (off > zoneStart && zoneEnd > zoneStart) {
                RayState st2 = st;
                st2.touchedTerrain = true;
                st2.touchedWater = true;
                bool under2 = false;
                const Hit h2 = hitIn(k + 1, d, cascades[k + 1].splitNear, cascades[k + 1].farWithOverlap, st2, under2);
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
    const vec3 d = rayDirection(px, py);
    const Hit h = castRay(d);
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
