#version 430
// render/gl/shaders/shore.comp: the water at a cascade's shores (water_rule.h: standsAbove, shoreLevel), mirroring
// CascadeTextures::extendWaterToShores() in render/src/approximate.cpp, after the approximation and before the max
// mipmaps. One invocation a texel: where its water does not stand above its terrain, the highest level of its 8
// neighbours' that do, kept where its terrain rises above it. In place: a texel written here stands above its terrain
// neither before nor after, so whichever of its two values a neighbour reads, it leaves it out.
layout(local_size_x = HC_GROUP_2D, local_size_y = HC_GROUP_2D) in;

layout(std430, binding = HC_BIND_HEIGHTS) buffer HeightBlock { float heights[]; };

uniform int uCascade;

void main() {
    const int i = int(gl_GlobalInvocationID.x), j = int(gl_GlobalInvocationID.y);
    const int n = cascades[uCascade].n;
    if (i >= n || j >= n) return;
    const uint terrain = uint(cascades[uCascade].terrainOffset), water = uint(cascades[uCascade].waterOffset);
    const uint at = uint(j * n + i);
    if (standsAbove(heights[water + at], heights[terrain + at])) return;
    float around = -kInf;
    for (int y = max(j - 1, 0); y <= min(j + 1, n - 1); ++y)
        for (int x = max(i - 1, 0); x <= min(i + 1, n - 1); ++x) {
            const uint q = uint(y * n + x);
            const float w = heights[water + q];
            if (standsAbove(w, heights[terrain + q])) around = max(around, w);
        }
    heights[water + at] = shoreLevel(heights[terrain + at], around);
}
