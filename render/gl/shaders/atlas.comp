#version 430
// render/gl/shaders/atlas.comp: out of core, the texels a frame copies from the surface pyramid, copied on the GPU from
// the pyramid tiles resident there (the atlas, docs/design.md section 4), after assemble.comp has placed the kept and the
// CPU's texels. A work group per tile this frame copies from (detail::PyramidTiles), an invocation per sample of it: the
// sample is copied to its texel where that texel lies in one of its row's spans to evaluate (as they were before the
// copies were taken out of them): exactly the texels the CPU marked for this tile. The water rule of surface.h as
// detail::copySamples applies it on the CPU, in the same float operations, so the texels are the CPU's bit for bit
// (tests/render_gl_test.cpp).
layout(local_size_x = 256) in;  // kAtlasPlane: a tile of up to 16 x 16 samples

layout(std430, binding = HC_BIND_HEIGHTS) buffer HeightBlock { float heights[]; };
layout(std430, binding = HC_BIND_VISIBLE) readonly buffer VisibleBlock { int spanRows[]; };
layout(std430, binding = HC_BIND_ATLAS_TERRAIN) readonly buffer AtlasTerrainBlock { float atlasTerrain[]; };
layout(std430, binding = HC_BIND_ATLAS_WATER) readonly buffer AtlasWaterBlock { float atlasWater[]; };
// Per tile: x its cascade | log2 of its side << 4, y the texel (i, j) of its first sample as i + 2^15 | (j + 2^15) << 16
// (it may lie left of or below texel 0), z the terrain tile's slot (kAtlasPlane floats), w the water tile's slot
// (2 kAtlasPlane floats: level, wet share) or 0xffffffff where its texels are dry.
layout(std430, binding = HC_BIND_ATLAS_TILES) readonly buffer AtlasTileBlock { uvec4 tiles[]; };

uniform uint uTiles;

void main() {
    const uint e = gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x;
    if (e >= uTiles) return;
    const uvec4 tile = tiles[e];
    const uint k = tile.x & 15u, shift = (tile.x >> 4u) & 15u, at = gl_LocalInvocationID.x;
    if (at >= (1u << (2u * shift))) return;
    const int i = int(tile.y & 0xffffu) - 32768 + int(at & ((1u << shift) - 1u)), j = int(tile.y >> 16u) - 32768 + int(at >> shift);
    const int n = cascades[k].n;
    if (i < 0 || j < 0 || i >= n || j >= n) return;
    const uint row = cascades[k].visibleOffset + 4u * uint(j);
    if (!((i >= spanRows[row] && i <= spanRows[row + 1u]) || (i >= spanRows[row + 2u] && i <= spanRows[row + 3u]))) return;
    const uint t = uint(j) * uint(n) + uint(i);
    const float z = atlasTerrain[tile.z * uint(kAtlasPlane) + at];
    const bool ok = !isnan(z);
    heights[cascades[k].terrainOffset + t] = ok ? z : -kInf;
    if (frame.hasWater == 0) return;
    float depth = 0.0, water = -kInf;
    if (tile.w != 0xffffffffu) {
        const uint w = tile.w * uint(2 * kAtlasPlane) + at;
        const float level = atlasWater[w], share = atlasWater[w + uint(kAtlasPlane)], d = level - z;
        const bool wet = ok && !isnan(level) && wetShare(share);  // water_rule.h
        if (wet && holdsDepth(d)) depth = d;
        if (wet && drawsWater(d, frame.minDepthM)) water = level;
    }
    heights[cascades[k].waterOffset + t] = water;
    heights[cascades[k].depthOffset + t] = depth;
}
