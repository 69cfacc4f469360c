// render/src/shading.cpp: stage 5 of the CPU renderer (detail::shadePixels): hillshade light, the colour ramps
// (elevation, water depth, a colour layer), distance fog, sky, cell outlines, and the legend and its layout
// (detail::legendLayout, which shade.comp draws the same way).
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdio>
#include <limits>
#include <optional>
#include <string>
#include <utility>

#include "heightcast/core/heap.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/timer.h"
#include "heightcast/render/detail/frame.h"
#include "heightcast/render/gpu_layout.h"
#include "renderer_internal.h"

namespace hc::render::detail {

namespace {

// detail::expOfNegative (frame.h), inline: the shading loop's calls of it vectorise (a call to a function the library
// exports, which -fPIC lets another library replace, is not inlined).
inline float expNegative(float x) {
    x = x < -87.0f ? -87.0f : x;  // -inf and the tail: a select
    const float n = std::floor(x * 1.44269504088896341f + 0.5f);
    const float r = (x - n * 0.693359375f) + n * 2.12194440e-4f;  // x - n ln 2, ln 2 in two parts (Cody-Waite)
    float p = 1.9875691500e-4f;                                   // e^r = 1 + r + r^2 p(r), Cephes' expf
    for (float c : {1.3981999507e-3f, 8.3334519073e-3f, 4.1665795894e-2f, 1.6666665459e-1f, 5.0000001201e-1f})
        p = p * r + c;
    const float er = p * r * r + r + 1.0f;
    return er * std::bit_cast<float>((int(n) + 127) << 23);  // n >= -126: a normal power of two
}

}  // namespace

float expOfNegative(float x) { return expNegative(x); }

namespace {

// In float, as shade.comp: the shading loop then works on twice the lanes (shadeBlock).
struct Rgb {
    float r, g, b;
};

// A colour ramp: stops (position, sRGB colour), positions rising from 0 to 1, padded to kRampStops by repeating the
// last. at() takes the segment that ends at the first stop at or past t, as a search from the first would, without a
// branch, so that the shading loop vectorises (shadeBlock); t is clamped to [0, 1] and NaN takes the last stop.
constexpr size_t kRampStops = 5;
struct Ramp {
    std::array<float, kRampStops> t{}, r{}, g{}, b{};
    Rgb at(float x) const {
        // std::clamp's value for every x but NaN, in two unconditional selects (the vectoriser does not speculate a
        // comparison that one select would make conditional).
        x = x < 0.0f ? 0.0f : x;
        x = x <= 1.0f ? x : 1.0f;
        float t0 = t[0], t1 = t[1], r0 = r[0], r1 = r[1], g0 = g[0], g1 = g[1], b0 = b[0], b1 = b[1];
        for (size_t k = 1; k + 1 < kRampStops; ++k) {
            const bool past = x > t[k];
            t0 = past ? t[k] : t0, t1 = past ? t[k + 1] : t1;
            r0 = past ? r[k] : r0, r1 = past ? r[k + 1] : r1;
            g0 = past ? g[k] : g0, g1 = past ? g[k + 1] : g1;
            b0 = past ? b[k] : b0, b1 = past ? b[k + 1] : b1;
        }
        const float a = (x - t0) / (t1 - t0);
        return {r0 + a * (r1 - r0), g0 + a * (g1 - g0), b0 + a * (b1 - b0)};
    }
};

// The ramps of gpu_layout.h (shared with shade.comp), and others, as Ramp.
template <size_t N>
constexpr Ramp rampOf(const double (&stops)[N][4]) {
    static_assert(N >= 2 && N <= kRampStops);
    Ramp ramp;
    for (size_t k = 0; k < kRampStops; ++k) {
        const auto& s = stops[std::min(k, N - 1)];
        ramp.t[k] = float(s[0]), ramp.r[k] = float(s[1]), ramp.g[k] = float(s[2]), ramp.b[k] = float(s[3]);
    }
    return ramp;
}
constexpr bool rampIsValid(const Ramp& ramp) {
    if (ramp.t[0] != 0.0 || ramp.t[kRampStops - 1] != 1.0) return false;
    for (size_t k = 1; k < kRampStops; ++k)
        if (ramp.t[k] < ramp.t[k - 1]) return false;
    return true;
}
constexpr Ramp kElevation = rampOf(gpu::kElevationRamp);
constexpr Ramp kDepth = rampOf(gpu::kDepthRamp);
static_assert(rampIsValid(kElevation) && rampIsValid(kDepth));
constexpr Ramp kDryRamp = [] {
    Ramp ramp = kElevation;
    ramp.r.fill(float(gpu::kDryColor[0])), ramp.g.fill(float(gpu::kDryColor[1])), ramp.b.fill(float(gpu::kDryColor[2]));
    return ramp;
}();

// sRGB transfer functions by table (pow per pixel channel was a sixth of a frame): 4096 steps keep
// the 8-bit output exact to within one level.
struct SrgbTables {
    std::array<float, 4097> toLinear{};
    std::array<uint8_t, 4097> toSrgb{};
    SrgbTables() {
        for (int i = 0; i <= 4096; ++i) {
            const double c = i / 4096.0;
            toLinear[size_t(i)] = float(c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4));
            const double s = c <= 0.0031308 ? 12.92 * c : 1.055 * std::pow(c, 1.0 / 2.4) - 0.055;
            toSrgb[size_t(i)] = static_cast<uint8_t>(std::lround(s * 255.0));
        }
    }
};
const SrgbTables kSrgb;

void drawText(Frame& f, int x, int y, const std::string& text, int scale) {
    for (char ch : text) {
        const uint32_t bits = gpu::glyphBits(ch);  // 3 x 5 pixels, bit 14 top-left
        for (int r = 0; r < 5; ++r)
            for (int c = 0; c < 3; ++c)
                if ((bits >> (14 - (r * 3 + c))) & 1u)
                    for (int dy = 0; dy < scale; ++dy)
                        for (int dx = 0; dx < scale; ++dx) {
                            const int px = x + c * scale + dx, py = y + r * scale + dy;
                            if (px < 0 || py < 0 || px >= f.width || py >= f.height) continue;
                            uint8_t* p = &f.rgb[(size_t(py) * size_t(f.width) + size_t(px)) * 3];
                            p[0] = p[1] = p[2] = 20;
                        }
        x += 4 * scale;
    }
}

std::string label(double v, const std::string& units = "m") {
    char b[48];
    std::snprintf(b, sizeof b,
                  std::abs(v) >= 100           ? "%.0f%s"
                  : std::abs(v) >= 1 || v == 0 ? "%.1f%s"
                                               : "%.3g%s",
                  v, units.c_str());
    return b;
}

constexpr Ramp kLayerRamp = rampOf(gpu::kLayerRamp);  // RenderOptions::colorLayer's
static_assert(rampIsValid(kLayerRamp));

}  // namespace

