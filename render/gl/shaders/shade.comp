#version 430
// render/gl/shaders/shade.comp: shading (docs/design.md section 5 step 5), mirroring the shading loop and
// drawLegend() of renderFrame() in render/src/shading.cpp: hillshade light from the sun, elevation, water-depth or
// colour-layer colours, cell outlines, distance fog, the sky, and the legend's colour bar and labels. What needs the
// CPU (a colour layer's exact values, cell outlines out of core) comes per pixel in the overlay (GpuFrame::overlay).
// Colours are blended in linear light; the sRGB transfer functions use the CPU's 4096-step
// quantisation of their input so that both backends round to the same 8-bit levels.
layout(local_size_x = HC_GROUP_2D, local_size_y = HC_GROUP_2D) in;

layout(std430, binding = HC_BIND_PIXELS) readonly buffer PixelBlock { GpuPixel pixels[]; };
layout(std430, binding = HC_BIND_COUNTERS) buffer CounterBlock { uint counters[]; };
layout(std430, binding = HC_BIND_OVERLAY) readonly buffer OverlayBlock { GpuOverlay overlay[]; };
layout(rgba8, binding = HC_IMAGE_COLOR) writeonly uniform image2D image;

float quantised(float c) { return floor(clamp(c, 0.0, 1.0) * 4096.0 + 0.5) / 4096.0; }
float toLinear(float c) {
    c = quantised(c);
    return c <= 0.04045 ? c / 12.92 : pow((c + 0.055) / 1.055, 2.4);
}
vec3 toLinear(vec3 c) { return vec3(toLinear(c.r), toLinear(c.g), toLinear(c.b)); }
float toSrgb8(float c) {
    c = quantised(c);
    const float s = c <= 0.0031308 ? 12.92 * c : 1.055 * pow(c, 1.0 / 2.4) - 0.055;
    return floor(s * 255.0 + 0.5);
}

// Ramp::at() of shading.cpp over five stops (t, r, g, b), as GpuFrame holds them.
vec3 rampOf5(const float stops[20], float t) {
    t = clamp(t, 0.0, 1.0);
    for (int i = 1; i < 5; ++i)
        if (t <= stops[4 * i]) {
            const float a = (t - stops[4 * i - 4]) / (stops[4 * i] - stops[4 * i - 4]);
            const vec3 p = vec3(stops[4 * i - 3], stops[4 * i - 2], stops[4 * i - 1]);
            const vec3 q = vec3(stops[4 * i + 1], stops[4 * i + 2], stops[4 * i + 3]);
            return p + a * (q - p);
        }
    return vec3(stops[17], stops[18], stops[19]);
}
vec3 elevationColor(float t) { return rampOf5(frame.elevationRamp, t); }
vec3 layerColor(float t) { return rampOf5(frame.layerRamp, t); }
vec3 depthColor(float t) {
    t = clamp(t, 0.0, 1.0);
    for (int i = 1; i < 3; ++i)
        if (t <= frame.depthRamp[4 * i]) {
            const float a = (t - frame.depthRamp[4 * i - 4]) / (frame.depthRamp[4 * i] - frame.depthRamp[4 * i - 4]);
            const vec3 p = vec3(frame.depthRamp[4 * i - 3], frame.depthRamp[4 * i - 2], frame.depthRamp[4 * i - 1]);
            const vec3 q = vec3(frame.depthRamp[4 * i + 1], frame.depthRamp[4 * i + 2], frame.depthRamp[4 * i + 3]);
            return p + a * (q - p);
        }
    return vec3(frame.depthRamp[9], frame.depthRamp[10], frame.depthRamp[11]);
}

// Is pixel (px, py) set by a legend label starting at (x, y)? drawText() of shading.cpp.
bool labelPixel(int px, int py, int x, int y, bool hi) {
    const int scale = frame.legendScale;
    const int len = hi ? frame.labelHiLen : frame.labelLoLen;
    const int rx = px - x, ry = py - y;
    if (rx < 0 || ry < 0 || ry >= 5 * scale || rx >= 4 * scale * len) return false;
    const int ch = rx / (4 * scale), cx = (rx % (4 * scale)) / scale, cy = ry / scale;
    if (cx >= 3) return false;
    const uint bits = hi ? frame.labelHi[ch] : frame.labelLo[ch];
    return ((bits >> uint(14 - (cy * 3 + cx))) & 1u) != 0u;
}

