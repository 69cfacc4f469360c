#version 430
// render/gl/shaders/assemble.comp: one cascade's textures from the last frame's, kept on the GPU, and (out of core) the
// texels the CPU evaluated this frame, uploaded packed (detail::approximateOnCpu); in memory approximate.comp sums the
// evaluated spans' texels after this pass (detail::planCascades), which leaves them to it. Row by row as copyReusedTexels in
// render/src/approximate.cpp places them: texel i of row j is the last frame's texel i + di of row j + dj where the row
// keeps it (keptFirst..keptLast), the next packed texel where the row evaluated it (spans a and b), and "no surface"
// (-inf, depth 0) elsewhere. So a moving camera uploads only the texels it newly sees, not the cascades. Every texel
// of the cascade is written here, "no surface" too (in memory, where approximate.comp sums the spans' texels after
// this pass, those included), so the textures need no clearing first.
// A work group covers kRun x 64 texels of a row, an invocation kRun of them 64 apart: the row's spans are read once
// per invocation (llvmpipe runs a work group on one CPU thread and pays its per-invocation cost a sixteenth as often
// as with a texel an invocation), and at each step the group's 64 invocations touch 64 neighbouring texels (a GPU's
// loads and stores coalesce; with the kRun texels of an invocation side by side they were 64 bytes apart).
#define kRun 16
layout(local_size_x = 64, local_size_y = 1) in;

layout(std430, binding = HC_BIND_HEIGHTS) writeonly buffer HeightBlock { float heights[]; };
layout(std430, binding = HC_BIND_LAST_HEIGHTS) readonly buffer LastHeightBlock { float lastHeights[]; };
layout(std430, binding = HC_BIND_FILL_ROWS) readonly buffer FillRowBlock { int fillRows[]; };
layout(std430, binding = HC_BIND_FILL_TEXELS) readonly buffer FillTexelBlock { float fillTexels[]; };

uniform int uCascade;
uniform int uRowBase;        // the cascade's first row in fillRows [rows]
uniform uint uPlane;         // packed texels per channel (the water's start in fillTexels, the depth's at twice that)
uniform int uKept;           // 1: the rows keep texels of the last frame's cascade at uLast*
uniform int uPacked;         // 1: the spans' texels are in fillTexels (out of core); 0: approximate.comp writes them
uniform uint uLastTerrain;   // that cascade's terrain, water and depth offsets in lastHeights [floats]
uniform uint uLastWater;
uniform uint uLastDepth;
uniform int uDi;             // this frame's texel (i, j) is that cascade's (i + uDi, j + uDj)
uniform int uDj;
uniform int uLastN;          // that cascade's side [texels]: its rows' length (a far cascade's side changes by 64 texels)

void main() {
    const int i0 = int(gl_WorkGroupID.x) * (kRun * 64) + int(gl_LocalInvocationID.x), j = int(gl_GlobalInvocationID.y);
    const int n = cascades[uCascade].n;
    if (i0 >= n || j >= n) return;
    const int r = (uRowBase + j) * kFillRowInts;
    const int keptFirst = uKept != 0 ? fillRows[r] : 0, keptLast = uKept != 0 ? fillRows[r + 1] : -1;
    const int a0 = fillRows[r + 2], a1 = fillRows[r + 3], b0 = fillRows[r + 4], b1 = fillRows[r + 5];
    const int packedA = fillRows[r + 6], packedB = fillRows[r + 7];
    const uint row = uint(j) * uint(n);
    const uint lastRow = uint(j + uDj) * uint(uLastN);
    const bool water = frame.hasWater != 0;
    for (int i = i0; i < min(i0 + kRun * 64, n); i += 64) {
        float z = -kInf, w = -kInf, depth = 0.0;
        if (i >= keptFirst && i <= keptLast) {
            const uint at = lastRow + uint(i + uDi);
            z = lastHeights[uLastTerrain + at];
            if (water) {
                w = lastHeights[uLastWater + at];
                depth = lastHeights[uLastDepth + at];
            }
        } else if (uPacked != 0) {
            int p = -1;
            if (i >= a0 && i <= a1) p = packedA + (i - a0);
            else if (i >= b0 && i <= b1) p = packedB + (i - b0);
            if (p >= 0) {
                z = fillTexels[p];
                if (water) {
                    w = fillTexels[uPlane + uint(p)];
                    depth = fillTexels[2u * uPlane + uint(p)];
                }
            }
        }
        const uint t = row + uint(i);
        heights[cascades[uCascade].terrainOffset + t] = z;
        if (water) {
            heights[cascades[uCascade].waterOffset + t] = w;
            heights[cascades[uCascade].depthOffset + t] = depth;
        }
    }
}
