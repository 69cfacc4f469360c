#version 430
// render/gl/shaders/approximate.comp: the approximation pass of one cascade (docs/design.md section 5 step
// 2), mirroring detail::approximate() in render/src/approximate*.cpp. One invocation per texel: a
// visible texel's cell is found by binary search of the sorted Morton keys (Grid::locate), and the
// Gaussian RBF sum over that cell's influence list is taken relative to the cell's centre and value,
// as the CPU does, so float keeps its precision however far the texel lies from the grid origin.
// Each row's spans to evaluate (HC_BIND_VISIBLE: the visible span less the texels kept from the last frame), a dispatch
// per span (uSpan). Narrow spans (a moving camera's: a few texels a row) get an invocation per texel of the span (x:
// its place in the span, y: the row), not n a row; wide ones (a fresh frame's) an invocation per texel of the row, so
// that a work group's 8 x 8 texels lie together (the same cells and lists: on llvmpipe a fresh frame took longer
// with the texels of a group placed from each row's own start). Texels in a hole or outside the domain get -inf
// ("no surface"); assemble.comp has written the others before (the kept texels, and "no surface" everywhere else).
layout(local_size_x = HC_GROUP_2D, local_size_y = HC_GROUP_2D) in;

layout(std430, binding = HC_BIND_INDICES) readonly buffer IndexBlock0 { uint indices0[]; };
layout(std430, binding = HC_BIND_INDICES_1) readonly buffer IndexBlock1 { uint indices1[]; };
layout(std430, binding = HC_BIND_INDICES_2) readonly buffer IndexBlock2 { uint indices2[]; };
layout(std430, binding = HC_BIND_INDICES_3) readonly buffer IndexBlock3 { uint indices3[]; };
layout(std430, binding = HC_BIND_VISIBLE) readonly buffer VisibleBlock { int visibleRows[]; };
layout(std430, binding = HC_BIND_HEIGHTS) buffer HeightBlock { float heights[]; };
layout(std430, binding = HC_BIND_COUNTERS) buffer CounterBlock { uint counters[]; };

uniform int uCascade;
uniform int uSpan;      // 0: each row's first span to evaluate (RowFill a0..a1), 1: its second (b0..b1)
uniform int uRelative;  // 1: x counts from the span's start, 0: from the row's

// Entry e of the influence lists (InfluenceLists::indices()[e]), from the chunk that holds it.
// Neighbouring texels share a list, so the branch hardly ever diverges.
uint listEntry(uint e) {
    const uint chunk = e >> frame.indexChunkShift, at = e & ((1u << frame.indexChunkShift) - 1u);
    if (chunk == 0u) return indices0[at];
    if (chunk == 1u) return indices1[at];
    if (chunk == 2u) return indices2[at];
    return indices3[at];
}

// exp(x) for x <= 0, the same branch-free polynomial as expNeg() in approximate_sum.cpp (so both
// backends round alike; the driver's exp() is allowed 3 ulp and differs between GPUs).
float expNeg(float x) {
    x = max(x, -87.0);
    const float y = x * 1.44269504088896341;
    const float n = floor(y + 0.5);
    const float f = y - n;
    const float p = 1.0 + f * (0.693147181 + f * (0.240226507 + f * (0.0555041087 + f * (0.00961812911 + f * (0.00133335581 + f * 0.000154035304)))));
    return p * intBitsToFloat((int(n) + 127) << 23);
}

void main() {
    // Fields are read from the buffer one by one (no local copy of the GpuCascade and its arrays).
    const uint j = gl_GlobalInvocationID.y, n = uint(cascades[uCascade].n);
    if (j >= n) return;
    const uint row = cascades[uCascade].visibleOffset + 4u * j + 2u * uint(uSpan);
    const int first = visibleRows[row], last = visibleRows[row + 1u];
    const int at = int(gl_GlobalInvocationID.x) + (uRelative != 0 ? first : 0);
    if (at < first || at > last) return;  // outside the span (an empty one ends below its start)
    const uint i = uint(at);
    const uint t = j * n + i;
    const float noSurface = -kInf;
    float z = noSurface, water = noSurface, depth = 0.0;
    // The texel centre in double, exactly as c.x0 + i * s in approximate_sum.cpp.
    const double x = cascades[uCascade].x0 + double(i) * cascades[uCascade].texelM, y = cascades[uCascade].y0 + double(j) * cascades[uCascade].texelM;
    const int k = locateCell(x, y);
    if (k >= 0) {
        const GpuCell ck = cells[k];
        const uint b = ck.listBegin, e = cells[k + 1].listBegin;
        // Centres in half finest units: integers, so the offsets between cells are exact.
        const int kcx2 = int(2u * ck.ix + (1u << ck.level)), kcy2 = int(2u * ck.iy + (1u << ck.level));
        const double halfFinest = 0.5 * frame.finestM;
        const float h = float(halfFinest);
        const float fx = float(x - double(kcx2) * halfFinest), fy = float(y - double(kcy2) * halfFinest);
        // The water level field (docs/design.md section 6, influence/surface.h) from the wet cells only (depth > 0),
        // relative to a wet cell's level: k's own if k is wet, else the first wet cell of its list (levelBase()).
        bool anyWet = frame.hasWater != 0 && ck.depth > 0.0;
        float levelBase = ck.z + ck.depth;
        for (uint idx = b; idx < e && frame.hasWater != 0 && !anyWet; ++idx) {
            const GpuCell ci = cells[listEntry(idx)];
            if (ci.depth > 0.0) {
                anyWet = true;
                levelBase = ci.z + ci.depth;
            }
        }
        float num = 0.0, den = 0.0, numL = 0.0, denW = 0.0;
        for (uint idx = b; idx < e; ++idx) {
            const GpuCell ci = cells[listEntry(idx)];
            const float ex = float(int(2u * ci.ix + (1u << ci.level)) - kcx2) * h;
            const float ey = float(int(2u * ci.iy + (1u << ci.level)) - kcy2) * h;
            const float dx = fx - ex, dy = fy - ey;
            const float d2 = dx * dx + dy * dy;
            const float w = d2 < ci.r2 ? max(expNeg(-d2 * ci.a) - frame.tail, 0.0) : 0.0;
            num += w * (ci.z - ck.z);
            den += w;
            if (ci.depth > 0.0) {
                numL += w * ((ci.z + ci.depth) - levelBase);
                denW += w;
            }
        }
        // den >= the cell's own weight at its farthest point (kernel.h): never zero here.
        const double zd = double(ck.z) + double(num / den);
        z = float(zd);
        // The water rule (water_rule.h): the depth texture holds level - terrain, the water heightfield the level.
        if (anyWet && wetWeights(denW, den)) {
            const double level = double(levelBase) + double(numL / denW);
            const float d = float(level - zd);
            if (holdsDepth(d)) depth = d;
            if (drawsWater(d, frame.minDepthM)) water = float(level);
        }
        atomicAdd(counters[uint(uCascade) * uint(kCounterSlots) + (gl_WorkGroupID.x + 7u * gl_WorkGroupID.y) % uint(kCounterSlots)], e - b);
    }
    heights[cascades[uCascade].terrainOffset + t] = z;
    if (frame.hasWater != 0) {
        heights[cascades[uCascade].waterOffset + t] = water;
        heights[cascades[uCascade].depthOffset + t] = depth;
    }
}