void main() {
    const uint px = gl_GlobalInvocationID.x, py = gl_GlobalInvocationID.y;
    if (px >= uint(frame.width) || py >= uint(frame.height)) return;
    const uint i = py * uint(frame.width) + px;
    const GpuPixel p = pixels[i];
    const vec3 d = rayDirection(px, py);
    const float up = clamp(d.z, 0.0, 1.0);
    const vec3 horizon = vec3(frame.skyHorizon[0], frame.skyHorizon[1], frame.skyHorizon[2]);
    const vec3 zenith = vec3(frame.skyZenith[0], frame.skyZenith[1], frame.skyZenith[2]);
    const vec3 sky = horizon + up * (zenith - horizon);
    vec3 c;
    if (p.t < kInf) {
        const uint slot = (gl_WorkGroupID.x + 7u * gl_WorkGroupID.y) % uint(kCounterSlots);
        atomicAdd(counters[uint(kMaxCascades * kCounterSlots) + slot], 1u);
        if (p.cascade >= 0)  // its cascade's nearest hit (HC_BIND_COUNTERS)
            atomicMax(counters[uint(kNearestHitCounter + p.cascade * kCounterSlots) + slot],
                      kNearestHitBits - floatBitsToUint(max(p.t, 0.0)));
        const vec3 sun = vec3(frame.sun[0], frame.sun[1], frame.sun[2]);
        const float light = 0.3 + 0.7 * max(0.0, dot(vec3(p.nx, p.ny, p.nz), sun));
        vec3 base;
        const float posZ = frame.eyeZ + p.relZ;
        const bool layered = (frame.overlay & 1) != 0;  // the priorities of shadeBlock(): wall, layer, dry under a water
        if (p.wall != 0)                                 // layer, water depth, dry (depth mode), elevation
            base = vec3(frame.wallColor[0], frame.wallColor[1], frame.wallColor[2]);
        else if (layered && overlay[i].valued != 0)
            base = layerColor((overlay[i].layer - frame.layerLo) / frame.layerRange);
        else if (layered && frame.layerOnWater != 0 && p.water == 0)
            base = vec3(frame.dryColor[0], frame.dryColor[1], frame.dryColor[2]);
        else if (p.water != 0)
            base = depthColor(p.depth / frame.dRange);
        else if (frame.colorMode == 1)
            base = vec3(frame.dryColor[0], frame.dryColor[1], frame.dryColor[2]);
        else
            base = elevationColor((posZ - frame.elevationMin) / frame.zRange);
        c = toLinear(base) * light;
        if ((frame.overlay & 2) != 0) {
            c *= overlay[i].dim;  // out of core: from the cells around the hit, on the CPU
        } else if (frame.cellOutlines != 0 && p.wall == 0) {
            // The hit position rounded to float as the CPU's Frame holds it, then located in double.
            const double x = double(float(frame.eyeX + double(p.relX))), y = double(float(frame.eyeY + double(p.relY)));
            const int k = locateCell(x, y);
            if (k >= 0) {
                const double size = frame.finestM * double(1u << cells[k].level);
                const double x0 = double(cells[k].ix) * frame.finestM, y0 = double(cells[k].iy) * frame.finestM;
                const double edge = min(min(x - x0, x0 + size - x), min(y - y0, y0 + size - y));
                if (edge < 0.7 * double(p.t) * double(frame.pixelAngle)) c *= 0.35;
            }
        }
        const float fog = 0.5 * (1.0 - exp(-p.t / frame.fogDistM));
        c = c + fog * (toLinear(sky) - c);
    } else {
        c = toLinear(sky);
    }
    vec3 rgb = vec3(toSrgb8(c.r), toSrgb8(c.g), toSrgb8(c.b));
    // The legend, drawn over the picture as drawLegend() does after shading.
    if (frame.legendRamp != 0) {
        const int x = int(px), y = int(py);
        const int bx = x - frame.legendX0, by = y - frame.legendY0;
        if (bx >= 0 && by >= 0 && bx < frame.legendBarW && by < frame.legendBarH) {
            const float t = 1.0 - float(by) / float(frame.legendBarH - 1);
            rgb = floor((frame.legendRamp == 1 ? depthColor(t) : frame.legendRamp == 3 ? layerColor(t) : elevationColor(t)) * 255.0);
        }
        const int lx = frame.legendX0 + frame.legendBarW + 2 * frame.legendScale;
        if (labelPixel(x, y, lx, frame.legendY0, true) ||
            labelPixel(x, y, lx, frame.legendY0 + frame.legendBarH - 5 * frame.legendScale, false))
            rgb = vec3(20.0);
    }
    imageStore(image, ivec2(px, uint(frame.height) - 1u - py), vec4(rgb / 255.0, 1.0));
}