std::pair<double, double> layerRange(const Grid& g, const influence::Layer& layer) {
    double lo = HUGE_VAL, hi = -HUGE_VAL;
    if (layer.kind == influence::Layer::WaterCells) {
        const size_t s = layer.index - g.firstStepLayer();
        for (const StepInfo& step : g.steps)
            if (s < step.layerMin.size())
                lo = std::min(lo, double(step.layerMin[s])), hi = std::max(hi, double(step.layerMax[s]));
    } else {
        for (float v : g.values[layer.index]) lo = std::min(lo, double(v)), hi = std::max(hi, double(v));
    }
    if (!(lo <= hi)) lo = hi = 0;
    return {lo, hi};
}

std::vector<float> colorLayerValues(const Scene& scene, const influence::Layer& layer, const RenderOptions& options,
                                    const Frame& f, const std::vector<uint8_t>& isWater) {
    std::vector<float> out(f.distanceM.size(), std::numeric_limits<float>::quiet_NaN());
    std::vector<std::array<double, 2>> pts;
    std::vector<size_t> at;
    const bool onWater = layer.kind == influence::Layer::WaterCells;
    for (size_t i = 0; i < out.size(); ++i)
        if (std::isfinite(f.distanceM[i]) && f.wall[i] == 0 && (isWater[i] != 0) == onWater)
            pts.push_back({f.posX[i], f.posY[i]}), at.push_back(i);
    const auto v = scene.evaluator().values(pts, layer, options.threads);
    for (size_t j = 0; j < at.size(); ++j)
        if (v[j]) out[at[j]] = float(*v[j]);
    return out;
}

