#version 430
// render/gl/shaders/atlas.comp: out of core, the texels a frame copies from the surface pyramid, copied on the GPU from
// the pyramid tiles resident there (the atlas, DESIGN.md section 10), after assemble.comp has placed the kept and the
// CPU's texels. A run (detail::PyramidRun) is up to 16 texels of one cascade row from one tile: an invocation per
// texel, 16 a run. The water rule of surface.h as detail::copySamples applies it on the CPU, in the same float
// operations, so the texels are the CPU's bit for bit (tests/render_gl_test.cpp).
layout(local_size_x = 64) in;

layout(std430, binding = HC_BIND_HEIGHTS) buffer HeightBlock { float heights[]; };
layout(std430, binding = HC_BIND_ATLAS_TERRAIN) readonly buffer AtlasTerrainBlock { float atlasTerrain[]; };
layout(std430, binding = HC_BIND_ATLAS_WATER) readonly buffer AtlasWaterBlock { float atlasWater[]; };
// Per run: x the first texel (j n + i) in its cascade, y its cascade | count << 8 | its first sample in the tile << 16,
// z the terrain tile's slot (kAtlasPlane floats), w the water tile's slot (2 kAtlasPlane floats: level, wet share) or
// 0xffffffff where the texels are dry.
layout(std430, binding = HC_BIND_ATLAS_RUNS) readonly buffer AtlasRunBlock { uvec4 runs[]; };

uniform uint uRuns;
uniform float uMinDepth;  // RenderOptions::waterMinDepthM
uniform float uWetShare;  // influence::kWetShareMin

void main() {
    const uint g = gl_GlobalInvocationID.y * gl_NumWorkGroups.x * 64u + gl_GlobalInvocationID.x;
    const uint r = g >> 4u, lane = g & 15u;
    if (r >= uRuns) return;
    const uvec4 run = runs[r];
    if (lane >= ((run.y >> 8u) & 0xffu)) return;
    const uint k = run.y & 0xffu, at = (run.y >> 16u) + lane, t = run.x + lane;
    const float z = atlasTerrain[run.z * uint(kAtlasPlane) + at];
    const bool ok = !isnan(z);
    heights[cascades[k].terrainOffset + t] = ok ? z : -kInf;
    if (frame.hasWater == 0) return;
    float depth = 0.0, water = -kInf;
    if (run.w != 0xffffffffu) {
        const uint w = run.w * uint(2 * kAtlasPlane) + at;
        const float level = atlasWater[w], share = atlasWater[w + uint(kAtlasPlane)], d = level - z;
        const bool wet = ok && !isnan(level) && share >= uWetShare;
        if (wet && d > 0.0) depth = d;
        if (wet && d > uMinDepth) water = level;
    }
    heights[cascades[k].waterOffset + t] = water;
    heights[cascades[k].depthOffset + t] = depth;
}
