#version 430
// render/gl/shaders/beams.comp: the beams of raycast.comp's tiles (raycast.cpp Beam), a pass before the ray casting.
layout(local_size_x = 64) in;

layout(std430, binding = HC_BIND_HEIGHTS) readonly buffer HeightBlock { float heights[]; };
// Per tile (row-major over the image, frame.beamTile^2 pixels each) and cascade: (start depth, 1 where passed).
// After them, the outer pass's blocks of 4 x 4 tiles, likewise.
layout(std430, binding = HC_BIND_BEAMS) buffer BeamBlock { vec2 beams[]; };

float mipValue(int k, bool water, int level, uint index) {
    return heights[(water ? cascades[k].waterMip[level] : cascades[k].terrainMip[level]) + index];
}

// Beams (raycast.cpp Beam): each tile of frame.beamTile^2 pixels marches its rays' beam over each cascade's max
// mipmaps (terrain and water together) before any ray walks: a step of depths is passed when the beam's
// lowest point over it lies above the largest maximum of the (at most 2 x 2) nodes under the box holding its footprint,
// by more than the walk's slack; steps double while they pass and halve when they fail, down to about the beam's
// width. Where the march stops, every ray of the tile starts its walks (traverse()'s tFrom); a cascade whose slab the
// march passed whole is not walked at all. Depths: a ray of raw direction f + sx r + sy u is at depth tau at
// t = tau |f + sx r + sy u|. An invocation marches one tile over one cascade; raycast.comp reads the results.

struct Beam {
    vec3 lo, hi;           // the corners' raw directions' componentwise extremes
    float maxLen;          // the longest corner direction
    float minDot, maxDot;  // the corners' rates along the fit's view direction
    float width;           // the tile's extent on the image plane at unit distance
    float centreLen;       // the length of its centre's direction
};

Beam beamOf(uint px0, uint py0, uint px1, uint py1) {
    const float sx0 = sxOf(float(px0)), sx1 = sxOf(float(px1)), sy0 = syOf(float(py0)), sy1 = syOf(float(py1));
    const vec2 dir = vec2(frame.dirX, frame.dirY);
    Beam b;
    b.lo = b.hi = rawDirection(sx0, sy0);
    b.maxLen = 0.0;
    b.minDot = b.maxDot = dot(b.lo.xy, dir);
    for (int i = 0; i < 4; ++i) {  // every quantity below is linear in (sx, sy): its extremes are at corners
        const vec3 c = rawDirection((i & 1) == 0 ? sx0 : sx1, (i & 2) == 0 ? sy0 : sy1);
        b.lo = min(b.lo, c), b.hi = max(b.hi, c);
        b.maxLen = max(b.maxLen, length(c));
        b.minDot = min(b.minDot, dot(c.xy, dir)), b.maxDot = max(b.maxDot, dot(c.xy, dir));
    }
    b.width = max(abs(sx1 - sx0), abs(sy1 - sy0));
    b.centreLen = length(rawDirection(0.5 * (sx0 + sx1), 0.5 * (sy0 + sy1)));
    return b;
}

float beamMax(int k, int level, uint i) {
    const float m = mipValue(k, false, level, i);
    return frame.hasWater != 0 ? max(m, mipValue(k, true, level, i)) : m;
}

// The largest maximum of the patches under the box [ua, ub] x [va, vb] (texture coordinates) of cascade k: -inf off the
// texture. The pad covers float rounding of the coordinates (well under a hundredth of a texel at the few thousand
// texels a side a cascade has).
float boxMax(int k, float ua, float ub, float va, float vb) {
    const float pad = 0.05;
    ua -= pad, va -= pad, ub += pad, vb += pad;
    const int patches = cascades[k].n - 1, top = cascades[k].levels - 1;
    if (!(ub >= 0.0 && vb >= 0.0 && ua < float(patches) && va < float(patches))) return -kInf;
    const int i0 = ua > 0.0 ? int(ua) : 0, j0 = va > 0.0 ? int(va) : 0;
    const int i1 = ub < float(patches - 1) ? int(ub) : patches - 1, j1 = vb < float(patches - 1) ? int(vb) : patches - 1;
    int level = 0;
    while (level < top && ((i1 >> level) - (i0 >> level) > 1 || (j1 >> level) - (j0 >> level) > 1)) ++level;
    const int side = cascades[k].mipSide[level];
    float m = -kInf;
    for (int j = j0 >> level; j <= j1 >> level; ++j)
        for (int i = i0 >> level; i <= i1 >> level; ++i) m = max(m, beamMax(k, level, uint(j * side + i)));
    return m;
}