double cellOutlineDim(const Scene& scene, const Frame& f, size_t i, double pixelAngle) {
    if (!std::isfinite(f.distanceM[i]) || f.wall[i] != 0) return 1.0;
    if (auto cell = scene.cellSquareAt(f.posX[i], f.posY[i])) {
        const auto q = *cell;
        const double edge = std::min({f.posX[i] - q.x0, q.x1 - f.posX[i], f.posY[i] - q.y0, q.y1 - f.posY[i]});
        if (edge < 0.7 * f.distanceM[i] * pixelAngle) return 0.35;
    }
    return 1.0;
}

namespace {

// A colour bar with its range, at the image's right edge.
void drawLegend(Frame& f, const LegendLayout& l) {
    if (!l.shown) return;
    const Ramp& ramp = l.layer ? kLayerRamp : l.depth ? kDepth : kElevation;
    for (int y = 0; y < l.barH; ++y) {
        const Rgb c = ramp.at(float(1.0 - double(y) / (l.barH - 1)));
        for (int x = 0; x < l.barW; ++x) {
            uint8_t* p = &f.rgb[(size_t(l.y0 + y) * size_t(f.width) + size_t(l.x0 + x)) * 3];
            p[0] = static_cast<uint8_t>(c.r * 255), p[1] = static_cast<uint8_t>(c.g * 255),
            p[2] = static_cast<uint8_t>(c.b * 255);
        }
    }
    drawText(f, l.x0 + l.barW + 2 * l.scale, l.y0, l.hi, l.scale);
    drawText(f, l.x0 + l.barW + 2 * l.scale, l.y0 + l.barH - 5 * l.scale, l.lo, l.scale);
}

// Stage 5's inputs: the frame's layers and rays, and the shading's constants.
struct ShadeInputs {
    const Frame& f;
    const PixelRays& rays;
    const double* sun;  // the unit vector to the sun
    double fogDist;     // [m]: a hit at distance d is 0.5 (1 - exp(-d / fogDist)) sky
    Rgb skyHorizon, skyZenith;
    double zMin, zRange, dRange;  // the elevation ramp's origin and range, the depth ramp's range [m]
    double layerLo, layerRange;   // the colour layer's ramp
    const float* layerValues;     // RenderOptions::colorLayer at every pixel (NaN where it does not colour), or null
    bool layerOnWater;            // the colour layer is a water layer: dry terrain in the dry colour
    bool depthMode;               // ColorMode::WaterDepth: dry terrain in the dry colour
};

// A worker's buffers for a run of up to kShadeBlock pixels of a row.
constexpr size_t kShadeBlock = 256;
struct ShadeBlock {
    std::array<float, kShadeBlock> fog;  // the fog's share
    std::array<float, kShadeBlock>
        dim;  // the cell outline's factor: 1, or 0.35 on an edge (RenderOptions::cellOutlines)
    std::array<int, kShadeBlock> water;    // PixelRays::isWater
    std::array<int, kShadeBlock> r, g, b;  // indices into the sRGB tables
    ShadeBlock() { dim.fill(1.0f); }
};

// Shades pixels i0 .. i0 + n - 1 into rgb (3 bytes a pixel); returns how many are hits. The colour of a pixel is
// computed without branches (every ramp at every pixel, chosen by selects) so that the compiler vectorises the loop:
// the arithmetic of a pixel, 17 ns on one core before, was 90 % of the stage. It is float, as shade.comp's (twice the
// lanes of double), the fog's exponential too (expNegative).
template <bool Layer>
uint64_t shadeBlock(const ShadeInputs& in, size_t i0, size_t n, ShadeBlock& blk, uint8_t* rgb) {
    const Frame& f = in.f;
    const float* dist = f.distanceM.data() + i0;
    uint64_t hits = 0;
    const uint8_t* water = in.rays.isWater.data() + i0;
    const float invFog = float(1.0 / in.fogDist);
    for (size_t k = 0; k < n; ++k) {
        const bool hit = std::isfinite(dist[k]);
        hits += hit;
        blk.fog[k] = hit ? 0.5f * (1.0f - expNegative(-dist[k] * invFog)) : 0.0f;
        blk.water[k] = water[k];  // bytes: out of the vectorised loop (a vector of bytes would make it 64 lanes wide)
    }
    const float* nX = f.nX.data() + i0;
    const float* nY = f.nY.data() + i0;
    const float* nZ = f.nZ.data() + i0;
    const float* posZ = f.posZ.data() + i0;
    const float* depth = f.waterDepthM.data() + i0;
    const float* wallAt = f.wall.data() + i0;
    const float* layerAt = Layer ? in.layerValues + i0 : nullptr;
    const float* dirZ = in.rays.dirZ.data() + i0;
    const float* toLin = kSrgb.toLinear.data();
    // std::clamp(c, 0, 1) by value, in two unconditional selects (std::clamp returns a reference, a branch to the
    // vectoriser, as is a comparison made only when another fails).
    auto unit = [](float c) {
        c = c < 0.0f ? 0.0f : c;
        return 1.0f < c ? 1.0f : c;
    };
    // The nearest entry of kSrgb's tables (adding 0.5 and truncating rounds as lround does).
    auto index = [&](float c) { return int(unit(c) * 4096.0f + 0.5f); };
    const Rgb hz = in.skyHorizon, zn = in.skyZenith,
              wallColor{float(gpu::kWallColor[0]), float(gpu::kWallColor[1]), float(gpu::kWallColor[2])},
              dry{float(gpu::kDryColor[0]), float(gpu::kDryColor[1]), float(gpu::kDryColor[2])};
    const float sun0 = float(in.sun[0]), sun1 = float(in.sun[1]), sun2 = float(in.sun[2]);
    const float zMin = float(in.zMin), zScale = float(1.0 / in.zRange), dScale = float(1.0 / in.dRange);
    const float layerLo = float(in.layerLo), layerScale = float(1.0 / in.layerRange);
    // Dry land in ColorMode::WaterDepth: a ramp of the dry colour at every stop, which gives that colour exactly (a
    // select on a flag the loop does not change is not vectorised).
    const Ramp& landRamp = in.depthMode ? kDryRamp : kElevation;
    for (size_t k = 0; k < n; ++k) {
        const float up = unit(dirZ[k]);
        const Rgb sky{hz.r + up * (zn.r - hz.r), hz.g + up * (zn.g - hz.g), hz.b + up * (zn.b - hz.b)};
        const Rgb skyLin{toLin[index(sky.r)], toLin[index(sky.g)], toLin[index(sky.b)]};
        // The base colour, by priority: wall, colour layer, dry under a water layer, water depth, dry (depth mode),
        // elevation (each a select of plain floats: a select of a struct is a branch to the vectoriser).
        const bool isWater = blk.water[k] != 0, wall = wallAt[k] != 0;
        const Rgb land = landRamp.at((posZ[k] - zMin) * zScale), wet = kDepth.at(depth[k] * dScale);
        float br = isWater ? wet.r : land.r, bg = isWater ? wet.g : land.g, bb = isWater ? wet.b : land.b;
        if constexpr (Layer) {
            const bool dryUnder = in.layerOnWater && !isWater;
            br = dryUnder ? dry.r : br, bg = dryUnder ? dry.g : bg, bb = dryUnder ? dry.b : bb;
            const float v = layerAt[k];
            const Rgb l = kLayerRamp.at((v - layerLo) * layerScale);
            const bool valued = !std::isnan(v);
            br = valued ? l.r : br, bg = valued ? l.g : bg, bb = valued ? l.b : bb;
        }
        br = wall ? wallColor.r : br, bg = wall ? wallColor.g : bg, bb = wall ? wallColor.b : bb;
        const float lambert = nX[k] * sun0 + nY[k] * sun1 + nZ[k] * sun2;
        const float light = 0.3f + 0.7f * (0.0f < lambert ? lambert : 0.0f);  // std::max(0.0f, lambert)
        Rgb c{toLin[index(br)] * light, toLin[index(bg)] * light, toLin[index(bb)] * light};
        c = {c.r * blk.dim[k], c.g * blk.dim[k], c.b * blk.dim[k]};  // 1 or 0.35
        const float fog = blk.fog[k];
        const bool hit = std::isfinite(dist[k]);
        const Rgb fogged{c.r + fog * (skyLin.r - c.r), c.g + fog * (skyLin.g - c.g), c.b + fog * (skyLin.b - c.b)};
        c = {hit ? fogged.r : skyLin.r, hit ? fogged.g : skyLin.g, hit ? fogged.b : skyLin.b};
        blk.r[k] = index(c.r), blk.g[k] = index(c.g), blk.b[k] = index(c.b);
    }
    for (size_t k = 0; k < n; ++k) {
        uint8_t* p = rgb + 3 * k;
        p[0] = kSrgb.toSrgb[size_t(blk.r[k])], p[1] = kSrgb.toSrgb[size_t(blk.g[k])],
        p[2] = kSrgb.toSrgb[size_t(blk.b[k])];
    }
    return hits;
}

}  // namespace

