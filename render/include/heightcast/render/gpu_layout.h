// heightcast/render/gpu_layout.h: the structs and constants that the CPU side and the GL compute
// shaders share (docs/design.md section 5: one header for both backends).
//
// Written in the common subset of C++ and GLSL 4.30: scalar members (float, int, uint, double) and
// fixed-size scalar arrays only, so the std430 layout the shaders see equals the C layout (std430
// aligns scalars and scalar arrays to their own size, structs to their largest member; no vec3
// padding traps). The build prepends this file to every render/gl/shaders/*.comp (after #version);
// tests/render_gl_test.cpp compares the driver's offsets, strides and sizes with offsetof/sizeof.
//
// Frames: "local" is metres from the grid origin (as everywhere in render/); "eye-relative" is local
// minus the camera position. Floats hold eye-relative or local values whose magnitude stays below
// the scene's extent (float resolves 1/16 mm at 1 km, 8 mm at 100 km).
#ifndef HEIGHTCAST_RENDER_GPU_LAYOUT_H
#define HEIGHTCAST_RENDER_GPU_LAYOUT_H

#ifdef __cplusplus
#include <algorithm>
#include <cmath>
#include <cstdint>
namespace hc::render::gpu {
using std::abs, std::min;
using uint = std::uint32_t;
#define HC_LAYOUT_FN inline
#else
#define HC_LAYOUT_FN
#endif

// Buffer binding points (macros: GLSL 4.30 layout qualifiers take literals only).
#define HC_BIND_FRAME 0      // FrameBlock: GpuFrame + GpuCascade[kMaxCascades]
#define HC_BIND_CELLS 1      // GpuCell[cellCount + 1]
#define HC_BIND_KEYS 2       // uint[2 * cellCount]: each cell's Morton key (lo, hi), sorted
#define HC_BIND_INDICES 3    // uint[]: the influence lists' entries (CSR indices), first chunk
#define HC_BIND_INDICES_1 8  // further chunks of the entries (a driver caps one storage buffer: llvmpipe at
#define HC_BIND_INDICES_2 9  //   128 MiB, which the lists of a million cells exceed)
#define HC_BIND_INDICES_3 10
#define HC_BIND_VISIBLE \
    4  // int[]: per cascade 4 ints a row: the spans to evaluate (RowFill a0, a1, b0, b1); out of core the
       //   spans atlas.comp copies the pyramid's texels in
#define HC_BIND_HEIGHTS 5  // float[]: per cascade terrain, water, depth textures and both max mipmaps
#define HC_BIND_PIXELS 6   // GpuPixel[width * height], row 0 at the top
#define HC_BIND_COUNTERS \
    7  // uint[kCounterUints]: Gaussians per cascade, then hits, then per cascade the float bits of its texels' error
       //   estimate (patchErrorEstimateM; uint order is float order for >= 0), then per cascade its nearest hit
       //   (CascadeStats::nearestHitM) as kNearestHitBits minus the distance's float bits, 0 none, the largest winning
// Out of core (assemble.comp): the last frame's heights buffer, and what the CPU evaluated this frame.
#define HC_BIND_LAST_HEIGHTS 11  // float[]: the last frame's HC_BIND_HEIGHTS
#define HC_BIND_FILL_ROWS \
    12  // int[kFillRowInts per texel row of every cascade]: RowFill, then its spans' first packed texels
#define HC_BIND_FILL_TEXELS 13  // float[3 * plane]: the evaluated texels packed, terrain, then water, then depth
// raycast.comp's beams (beams.comp): per tile of GpuFrame::beamTile^2 pixels and cascade, (start depth, passed).
#define HC_BIND_BEAMS 14  // vec2[tiles * kMaxCascades], tiles row-major over the image
// Out of core with a pyramid (atlas.comp): its tiles resident on the GPU, and the frame's tiles to copy texels from
// (each cascade's row spans to copy in, before the copies were taken out, are in HC_BIND_VISIBLE).
#define HC_BIND_ATLAS_TERRAIN 15  // float[kAtlasPlane per slot]: a tile's elevations
#define HC_BIND_ATLAS_WATER 16    // float[2 kAtlasPlane per slot]: a tile's water levels, then its wet shares
#define HC_BIND_ATLAS_TILES 17    // uvec4 per tile to copy from (atlas.comp)
#define HC_BIND_ATLAS_BLOCKS \
    18  // uint[kAtlasBlockUints per block]: texels to interpolate from level 0's tiles (interpolate.comp)
// Values the CPU computes from a frame's hits before shading (GpuFrame::overlay): --color-by, cell outlines out of
// core.
#define HC_BIND_OVERLAY 19  // GpuOverlay[width * height], row 0 at the top
#define HC_BIND_LAST 19     // the highest binding
#define HC_IMAGE_COLOR 0    // rgba8 image unit of the shaded picture (row 0 at the bottom)

// Work-group sizes (macros: they go into layout(local_size_x = ...)).
#define HC_GROUP_2D 8

const int kMaxCascades = 4;
const int kMaxMipLevels = 16;  // a 8192^2 cascade has 14 levels
const int kCounterSlots = 64;  // a counter is spread over slots so that no uint overflows
const int kEstimateCounter = kCounterSlots * (kMaxCascades + 1);  // HC_BIND_COUNTERS: cascade 0's error estimate
const int kNearestHitCounter = kEstimateCounter + kMaxCascades;   // HC_BIND_COUNTERS: cascade 0's nearest hit's slots
const uint kNearestHitBits = 0x7f800000u;  // +inf's float bits: a nearest hit d counts as kNearestHitBits - bits(d)
const int kCounterUints = kNearestHitCounter + kMaxCascades * kCounterSlots;  // the whole HC_BIND_COUNTERS buffer
const int kMaxLabelChars = 12;                                                // legend labels ("-10994m")
const int kIndexChunks = 4;  // storage buffers the influence lists' entries may span
const int kFillRowInts = 8;  // a row of HC_BIND_FILL_ROWS: keptFirst, keptLast, a0, a1, b0, b1, packed a0, packed b0
const int kAtlasPlane =
    256;  // floats a channel of an atlas slot: a pyramid tile's samples (16^2; fewer where its side is less)
const int kAtlasBlockUints =
    20;  // a block of interpolate.comp: its head, its first texel, 9 terrain slots, 9 water slots

// One grid cell, plus a sentinel after the last so that cells[k + 1].listBegin ends k's list.
struct GpuCell {
    uint ix;  // south-west corner [finest units]
    uint iy;
    uint level;      // size = finest * 2^level
    uint listBegin;  // first entry of the influence list in the indices buffer
    float a;         // 1 / (2 sigma^2 c^2) (Scene::CellKernel::a)
    float r2;        // squared kernel radius [m^2]
    float z;         // elevation [m]
    float depth;     // water depth [m], 0 without a water layer
};

// One cascade (Cascade in cascades.h) as the shaders read it.
struct GpuCascade {
    double x0;      // local position of texel (0, 0)'s centre [m]; double: texel centres are
    double y0;      //   located in the grid exactly as the CPU does (approximate_sum.cpp)
    double texelM;  // texel size s [m]
    float x0Eye;    // x0 - eye, y0 - eye [m]: the ray caster's frame
    float y0Eye;
    float texelF;     // s as float
    int n;            // texels per side; 0 for an empty cascade
    float splitNear;  // offsets from the eye along the horizontal view direction [m]
    float splitFar;
    float farWithOverlap;
    int levels;                      // max mipmap levels (Heightfield::mip.size())
    uint terrainOffset;              // into the heights buffer [floats]: terrain heights, n * n
    uint waterOffset;                // water surface heights, n * n
    uint depthOffset;                // water depths, n * n
    uint visibleOffset;              // into the visible buffer [uints]
    uint terrainMip[kMaxMipLevels];  // per level: offset of the terrain's max mipmap [floats]
    uint waterMip[kMaxMipLevels];
    int mipSide[kMaxMipLevels];
};

// What every stage of one frame reads.
struct GpuFrame {
    double eyeX;  // camera position, local [m] (double: cell outlines locate hit points)
    double eyeY;
    double finestM;  // grid's finest cell size [m]
    double domainM;  // grid's domain side [m]
    float eyeZ;      // camera height, local z (= world z) [m]
    float tanHalfX;  // image plane half extents at unit distance
    float tanHalfY;
    float nearM;
    float farM;
    float dirX;  // horizontal view direction the cascade offsets are measured along
    float dirY;
    float tail;  // exp(-R^2 / 2): the kernel's cut
    float forward[3];
    float right[3];
    float up[3];
    float sun[3];  // unit vector towards the sun
    int width;     // image [pixels]
    int height;
    int cascades;  // fitted cascades (<= kMaxCascades)
    int hasWater;
    uint cellCount;
    uint rootLevel;
    uint indexChunkShift;  // entry e lies in chunk e >> shift, at e & ((1 << shift) - 1)
    float minDepthM;       // RenderOptions::waterMinDepthM
    float fogDistM;        // fog reaches 1 - 1/e of its half strength at this distance
    float elevationMin;
    float zRange;      // elevation range (>= 1e-6)
    float dRange;      // water depth range (>= 1e-6)
    float pixelAngle;  // vertical angle of one pixel at the image centre [rad]
    int colorMode;     // 0 elevation, 1 water depth (ColorMode)
    int cellOutlines;
    int legendRamp;  // 0 none, 1 water depth, 2 elevation, 3 the colour layer
    int legendX0;    // colour bar's top-left pixel (row 0 at the top), size and label scale
    int legendY0;
    int legendBarW;
    int legendBarH;
    int legendScale;
    int labelHiLen;  // characters of the two labels; their glyphs are 15-bit masks (glyphBits)
    int labelLoLen;
    uint labelHi[kMaxLabelChars];
    uint labelLo[kMaxLabelChars];
    float elevationRamp[5 * 4];  // stops (t, r, g, b), sRGB
    float depthRamp[3 * 4];
    float skyHorizon[3];
    float skyZenith[3];
    float dryColor[3];
    float zFloor;        // the terrain block's bottom: the grid's lowest elevation, local z [m] (RayContext::zFloor)
    float wallColor[3];  // kWallColor, sRGB
    int beamTile;        // raycast.comp's beams: tiles of beamTile^2 pixels, 0 or 1 none (RenderOptions::beamTilePx)
    int overlay;         // what HC_BIND_OVERLAY holds: bit 1 the colour layer's values, bit 2 the outlines' factors
    float layerLo;       // the colour layer's ramp: value at 0 and range (RenderOptions::colorLayer)
    float layerRange;
    int layerOnWater;        // the colour layer is a water layer: dry terrain in the dry colour
    float layerRamp[5 * 4];  // stops (t, r, g, b), sRGB
    int pad[3];              // FrameBlock to a multiple of 16 bytes, to which Mesa rounds a buffer block's size
};

// One pixel's ray-cast result, row 0 at the top (Frame's layout).
struct GpuPixel {
    float t;     // distance along the ray [m]; +inf where the ray misses
    float relX;  // hit position minus the eye [m]
    float relY;
    float relZ;
    float nx;  // unit normal
    float ny;
    float nz;
    float depth;  // water depth at a water hit, else 0
    int cascade;  // -1 where the ray misses
    int water;    // 1 for a water hit
    int wall;     // 1 for a hit on a cut face of the terrain block (Frame::wall)
};

// What the CPU computed at one pixel's hit for the shading (GL backend; shading.cpp computes the same on the CPU).
struct GpuOverlay {
    float layer;  // the colour layer's value (where `valued`)
    float dim;    // the cell outline's factor: 1, or 0.35 on an edge
    int valued;   // 1 where the colour layer colours the hit
};

// Without a surface pyramid a frame's error is estimated from its texels alone (both backends: Heightfield::
// errorEstimateM, mipmap.comp): at the patch whose corner texel is h00 = h(i, j), the error of patches twice as large
// at the texels between their corners, along x (h(i, j), h(i + 1, j), h(i + 2, j): h00, h10, h20) and along y (h00,
// h01, h02), i.e. half the second differences, added. Where the texels resolve the surface that is four times the
// patch's own bilinear error (s^2/2 against s^2/8 times |v_xx| + |v_yy|): a margin; a feature narrower than a texel
// that lies between samples goes unseen. 0 where any of the five has no surface (-inf).
HC_LAYOUT_FN float patchErrorEstimateM(float h00, float h10, float h20, float h01, float h02) {
    if (min(min(h00, h10), min(h20, min(h01, h02))) < -1.0e37f) return 0.0f;
    return 0.5f * (abs(h00 - 2.0f * h10 + h20) + abs(h00 - 2.0f * h01 + h02));
}
#undef HC_LAYOUT_FN

#ifdef __cplusplus
// Shading constants both backends use (shading.cpp and shade.comp through GpuFrame).
// Colour ramps: stops (t, r, g, b), sRGB.
inline constexpr double kElevationRamp[5][4] = {{0.0, 0.24, 0.47, 0.24},
                                                {0.3, 0.59, 0.67, 0.35},
                                                {0.55, 0.63, 0.51, 0.35},
                                                {0.8, 0.6, 0.6, 0.6},
                                                {1.0, 0.98, 0.98, 0.98}};
inline constexpr double kDepthRamp[3][4] = {{0.0, 0.6, 0.87, 0.95}, {0.5, 0.16, 0.47, 0.8}, {1.0, 0.04, 0.12, 0.45}};
// RenderOptions::colorLayer's ramp (perceptually ordered, dark violet to yellow, as viridis), distinct from the
// elevation and depth ramps so that a picture never reads as one of those.
inline constexpr double kLayerRamp[5][4] = {{0.0, 0.267, 0.005, 0.329},
                                            {0.25, 0.229, 0.322, 0.546},
                                            {0.5, 0.128, 0.567, 0.551},
                                            {0.75, 0.369, 0.789, 0.383},
                                            {1.0, 0.993, 0.906, 0.144}};
inline constexpr double kDryColor[3] = {0.7, 0.7, 0.68};  // terrain under ColorMode::WaterDepth
// The cut faces of the terrain block (walls at hole and domain edges, the bottom: Frame::wall), in either colour
// mode: a soil brown darker and redder than every elevation ramp stop, so a wall never reads as terrain.
inline constexpr double kWallColor[3] = {0.45, 0.27, 0.18};
inline constexpr double kSkyHorizon[3] = {0.78, 0.84, 0.92};
inline constexpr double kSkyZenith[3] = {0.43, 0.59, 0.82};
inline constexpr double kSunAzimuthDeg = 315, kSunAltitudeDeg = 45;
inline constexpr double kFogExtents = 3.0;  // fog distance in horizontal scene diagonals

// A 3 x 5 pixel glyph for legend labels (digits, '.', '-', 'm') as 15 bits, row-major from the
// top-left, bit 14 first.
constexpr uint glyphBits(char ch) {
    const char* rows = "000000000000000";
    switch (ch) {
        case '0':
            rows = "111101101101111";
            break;
        case '1':
            rows = "010110010010111";
            break;
        case '2':
            rows = "111001111100111";
            break;
        case '3':
            rows = "111001111001111";
            break;
        case '4':
            rows = "101101111001001";
            break;
        case '5':
            rows = "111100111001111";
            break;
        case '6':
            rows = "111100111101111";
            break;
        case '7':
            rows = "111001001001001";
            break;
        case '8':
            rows = "111101111101111";
            break;
        case '9':
            rows = "111101111001111";
            break;
        case '.':
            rows = "000000000000010";
            break;
        case '-':
            rows = "000000111000000";
            break;
        case 'm':
            rows = "000000111111101";
            break;
        // Enough letters for the units of a --color-by layer ("m s-1", "m/s", "%", "kg m-3", "degC", ...).
        case 's':
            rows = "011100010001110";
            break;
        case '/':
            rows = "001001010100100";
            break;
        case '%':
            rows = "101001010100101";
            break;
        case 'k':
        case 'K':
            rows = "100101110101101";
            break;
        case 'g':
            rows = "011101011001110";
            break;
        case 'h':
            rows = "100100111101101";
            break;
        case 'e':
            rows = "000111101110011";
            break;
        case 'C':
            rows = "111100100100111";
            break;
        case 'd':
            rows = "001001111101111";
            break;
        case 'a':
            rows = "000110011101111";
            break;
        default:
            break;
    }
    uint bits = 0;
    for (int i = 0; i < 15; ++i) bits = (bits << 1) | (rows[i] == '1' ? 1u : 0u);
    return bits;
}

// The whole FrameBlock buffer as the shaders declare it (common.glsl).
struct FrameBlock {
    GpuFrame frame;
    GpuCascade cascades[kMaxCascades];
};

}  // namespace hc::render::gpu
#endif

#endif  // HEIGHTCAST_RENDER_GPU_LAYOUT_H