// The depth from which no ray of beam b can reach a node of cascade k before (0: none found); passed: none reaches any.
// outer: the start depth of a beam holding this one (its rays meet no node of the cascade before it), or 0.
float beamMarch(int k, Beam b, float outer, out bool passed) {
    passed = false;
    if (cascades[k].n < 2 || cascades[k].levels < 1) return 0.0;
    // The depths at which the beam's rays walk this cascade: t >= near, offsets within the cascade's slab.
    float tau = frame.nearM / b.maxLen;
    if (k > 0 && cascades[k].splitNear > 0.0 && b.maxDot > 0.0) tau = max(tau, cascades[k].splitNear / b.maxDot);
    float tauEnd = frame.farM;
    if (cascades[k].farWithOverlap > 0.0 && b.minDot > 0.0) tauEnd = min(tauEnd, cascades[k].farWithOverlap / b.minDot);
    tau *= 1.0 - 1e-5;
    if (!(tau < tauEnd)) return 0.0;
    tau = max(tau, outer);
    if (!(tau < tauEnd)) {
        passed = true;
        return tauEnd;
    }
    const float s = cascades[k].texelF, x0 = cascades[k].x0Eye, y0 = cascades[k].y0Eye, eyeZ = frame.eyeZ;
    const int top = cascades[k].levels - 1;
    // traverse()'s slack (the larger of terrain's and water's), twice over, and float rounding of the heights along rays.
    const float slack = 2.0 * (1e-6 * (abs(eyeZ) + abs(beamMax(k, top, 0u))) + 1e-3);
    float step = max(tau * b.width, 0.5 * s) / b.centreLen;
    for (int guard = 0; guard < 4096 && tau < tauEnd; ++guard) {
        const float tb = min(tau + step, tauEnd);
        const float zLow = eyeZ + min(tau * b.lo.z, tb * b.lo.z);
        const float ua = (min(tau * b.lo.x, tb * b.lo.x) - x0) / s, ub = (max(tau * b.hi.x, tb * b.hi.x) - x0) / s;
        const float va = (min(tau * b.lo.y, tb * b.lo.y) - y0) / s, vb = (max(tau * b.hi.y, tb * b.hi.y) - y0) / s;
        const float m = boxMax(k, ua, ub, va, vb);  // -inf: nothing under the box
        if (m == -kInf || zLow > m + slack + 1e-5 * (abs(zLow) + abs(m))) {
            tau = tb;
            step *= 2.0;
            continue;
        }
        const float smallest = max(tau * b.width, 0.5 * s) / b.centreLen;
        if (step <= smallest) return tau;
        step = max(0.5 * step, smallest);
    }
    passed = !(tau < tauEnd);
    return min(tau, tauEnd);
}

// Two passes (uOuter): first the beams of blocks of 4 x 4 tiles, after the tiles' slots; then each tile's, starting where
// its block's stopped (as raycast.cpp's Beam with its outer beam): most of a tile's march is its block's.
uniform int uOuter;

void main() {
    const uint T = uint(frame.beamTile), across = (uint(frame.width) + T - 1u) / T, down = (uint(frame.height) + T - 1u) / T;
    const uint tiles = across * down, blocksAcross = (across + 3u) / 4u, blocks = blocksAcross * ((down + 3u) / 4u);
    const uint slot = gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x + gl_GlobalInvocationID.x;
    const uint at = slot / uint(kMaxCascades);  // a tile, or a block in the outer pass
    const int k = int(slot % uint(kMaxCascades));
    if (T < 2u || at >= (uOuter != 0 ? blocks : tiles)) return;
    vec2 result = vec2(0.0);
    if (k < frame.cascades) {
        const uint size = uOuter != 0 ? 4u * T : T, row = uOuter != 0 ? blocksAcross : across;
        const uint px0 = (at % row) * size, py0 = (at / row) * size;
        const Beam b = beamOf(px0, py0, min(px0 + size - 1u, uint(frame.width) - 1u), min(py0 + size - 1u, uint(frame.height) - 1u));
        float outer = 0.0;
        if (uOuter == 0) outer = beams[(tiles + ((at / across) / 4u) * blocksAcross + (at % across) / 4u) * uint(kMaxCascades) + uint(k)].x;
        bool passed;
        const float depth = beamMarch(k, b, outer, passed);
        result = vec2(depth, passed ? 1.0 : 0.0);
    }
    beams[(uOuter != 0 ? tiles * uint(kMaxCascades) : 0u) + slot] = result;
}