LegendLayout legendLayout(const Scene& scene, const RenderOptions& options, int width, int height) {
    LegendLayout l;
    if (!options.legend) return l;
    double lo = 0, hi = 0;
    std::string units = "m";
    if (!options.colorLayer.empty()) {
        const influence::Layer layer = influence::Layer::byName(scene.grid(), options.colorLayer);
        std::tie(lo, hi) = layerRange(scene.grid(), layer);
        l.layer = true;
        units = scene.grid().layers[layer.index].units;
        if (!units.empty()) units = " " + units;
    } else if (scene.hasWater() && scene.depthColorMaxM > 0) {
        l.depth = true, lo = 0, hi = scene.depthColorMaxM;
    } else if (options.color == ColorMode::Elevation) {
        lo = scene.elevationMin, hi = scene.elevationMax;
    } else {
        return l;
    }
    l.hi = label(hi, units);
    l.lo = label(lo, units);
    l.scale = std::max(1, height / 360);
    l.barH = std::max(20, height * 2 / 5), l.barW = std::max(6, 6 * l.scale);
    // Room for the longer label (glyphs 3 pixels and a space wide), and never less than 8 characters' worth.
    const int chars = int(std::max<size_t>({8, l.hi.size(), l.lo.size()}));
    l.x0 = width - l.barW - 8 * l.scale - 4 * l.scale * chars, l.y0 = height / 2 - l.barH / 2;
    l.shown = l.x0 >= 0 && l.y0 >= 0;
    return l;
}

