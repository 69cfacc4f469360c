#version 430
// render/gl/shaders/mipmap.comp: one level of a cascade's max mipmap (Tevs et al. 2008), mirroring
// Heightfield::buildMip() in render/src/approximate.cpp. Level 0 holds each patch's maximum (the 2 x 2
// texels at its corners: (n-1)^2 patches); level L + 1 the maximum of up to 2 x 2 nodes of level L,
// ceil(side / 2) per side. -inf (no surface) is the identity of max, as on the CPU. Without a surface pyramid, level 0
// also takes the largest of its patches' error estimates into the cascade's counter.
layout(local_size_x = HC_GROUP_2D, local_size_y = HC_GROUP_2D) in;

layout(std430, binding = HC_BIND_HEIGHTS) buffer HeightBlock { float heights[]; };
layout(std430, binding = HC_BIND_COUNTERS) buffer CounterBlock { uint counters[]; };

uniform int uCascade;
uniform int uWater;     // 0: terrain, 1: water surface
uniform int uLevel;     // the level written
uniform int uEstimate;  // 1 (no surface pyramid): at level 0, the texels' error estimate too (patchErrorEstimateM)

shared uint groupEstimate;  // the work group's largest estimate, as float bits

void main() {
    // Fields are read from the buffer one by one: copying the whole GpuCascade (with its arrays) into a
    // local costs llvmpipe a scratch copy per invocation.
    const uint i = gl_GlobalInvocationID.x, j = gl_GlobalInvocationID.y;
    const uint side = uint(cascades[uCascade].mipSide[uLevel]);
    float estimate = 0.0;
    if (i < side && j < side) {
        const uint dst = (uWater != 0 ? cascades[uCascade].waterMip[uLevel] : cascades[uCascade].terrainMip[uLevel]) + j * side + i;
        float m;
        if (uLevel == 0) {
            const uint n = uint(cascades[uCascade].n);
            const uint r0 = (uWater != 0 ? cascades[uCascade].waterOffset : cascades[uCascade].terrainOffset) + j * n + i;
            m = max(max(heights[r0], heights[r0 + 1u]), max(heights[r0 + n], heights[r0 + n + 1u]));
            if (uEstimate != 0 && i + 1u < side && j + 1u < side)  // as Heightfield::errorEstimateM: texels i + 2, j + 2
                estimate = patchErrorEstimateM(heights[r0], heights[r0 + 1u], heights[r0 + 2u], heights[r0 + n],
                                               heights[r0 + 2u * n]);
        } else {
            const uint lowSide = uint(cascades[uCascade].mipSide[uLevel - 1]);
            const uint low = uWater != 0 ? cascades[uCascade].waterMip[uLevel - 1] : cascades[uCascade].terrainMip[uLevel - 1];
            m = -kInf;
            for (uint b = 0u; b < 2u; ++b)
                for (uint a = 0u; a < 2u; ++a) {
                    const uint li = 2u * i + a, lj = 2u * j + b;
                    if (li < lowSide && lj < lowSide) m = max(m, heights[low + lj * lowSide + li]);
                }
        }
        heights[dst] = m;
    }
    if (uLevel == 0 && uEstimate != 0) {  // uniform: the barriers are reached by the whole group
        if (gl_LocalInvocationIndex == 0u) groupEstimate = 0u;
        memoryBarrierShared();
        barrier();
        atomicMax(groupEstimate, floatBitsToUint(estimate));  // >= 0: the bits order as the floats
        memoryBarrierShared();
        barrier();
        if (gl_LocalInvocationIndex == 0u && groupEstimate > 0u)
            atomicMax(counters[uint(kEstimateCounter + uCascade)], groupEstimate);
    }
}
