// heightcast/render/detail/frame.h: the frame layer both backends fill: per-cascade textures and the per-frame
// set-up shared by the CPU stages (render/src/) and the GL backend (render/gl/). Internal to render/: the GL backend
// and the tests use it; tools use renderer.h.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <memory>
#include <new>
#include <string>
#include <utility>
#include <vector>

#include <glm/vec3.hpp>

#include "heightcast/core/heap.h"
#include "heightcast/render/camera.h"
#include "heightcast/render/cascades.h"
#include "heightcast/render/renderer.h"

namespace hc::render::detail {

// An allocator whose vectors leave new elements uninitialised where std::vector would zero them: a cascade's
// textures are sized before every texel that is read is written (approximate(): copyReusedTexels writes every texel,
// with RowFill spans every texel of a span, and no other is read), and zeroing them first cost a measurable share of
// every fresh frame (a 1344^2 texture is 7 MB; docs/benchmarks.md). Blocks of 4 MB and more are advised to the
// kernel's huge pages before their first touch (core/heap.h): a fresh process's textures and mipmaps (hundreds of MB
// at 1920 x 1080) fault in 2 MB at a time instead of 4 kB.
template <class T>
struct UninitialisedAllocator : std::allocator<T> {
    template <class U>
    struct rebind {
        using other = UninitialisedAllocator<U>;
    };
    UninitialisedAllocator() = default;
    template <class U>
    UninitialisedAllocator(const UninitialisedAllocator<U>&) noexcept {}
    T* allocate(size_t n) {
        T* p = std::allocator<T>::allocate(n);
        if (n * sizeof(T) >= (size_t(4) << 20)) adviseHugePages(p, n * sizeof(T));
        return p;
    }
    template <class U>
    void construct(U* p) noexcept {
        ::new (static_cast<void*>(p)) U;  // default-initialised: for float, nothing written
    }
    template <class U, class... Args>
    void construct(U* p, Args&&... args) {
        ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
    }
};
using Texels = std::vector<float, UninitialisedAllocator<float>>;

// One heightfield in a cascade: heights at texel centres and its max mipmap over patches.
// -inf marks "no surface" (a hole, dry land for water, or a texel outside the visible polygon).
struct Heightfield {
    int n = 0;                        // texels per side; patches per side = n - 1
    Texels h;                         // n * n [m, local z]
    std::vector<Texels> mip;          // mip[0]: (n-1)^2 patch maxima, then halving to 1 x 1
    std::vector<int> mipSide;         // side of each mip level
    void buildMip(unsigned threads);  // the rows of its large levels on `threads` workers (0 = all cores)
    // The largest error estimate of its patches (gpu::patchErrorEstimateM over each patch with texels i + 2 and
    // j + 2; 0 for none) [m]: the bound without a surface pyramid (error_bound.cpp). Rows on `threads` workers.
    float errorEstimateM(unsigned threads) const;
};

// Levels of at least this many nodes are built on several workers (waking parallelFor's threads costs microseconds).
constexpr size_t kMipParallelNodes = size_t{1} << 16;

struct CascadeTextures {
    Heightfield terrain, water;  // water: surface height where wet (depth > min) or at a shore, else -inf
    Texels depth;                // water depth at texels (0 where dry)
    bool hasWater = false;
    // With water: the larger of the two max mipmaps, level by level (buildBothMip, after both buildMip): the ray walk
    // over both surfaces reads one maximum a node instead of two. Empty: the walk reads both.
    std::vector<Texels> bothMip;
    void buildBothMip(unsigned threads);
    // The larger of the terrain's and (with water) the drawn water's Heightfield::errorEstimateM [m].
    float errorEstimateM(unsigned threads) const;
    // The water at the shores (water_rule.h: shoreLevel), after the texels and before the mipmaps: every texel whose
    // water does not stand above its terrain is made again from its neighbours (so a kept shore texel is too).
    void extendWaterToShores(unsigned threads);
};

// The last frame's textures of a cascade with the same texel size, side and lattice: this frame's texel (i, j)
// is that one's (i + di, j + dj). `tex` may be the textures being filled (updated in place).
struct TexelReuse {
    const Cascade* cascade;
    const CascadeTextures* tex;
    int di, dj;
};

// What one cascade's approximation did, in counts that do not depend on the machine.
struct ApproximationWork {
    uint64_t gaussians = 0;      // kernel evaluations
    uint64_t cellsVisited = 0;   // cells whose squares were examined for texel centres to evaluate
    uint64_t reusedTexels = 0;   // visible texels copied from `reuse`
    uint64_t pyramidTexels = 0;  // visible texels copied from the scene's surface pyramid (and not evaluated again)
    int pyramidLevel = -1;       // the pyramid level whose spacing is the cascade's texel size, -1 when none fits
    uint64_t pyramidInterpolated = 0;  // visible texels interpolated from a coarser pyramid level (interpolateLevels)
    int pyramidInterpolatedUp = 0;     // the most levels above the cascade's one of them was interpolated from
    uint64_t regionsRead = 0;          // out of core: blocks of texels whose cells were read from the grid file
    uint64_t cellsRead = 0;            // out of core: the cells those regions held (kernel margins included)
};

// A cascade's row j as approximate() filled it for a caller that keeps the last frame's texels itself (the GL backend
// out of core keeps them on the GPU): the texels `kept` are the last frame's (TexelReuse: texel i + di of
// its row j + dj), the spans a and b were evaluated; every other texel has no surface. Empty spans end
// below their start.
struct RowFill {
    TexelSpan kept, a, b;
    TexelSpan& span(int k) { return k == 0 ? a : b; }
    const TexelSpan& span(int k) const { return k == 0 ? a : b; }
};

// Widens span `span` (0: a, 1: b) of `row` to hold texels lo .. hi (a span empty before becomes lo .. hi): a backend
// that writes texels approximate() left to it into the textures after all (its atlas has no slot for their tile).
inline void widenSpan(RowFill& row, int span, int lo, int hi) {
    TexelSpan& s = row.span(span);
    if (s.empty())
        s.first = lo, s.last = hi;
    else
        s.first = std::min(s.first, lo), s.last = std::max(s.last, hi);
}

// The texels that approximate() with `tiles` leaves to the caller to copy from the surface pyramid (the GL backend out
// of core copies them on the GPU, from its atlas of pyramid tiles: a page table over them): a table of the tiles of the
// cascade's level that its texels cover, `width` x `height` row-major, and for each the samples copied from it. Texel
// (i, j) of the cascade is sample (originI + i, originJ + j) of the table, counting from its first tile's first sample;
// those of a tile in the table are copied exactly where that tile's `copied` bit is set (every texel of a span to
// evaluate that lies in a stored tile: no other is), under the water rule of surface.h as copySamples() copies them.
struct PyramidTiles {
    int side = 0;      // samples a tile side (a power of two, <= 16); 0: nothing is copied
    size_t plane = 0;  // samples a tile channel (side^2); channel c of a tile at [c * plane]
    int64_t originI = 0, originJ = 0;
    int width = 0, height = 0;  // tiles
    std::vector<const float*>
        tile;  // per table entry: the tile's first sample, nullptr where nothing is copied from it
    std::vector<const float*>
        water;  // its water levels (wet shares a plane after): its own channels 1 and 2, or the
                // water pyramid's tile at the same place in a later step of a scenario; nullptr: dry
    std::vector<uint16_t>
        copied;                  // per entry, `side` rows: bit c of row r set where sample (c, r) is copied to a texel
    std::vector<RowFill> spans;  // per texel row: its spans to evaluate before the copies were taken out (a and b)