void shadePixels(const Scene& scene, const RenderOptions& options, const CameraBasis& basis, const PixelRays& rays,
                 Frame& f, Timings& timings) {
    const Stopwatch clock;
    const int W = f.width, H = f.height;
    assignOnHugePages(f.rgb, size_t(W) * size_t(H) * 3, uint8_t(0));
    const double sunAz = gpu::kSunAzimuthDeg * M_PI / 180, sunAlt = gpu::kSunAltitudeDeg * M_PI / 180;
    const double sun[3] = {std::sin(sunAz) * std::cos(sunAlt), std::cos(sunAz) * std::cos(sunAlt), std::sin(sunAlt)};
    const double fogDist = gpu::kFogExtents * std::hypot(scene.xMax - scene.xMin, scene.yMax - scene.yMin);
    const Rgb skyHorizon{float(gpu::kSkyHorizon[0]), float(gpu::kSkyHorizon[1]), float(gpu::kSkyHorizon[2])};
    const Rgb skyZenith{float(gpu::kSkyZenith[0]), float(gpu::kSkyZenith[1]), float(gpu::kSkyZenith[2])};
    const double zRange = std::max(scene.elevationMax - scene.elevationMin, 1e-6);
    const double dRange = std::max(scene.depthColorMaxM, 1e-6);
    const double pixelAngle = 2.0 * basis.tanHalfY / H;
    // --color-by: the layer's value at every hit it colours (one batch through the exact evaluator), and its range.
    std::optional<influence::Layer> colorLayer;
    std::vector<float> layerValues;
    double layerLo = 0, layerRangeV = 1;
    if (!options.colorLayer.empty()) {
        colorLayer = influence::Layer::byName(scene.grid(), options.colorLayer);
        layerValues = colorLayerValues(scene, *colorLayer, options, f, rays.isWater);
        f.colorLayer = options.colorLayer;
        const auto [lo, hi] = layerRange(scene.grid(), *colorLayer);
        layerLo = lo, layerRangeV = std::max(hi - lo, 1e-12);
    }
    const ShadeInputs in{.f = f,
                         .rays = rays,
                         .sun = sun,
                         .fogDist = fogDist,
                         .skyHorizon = skyHorizon,
                         .skyZenith = skyZenith,
                         .zMin = scene.elevationMin,
                         .zRange = zRange,
                         .dRange = dRange,
                         .layerLo = layerLo,
                         .layerRange = layerRangeV,
                         .layerValues = colorLayer ? layerValues.data() : nullptr,
                         .layerOnWater = colorLayer && colorLayer->kind == influence::Layer::WaterCells,
                         .depthMode = options.color == ColorMode::WaterDepth};
    // Cell outlines: a scene lookup a pixel, so outside the vectorised loop (ShadeBlock::dim).
    auto outline = [&](size_t i0, size_t n, float* dim) {
        for (size_t k = 0; k < n; ++k) dim[k] = float(cellOutlineDim(scene, f, i0 + k, pixelAngle));
    };
    std::vector<uint64_t> hits(resolveThreads(options.threads), 0);
    parallelFor(size_t(H), 16, options.threads, [&](size_t b, size_t e, unsigned worker) {
        ShadeBlock block;
        uint64_t hit = 0;  // added to hits[worker] once: the workers' counters share a cache line
        for (size_t py = b; py < e; ++py)
            for (size_t px = 0; px < size_t(W); px += kShadeBlock) {
                const size_t i0 = py * size_t(W) + px, n = std::min(kShadeBlock, size_t(W) - px);
                if (options.cellOutlines) outline(i0, n, block.dim.data());
                uint8_t* rgb = &f.rgb[i0 * 3];
                hit += colorLayer ? shadeBlock<true>(in, i0, n, block, rgb) : shadeBlock<false>(in, i0, n, block, rgb);
            }
        hits[worker] += hit;
    });
    for (uint64_t h : hits) timings.hits += h;
    drawLegend(f, legendLayout(scene, options, W, H));
    f.colorLayerValue = std::move(layerValues);
    timings.shadingMs = clock.milliseconds();
}

}  // namespace hc::render::detail
