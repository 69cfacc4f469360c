#version 430
// render/gl/shaders/interpolate.comp: out of core, the texels of a cascade finer than every level of the surface
// pyramid, interpolated on the GPU from level 0's tiles resident there (the atlas, docs/design.md section 4) as
// PyramidInterpolator interpolates them on the CPU (render/src/approximate_interpolate.cpp): the bicubic Catmull-Rom blend of the
// 4 x 4 level-0 samples around each texel, in double, a column of samples blended vertically, then the columns, each
// sum in the CPU's order, skipping zero weights as it does. Runs after assemble.comp (and atlas.comp), a work group per
// block (detail::PyramidTiles::Block: one level-0 tile's footprint in texels, whose stencils lie in the 3 x 3 tiles
// around it, all numbers and all dry or all wet, so that no texel is refused): the texels of the block that lie in
// their row's spans to evaluate, as they were before the pyramid's texels were taken out (exactly those the CPU left
// to it). The CPU build fuses each multiply-add where its compiler may (GCC does with FMA): fma() here does so always,
// so a texel matches the CPU's to its last bit where the CPU fused, within a float's rounding of the sum otherwise
// (tests/render_gl_test.cpp names the tolerance).
layout(local_size_x = 256) in;

layout(std430, binding = HC_BIND_HEIGHTS) buffer HeightBlock { float heights[]; };
layout(std430, binding = HC_BIND_VISIBLE) readonly buffer VisibleBlock { int spanRows[]; };
layout(std430, binding = HC_BIND_ATLAS_TERRAIN) readonly buffer AtlasTerrainBlock { float atlasTerrain[]; };
layout(std430, binding = HC_BIND_ATLAS_WATER) readonly buffer AtlasWaterBlock { float atlasWater[]; };
// Per block kAtlasBlockUints: [0] its cascade | levels up to level 0 << 4 | log2 of level 0's tile side << 8; [1] the
// texel (i, j) of its first sample as i + 2^15 | (j + 2^15) << 16 (it may lie left of or below texel 0); [2 + q] the
// slot of level 0's tile q around it (q = 3 (dy + 1) + dx + 1, dx and dy in -1..1), kAtlasPlane floats; [11 + q] its
// water tile's slot (2 kAtlasPlane floats: level, wet share), 0xffffffff in every one where the block is dry.
layout(std430, binding = HC_BIND_ATLAS_BLOCKS) readonly buffer AtlasBlockBlock { uint blocks[]; };

uniform uint uBlocks;

// Catmull-Rom weights at fraction f of the middle interval (catmullRom() in approximate_interpolate.cpp): f has at most
// PyramidTiles::kMaxBlockUp bits, so every product and sum here is exact, in any order.
dvec4 catmullRom(double f) {
    const double f2 = f * f, f3 = f2 * f;
    return dvec4(0.5 * (-f3 + 2.0 * f2 - f), 0.5 * (3.0 * f3 - 5.0 * f2 + 2.0), 0.5 * (-3.0 * f3 + 4.0 * f2 + f), 0.5 * (f3 - f2));
}

void main() {
    const uint b = gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x;
    if (b >= uBlocks) return;
    const uint base = b * uint(kAtlasBlockUints), head = blocks[base];
    const uint k = head & 15u, up = (head >> 4u) & 15u, shift = (head >> 8u) & 15u;
    const uint side = 1u << shift, blockShift = shift + up, mask = (1u << up) - 1u;
    const int bi = int(blocks[base + 1u] & 0xffffu) - 32768, bj = int(blocks[base + 1u] >> 16u) - 32768;
    const int n = cascades[k].n;
    const bool wet = blocks[base + 11u] != 0xffffffffu;
    const double scale = 1.0 / double(1u << up);
    for (uint at = gl_LocalInvocationID.x; at < (1u << (2u * blockShift)); at += gl_WorkGroupSize.x) {
        const uint u = at & ((1u << blockShift) - 1u), v = at >> blockShift;
        const int i = bi + int(u), j = bj + int(v);
        if (i < 0 || j < 0 || i >= n || j >= n) continue;
        const uint row = cascades[k].visibleOffset + 4u * uint(j);
        if (!((i >= spanRows[row] && i <= spanRows[row + 1u]) || (i >= spanRows[row + 2u] && i <= spanRows[row + 3u]))) continue;
        const dvec4 wx = catmullRom(double(u & mask) * scale), wy = catmullRom(double(v & mask) * scale);
        // Sample (x, y) of the block's tile, x and y in -1 .. side + 1: tile (x + side) >> shift of the 3 across.
        const int x0 = int(u >> up) - 1 + int(side), y0 = int(v >> up) - 1 + int(side);
        double z = 0.0, level = 0.0, share = 0.0;
        for (int c = 0; c < 4; ++c) {
            if (wx[c] == 0.0) continue;
            const uint x = uint(x0 + c), tx = x >> shift, sx = x & (side - 1u);
            double cz = 0.0, cl = 0.0, cs = 0.0;
            for (int r = 0; r < 4; ++r) {
                if (wy[r] == 0.0) continue;
                const uint y = uint(y0 + r), q = 3u * (y >> shift) + tx, s = (y & (side - 1u)) * side + sx;
                cz = fma(wy[r], double(atlasTerrain[blocks[base + 2u + q] * uint(kAtlasPlane) + s]), cz);
                if (wet) {
                    const uint w = blocks[base + 11u + q] * uint(2 * kAtlasPlane) + s;
                    cl = fma(wy[r], double(atlasWater[w]), cl);
                    cs = fma(wy[r], double(atlasWater[w + uint(kAtlasPlane)]), cs);
                }
            }
            z = fma(wx[c], cz, z), level = fma(wx[c], cl, level), share = fma(wx[c], cs, share);
        }
        const uint t = uint(j) * uint(n) + uint(i);
        const float zf = float(z);
        heights[cascades[k].terrainOffset + t] = zf;
        if (frame.hasWater == 0) continue;
        float depth = 0.0, water = -kInf;
        if (wet && wetShare(float(share))) {  // water_rule.h
            const float lf = float(level), d = lf - zf;
            if (holdsDepth(d)) depth = d;
            if (drawsWater(d, frame.minDepthM)) water = lf;
        }
        heights[cascades[k].waterOffset + t] = water;
        heights[cascades[k].depthOffset + t] = depth;
    }
}