    // Texels finer than every level (the cascade's level t < 0) left to the caller to interpolate from level 0, `up` =
    // -t levels above, as PyramidInterpolator does (the GL backend does it on the GPU from its atlas:
    // interpolate.comp), in blocks: a block is the footprint of one level-0 tile in texels, (levelSide << up)^2 of
    // them, and is left to the caller where the Catmull-Rom stencils of all its texels lie in the 3 x 3 level-0 tiles
    // around it and those are all stored, all numbers, and all dry or all wet: there the interpolator takes level 0 and
    // refuses no texel. Every texel of a span to evaluate (`spans`) in a block is the caller's; no other is. They count
    // as interpolated.
    struct Block {
        int64_t i0 = 0, j0 = 0;                       // its first texel (it may lie left of or below texel 0)
        std::array<const float*, 9> tile{}, water{};  // level 0's tiles around it, (dx, dy) in -1..1 at 3 (dy + 1) + dx
                                                      // + 1; water (levels, wet shares a plane after) nullptr: dry
    };
    static constexpr int kMaxBlockUp = 3;  // blocks only up to this many levels below level 0 (a block of 128^2 texels)
    int up = 0;                            // levels from the cascade's up to level 0 (0: no blocks)
    int levelSide = 0;                     // level 0's tile side (samples)
    size_t levelPlane = 0;                 // its samples a channel
    std::vector<Block> blocks;
};

// Calls fn(j, lo, hi, span) for each run of texels lo .. hi of row j that lie in `block` and in span `span` (0: a, 1:
// b) of that row's spans to evaluate (tiles.spans), in a cascade of n texels a side: the texels of the block that are
// the caller's.
template <class Fn>
void forEachBlockRun(const PyramidTiles& tiles, const PyramidTiles::Block& block, int n, Fn&& fn) {
    const int64_t side = int64_t(tiles.levelSide) << tiles.up;
    for (int64_t j = std::max<int64_t>(block.j0, 0); j <= std::min<int64_t>(block.j0 + side - 1, n - 1); ++j) {
        const RowFill& s = tiles.spans[size_t(j)];
        for (int span = 0; span < 2; ++span) {
            const int64_t lo = std::max({int64_t(s.span(span).first), block.i0, int64_t{0}});
            const int64_t hi = std::min({int64_t(s.span(span).last), block.i0 + side - 1, int64_t(n) - 1});
            if (lo <= hi) fn(int(j), int(lo), int(hi), span);
        }
    }
}

// The texels of `block` (approximate() with `tiles` left them to the caller) interpolated on the CPU into tex, as
// approximate() interpolates, for a caller that cannot take them (the GL backend whose atlas has no slot left), and
// each RowFill span of `rows` widened to hold them. Returns the texels written.
uint64_t interpolateBlock(const Scene& scene, const Cascade& c, const PyramidTiles& tiles,
                          const PyramidTiles::Block& block, double waterMinDepthM, CascadeTextures& tex,
                          std::vector<RowFill>& rows);

struct FrameSetup;
// Half a float32 ulp of the scene's largest |height| [m]: a pyramid sample's rounding (the exact surface rounded once).
double pyramidCopyBoundM(const Scene& scene);
// Without a surface pyramid, under an error budget: the bound each level's spacing (finest cell * 2^t, t = 0 up to the
// box's extent) would give a cascade over the box [x0, x1] x [y0, y1] (local m), for the fit
// (ViewVolume::levelErrorIn). Predicted from a probe: the box's surface summed at one spacing (the coarsest that
// resolves it, or coarser where that takes more than 256 texels a side) and its texels' estimate
// (Heightfield::errorEstimateM), which grows with the square of the spacing while the texels resolve the surface; at
// most, and coarser than that, the relief under the box (Scene::reliefM); plus what boundFrame adds. A prediction only:
// the frame's bound is still its own texels' (boundFrame).
std::vector<double> predictLevelErrorM(const Scene& scene, double x0, double y0, double x1, double y1,
                                       double waterMinDepthM, unsigned threads);
// e^x for x <= 0 (-inf included) in float, in arithmetic the vectoriser takes where std::exp is a call a lane (the
// shading's fog, shading.cpp): e^x = 2^n e^r, n the nearest integer to x / ln 2, |r| <= ln 2 / 2. Within 2 float ulps
// of e^x (RenderShading.FogExponentialIsExpWithinTwoUlps). Below -87 (e^-87 ~ 1.6e-38, near the smallest normal float)
// it gives e^-87, which leaves 1 - e^x exactly 1.
float expOfNegative(float x);
// CascadeStats::nearestHitM of every cascade of `timings` from a scan of frame `f`'s hits: the reference the tests hold
// both backends' own counts to (the CPU counts as its rays land, the GL backend's shade.comp as it shades).
void measureNearestHits(const Frame& f, unsigned threads, Timings& timings);
// Each cascade's error bound and the frame's (CascadeStats::errorBoundM, Timings::errorBoundM), once its cascades'
// statistics are final, nearestHitM included (error_bound.cpp; both backends).
void boundFrame(const Scene& scene, const FrameSetup& setup, const CascadeFit& fit, Timings& timings);

// Copies `count` pyramid samples into a row of a cascade's textures with the water rule of surface.h: s the elevations,
// w (nullptr: dry) the water levels with the wet shares at w + plane; NaN elevations (outside every cell) and dry
// texels leave h, depth and water as they are. Returns the texels with a surface.
int copySamples(const float* s, const float* w, size_t plane, int count, float minDepth, float* h, float* depth,
                float* water);

// The RowFill of every row of c with the texels kept from `reuse` (none without), adding their count to `kept`: what
// approximate() with `rows` gives, without evaluating anything (the GL backend in memory sums the texels on the GPU).
std::vector<RowFill> rowFills(const Cascade& c, const TexelReuse* reuse, uint64_t& kept);

// Approximation (approximate.cpp): fills the textures of one cascade. With `reuse`, the visible texels that were
// visible there too are copied; with a scene pyramid at the cascade's texel size, texels whose samples it holds
// are copied from it; the others are evaluated. The cells visited follow the texels evaluated (a few per texel),
// not the cascade's area. With `rows`, the kept texels are not copied and the texels outside every span are not
// written: only the evaluated spans, which go into `rows` with the kept ones (RowFill). With `rows` and `tiles` too,
// the texels copied from the pyramid are not written either but marked in `tiles` (PyramidTiles), and each RowFill span
// shrinks to the texels written (interpolated or summed), from the first to the last of them: the caller copies the
// marked texels itself, after the spans, and interpolates the texels of the blocks listed there (PyramidTiles::Block).
ApproximationWork approximate(const Scene& scene, const Cascade& c, CascadeTextures& tex, double waterMinDepthM,
                              unsigned threads, const TexelReuse* reuse = nullptr, int interpolateLevels = 0,
                              std::vector<RowFill>* rows = nullptr, PyramidTiles* tiles = nullptr);

// One ray through the cascades (raycast.cpp).
struct Hit {
    bool hit = false;
    double t = 0;                   // distance along the ray [m]
    double nx = 0, ny = 0, nz = 1;  // unit normal (unless slopeOnly)
    // The hit is on a smooth surface that rises gx and gy [m] a texel of texelM [m] along x and y, and nx, ny, nz are
    // not set: the caller takes the normal from normalOfSlope(), as castRays does for many hits at once, in vector
    // registers.
    bool slopeOnly = false;
    double gx = 0, gy = 0, texelM = 1;
    double depth = 0;  // water depth at the hit (water hits), else 0
    bool water = false;
    bool wall = false;  // on a cut face of the terrain block (raycast.cpp): a hole's or the domain's edge, the bottom
    int cascade = -1;
};

// The unit normal (-gx, -gy, 1) / |(-gx, -gy, 1)| of a surface with slope (gx, gy) = (riseX, riseY) / texelM [m/m], in
// the operations every hit's normal has always been computed with. IEEE square roots and divisions round the same in
// any vector width; a multiply-add the compiler fuses in one loop and not in another could move a last bit (none did
// in the renders docs/benchmarks.md compares).
inline void normalOfSlope(double riseX, double riseY, double texelM, double& nx, double& ny, double& nz) {
    const double gx = riseX / texelM, gy = riseY / texelM;
    const double nl = std::sqrt(gx * gx + gy * gy + 1.0);
    nx = -gx / nl;
    ny = -gy / nl;
    nz = 1.0 / nl;
}

struct RayContext {
    const CascadeFit* fit;
    const std::vector<CascadeTextures>* tex;
    glm::dvec3 eyeLocal;  // where every ray starts [m, local]
    double nearM, farM;
    double zFloor;  // the terrain block's bottom: the grid's lowest elevation, local z [m]
};

// The rays of a tile of pixels as one beam (raycast.cpp): every ray eye + tau (forward + sx right + sy up) for (sx, sy)
// in a rectangle of the image plane, tau the depth along the camera's forward axis. A march of the beam over a
// cascade's max mipmap finds, for the whole tile at once, a depth before which no ray of the tile comes down to any
// maximum of that cascade; each ray's walk there starts at the patch under that depth instead of at the cascade's
// start. The walk would have skipped every node before it, so the hit is the same (tests: render_hits_test,
// "Beams"), and a ray makes a few visits near its hit instead of the descent from the top (docs/benchmarks.md).
class Beam {
public:
    // (sx0, sy0) and (sx1, sy1): opposite corners of the rectangle, in CameraBasis image-plane units (the pixels'
    // centres at the tile's corners).
    // `outer`: a beam holding this one (its rays a subset), whose start depths this one's marches start from.
    Beam(const RayContext& ctx, const CameraBasis& basis, double sx0, double sy0, double sx1, double sy1,
         Beam* outer = nullptr);
    // The depth tau before which no ray of the beam meets cascade k's surfaces or walls; marched once a tile, when
    // a ray first walks cascade k. Inline: every ray asks twice a cascade, and all but the first find it marched.
    double startDepth(size_t k) {
        if (k < depth_.size() && !std::isnan(depth_[k])) return depth_[k];
        return firstStartDepth(k);
    }
    // True when no ray of the beam meets cascade k at all: its march passed over every depth of the cascade's slab
    // (or the outer beam's did), so a ray's entry into it would only clip its span and walk nothing.
    bool passesOver(size_t k) {
        startDepth(k);
        return k < passed_.size() && passed_[k];
    }

private:
    double firstStartDepth(size_t k);
    double march(size_t k);
    const RayContext& ctx_;
    Beam* outer_;
    glm::dvec3 lo_, hi_;              // the componentwise least and largest of the four corner directions
    double width_ = 0;                // the rectangle's longer side [image-plane units ~ radians]
    double maxLen_ = 1;               // the longest corner direction (t = tau |direction|, |direction| >= 1)
    double minDot_ = 0, maxDot_ = 0;  // the least and largest horizontal rate along the fit's view direction
    double centreLen_ = 1;            // |the centre's direction|
    std::array<double, 8> depth_;     // per cascade (RenderOptions: at most 4); NaN until marched
    std::array<bool, 8> passed_{};    // per cascade: the march passed the whole slab (passesOver)
};

// What each ray's walk through each cascade needs from its direction alone (raycast.cpp): its span there (the
// cascade's slab along the view and its texture's patch domain), its steps in texel coordinates and their reciprocals,
// and the depths where it crosses the cascade's highest point (without water and with it) and the block's bottom.
// setUpRays() computes them for many rays at once in vector registers, in the operations a ray's walk used one at a
// time (the same values up to how the compiler fuses multiply-adds: Render.RaySetupsAreTheWalksOwnClips): a dozen
// divisions at the start of every walk, waited on before its first step (docs/benchmarks.md).
struct RaySetups {
    struct Cascade {
        double u0 = 0, v0 = 0;  // the eye in the cascade's texel coordinates
        std::vector<double> t0, t1, du, dv, invDu, invDv, tTopDry, tTopWet;  // per ray; t0 >= t1: nothing there
    };
    std::vector<Cascade> cascades;  // per cascade of ctx.fit
    std::vector<double> tFloor;     // per ray
};
// The setups of n rays with unit directions (dx[i], dy[i], dz[i]), into `out` (its vectors reused from call to call).
void setUpRays(const RayContext& ctx, size_t n, const double* dx, const double* dy, const double* dz, RaySetups& out);

// dir: unit direction of the ray, setups.*[ray] its setup (setUpRays). With a beam holding the ray (its direction
// before normalising was dirLength times dir), each cascade's walk starts where the beam's march allows.
Hit castRay(const RayContext& ctx, const glm::dvec3& dir, const RaySetups& setups, size_t ray, Beam* beam = nullptr,
            double dirLength = 1);

// What approximateOnCpu() filled of a cascade, for a backend that keeps the last frame's texels itself.
struct CascadeFill {
    std::vector<RowFill> rows;  // per texel row: the texels kept and the spans evaluated
    PyramidTiles tiles;         // with approximateOnCpu's pyramidTiles: the texels left to copy from the pyramid
    int from = -1;       // the last frame's cascade (its index in that frame's fit) whose texels are kept, -1: none
    int di = 0, dj = 0;  // this frame's texel (i, j) is that one's (i + di, j + dj)
};

// Stage 2 on the CPU for a backend that runs the later stages elsewhere and keeps the cascades' texels from one frame
// to the next there (the GL backend over an out-of-core scene, which has no cells or lists to upload, keeps them on the
// GPU): the texels of every cascade that the last frame of `cache` did not hold evaluated as renderFrame() evaluates
// them (from the pyramid and the grid file), without max mipmaps, their statistics appended to timings.cascades and
// their time to timings.approximationMs. Then use(k, textures, fill) for each non-empty cascade: only the texels of
// fill's evaluated spans are defined in `textures`; the kept ones are the backend's to copy from its last frame (the
// one this cache saw), those outside every span have no surface. With `pyramidTiles`, the texels copied from the
// pyramid are left to the backend too (CascadeFill::tiles; approximate() with `tiles`), and `use` may write into the
// textures (the texels it copies there itself). The cache holds the cascades' shapes for the next frame, not their
// texels: it must not be handed to renderFrame().
void approximateOnCpu(const Scene& scene, const CascadeFit& fit, const RenderOptions& options, CascadeCache& cache,
                      Timings& timings, const std::function<void(size_t, CascadeTextures&, CascadeFill&)>& use,
                      bool pyramidTiles = false);
// The same plan without evaluating a texel, for a backend that evaluates them itself (the GL backend in memory): each
// cascade's rows and the last frame's cascade it keeps texels of (CascadeFill), their count in timings.cascades[k]
// (which must hold the frame's cascades) as reusedTexels. The cache holds the cascades' shapes for the next frame.
std::vector<CascadeFill> planCascades(const Scene& scene, const CascadeFit& fit, const RenderOptions& options,
                                      CascadeCache& cache, Timings& timings);

// Per-frame set-up both backends share (renderer.cpp): the eye in the local frame, near and far along the
// ray (the camera's, else from the scene's bounds), and the view volume cascade fitting takes.
struct FrameSetup {
    CameraBasis basis;
    glm::dvec3 eyeLocal;  // the camera, local [m]
    double nearM, farM;
    ViewVolume view;
};
FrameSetup setUpFrame(const Scene& scene, const Camera& camera);
// The camera in the grid's local frame: its position mapped (Grid::worldToLocal; x, y only) and its yaw turned by
// the grid's rotation, so that rays cast in the local frame look where the world camera looks.
Camera localCamera(const Grid& grid, const Camera& camera);
// A finished frame's hit positions and normals turned from the local axes to the CRS's (Frame: offsets from the
// origin along the CRS's axes); nothing to do for a grid without rotation.
void frameToWorldAxes(const Grid& grid, Frame& f);
// The frame's cascades (stage 1 of both backends), with Timings' fittingMs and view direction. A camera below
// the terrain (cameraBelowTerrainM > 0) sees nothing: no cascade is fitted (an empty fit).
CascadeFit fitFrame(const Scene& scene, const Camera& camera, const FrameSetup& setup, const RenderOptions& options,
                    Timings& timings);
// A cascade's extent and texels as Timings reports them (both backends; the work counts are filled by the caller).
CascadeStats statsOf(const Cascade& c);

// Where the legend goes and what it says (drawn by renderFrame() and by shade.comp).
struct LegendLayout {
    bool shown = false;
    bool depth = false;                                 // the water-depth ramp, else the elevation ramp
    bool layer = false;                                 // RenderOptions::colorLayer's ramp (before `depth`)
    int x0 = 0, y0 = 0, barW = 0, barH = 0, scale = 1;  // bar's top-left pixel (row 0 at the top) and size
    std::string hi, lo;                                 // labels at the bar's top and bottom
};
LegendLayout legendLayout(const Scene& scene, const RenderOptions& options, int width, int height);

// What shading computes from a frame's hits on the CPU, on either backend (the GL one uploads it for shade.comp).

// The colour layer's range over the whole scenario (every step's, from the step table; a static layer's from its
// values), so that a colour means the same value in every step.
std::pair<double, double> layerRange(const Grid& g, const influence::Layer& layer);
// The colour layer (RenderOptions::colorLayer) at every hit it colours (f's distanceM, wall, posX, posY, local axes):
// the water's hits (isWater) for a step layer, the terrain's (not walls) for a static one; NaN elsewhere and where the
// field is undefined. One batch through the exact evaluator.
std::vector<float> colorLayerValues(const Scene& scene, const influence::Layer& layer, const RenderOptions& options,
                                    const Frame& f, const std::vector<uint8_t>& isWater);
// The cell outline's factor at pixel i (RenderOptions::cellOutlines): 0.35 where the hit lies within 0.7 pixel
// (pixelAngle [rad] at its distance) of its cell's edge, else 1.
double cellOutlineDim(const Scene& scene, const Frame& f, size_t i, double pixelAngle);

}  // namespace hc::render::detail
