// render/gl/shaders/common.glsl: the buffers and helpers every compute shader of the GL backend shares.
// The build prepends it (after gpu_layout.h) to each *.comp; the layouts are in gpu_layout.h.

layout(std430, binding = HC_BIND_FRAME) readonly buffer FrameBlock {
    GpuFrame frame;
    GpuCascade cascades[kMaxCascades];
};
layout(std430, binding = HC_BIND_CELLS) readonly buffer CellBlock { GpuCell cells[]; };
layout(std430, binding = HC_BIND_KEYS) readonly buffer KeyBlock { uint keys[]; };

// +infinity (a macro: GLSL 4.30 global constants need constant initialisers).
#define kInf uintBitsToFloat(0x7f800000u)

// Bits 0..15 of v spread to the even bits (morton.h spreadBits, one 32-bit half at a time).
uint spread16(uint v) {
    v &= 0xffffu;
    v = (v | (v << 8)) & 0x00ff00ffu;
    v = (v | (v << 4)) & 0x0f0f0f0fu;
    v = (v | (v << 2)) & 0x33333333u;
    v = (v | (v << 1)) & 0x55555555u;
    return v;
}

// floor(v / finest) corrected to agree exactly with the edges ix * finest (Grid::locate).
uint finestIndex(double v, uint limit) {
    uint i = min(uint(v / frame.finestM), limit);
    if (i > 0u && v < double(i) * frame.finestM) --i;
    if (i < limit && v >= double(i + 1u) * frame.finestM) ++i;
    return i;
}

// The cell whose half-open square contains local (x, y), or -1: Grid::locate on the GPU. The keys
// are sorted (the grid's codes without their level bits): the last key <= the point's key is the
// only cell that can contain it.
int locateCell(double x, double y) {
    if (!(x >= 0.0 && y >= 0.0 && x < frame.domainM && y < frame.domainM)) return -1;
    const uint limit = (1u << frame.rootLevel) - 1u;
    const uint ix = finestIndex(x, limit), iy = finestIndex(y, limit);
    const uint lo = spread16(ix) | (spread16(iy) << 1), hi = spread16(ix >> 16) | (spread16(iy >> 16) << 1);
    // upper_bound: first index whose key > (hi, lo).
    uint first = 0u, count = frame.cellCount;
    while (count > 0u) {
        const uint step = count >> 1, m = first + step;
        const uint mhi = keys[2u * m + 1u], mlo = keys[2u * m];
        if (mhi < hi || (mhi == hi && mlo <= lo)) {
            first = m + 1u;
            count -= step + 1u;
        } else {
            count = step;
        }
    }
    if (first == 0u) return -1;
    const uint k = first - 1u;
    const uint span = 1u << cells[k].level;
    if (ix - cells[k].ix < span && iy - cells[k].iy < span && ix >= cells[k].ix && iy >= cells[k].iy) return int(k);
    return -1;
}

// Pixel column px's and row py's place on the image plane at unit distance (row 0 at the top), and the direction
// through it, not normalised: renderFrame()'s formula in renderer.cpp.
float sxOf(float px) { return (2.0 * (px + 0.5) / float(frame.width) - 1.0) * frame.tanHalfX; }
float syOf(float py) { return (1.0 - 2.0 * (py + 0.5) / float(frame.height)) * frame.tanHalfY; }
vec3 rawDirection(float sx, float sy) {
    const vec3 f = vec3(frame.forward[0], frame.forward[1], frame.forward[2]);
    const vec3 r = vec3(frame.right[0], frame.right[1], frame.right[2]);
    const vec3 u = vec3(frame.up[0], frame.up[1], frame.up[2]);
    return f + sx * r + sy * u;
}

// The unit ray direction of pixel (px, py).
vec3 rayDirection(uint px, uint py) { return normalize(rawDirection(sxOf(float(px)), syOf(float(py)))); }
