#version 430
// render/gl/shaders/assemble.comp: one cascade's textures from the last frame's, kept on the GPU, and (out of core) the
// texels the CPU evaluated this frame, uploaded packed (detail::approximateOnCpu); in memory approximate.comp sums the
// evaluated spans' texels after this pass (detail::planCascades), which leaves them to it. Row by row as copyReusedTexels in
// render/src/approximate.cpp places them: texel i of row j is the last frame's texel i + di of row j + dj where the row
// keeps it (keptFirst..keptLast), the next packed texel where the row evaluated it (spans a and b), and "no surface"
// (-inf, depth 0) elsewhere. So a moving camera uploads only the texels it newly sees, not the cascades. The cascade's
// textures were cleared to "no surface" before (glClearBufferSubData): a run of texels outside the row's spans writes
// nothing.
// An invocation per run of kRun texels of a row: the row's spans are read once, and llvmpipe (one CPU thread a
// work group) pays its per-invocation cost a sixteenth as often: 43 -> 22-24 ms on Petzenkirchen's cascades (BENCHMARKS.md).
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

void main() {
    const int i0 = int(gl_GlobalInvocationID.x) * kRun, j = int(gl_GlobalInvocationID.y);
    const int n = cascades[uCascade].n;
    if (i0 >= n || j >= n) return;
    const int r = (uRowBase + j) * kFillRowInts;
    const int keptFirst = uKept != 0 ? fillRows[r] : 0, keptLast = uKept != 0 ? fillRows[r + 1] : -1;
    const int a0 = fillRows[r + 2], a1 = fillRows[r + 3], b0 = fillRows[r + 4], b1 = fillRows[r + 5];
    const int packedA = fillRows[r + 6], packedB = fillRows[r + 7];
    // The row's texels with a value: from the first span's start to the last one's end (empty spans end below their start).
    int first = n, last = -1;
    if (keptFirst <= keptLast) first = min(first, keptFirst), last = max(last, keptLast);
    if (uPacked != 0 && a0 <= a1) first = min(first, a0), last = max(last, a1);
    if (uPacked != 0 && b0 <= b1) first = min(first, b0), last = max(last, b1);
    if (i0 + kRun <= first || i0 > last) return;
    const uint row = uint(j) * uint(n);
    const uint lastRow = uint(j + uDj) * uint(n);
    const bool water = frame.hasWater != 0;
    for (int i = i0; i < min(i0 + kRun, n); ++i) {
        float z = -kInf, w = -kInf, depth = 0.0;
        if (i >= keptFirst && i <= keptLast) {
            const uint at = lastRow + uint(i + uDi);
            z = lastHeights[uLastTerrain + at];
            if (water) {
                w = lastHeights[uLastWater + at];
                depth = lastHeights[uLastDepth + at];
            }
        } else {
            if (uPacked == 0) continue;
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
