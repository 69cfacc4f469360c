// heightcast/render/renderer.h: the CPU renderer of the smooth surface (docs/design.md section 5).
//
// Per frame: fit cascades to the view (cascades.h), approximate the surface into each cascade's
// texture (the Gaussian RBF sum at every visible texel), build max mipmaps, cast one ray per pixel
// through the cascades near to far with exact ray/bilinear-patch intersection and blending in the
// cascades' overlaps, and shade. All geometry is camera-relative; world coordinates appear only in
// the camera and in the outputs' georeference.
#pragma once

#include <cstdint>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "heightcast/grid/grid.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/influence/influence.h"
#include "heightcast/influence/pyramid.h"
#include "heightcast/influence/surface.h"
#include "heightcast/render/camera.h"

namespace hc::render {

enum class ColorMode { Elevation, WaterDepth };

struct RenderOptions {
    int cascades = 3;          // 1..4
    int texelsPerSide = 1024;  // 16..8192, cascade texture side N
    unsigned threads = 0;      // 0 = all cores
    ColorMode color = ColorMode::Elevation;
    bool cellOutlines = false;     // draw the adaptive cells' edges
    bool legend = true;            // colour bar of the water depth (or elevation) in the image
    double waterMinDepthM = 0.01;  // water thinner than this is not drawn (smoothing spreads depth thinly)
    // With a surface pyramid, texel sizes are its spacings (powers of two of the finest cell). false: the largest
    // not above the size without a pyramid, with up to 2N texels a side (never coarser, so the rendered error is
    // no worse); true: the smallest not below it, N texels (up to 2x coarser: faster, more texels copied, larger
    // rendered error). docs/benchmarks.md measures both.
    bool pyramidCoarseTexels = false;
    // With a surface pyramid: texels finer than every level stored around them (over cells at least twice their size,
    // no finer cell within a kernel's reach) are interpolated (bicubic) from the nearest coarser level stored, at most
    // this many levels up, 0..8; 0 sums them from the kernels. docs/benchmarks.md measures the trade.
    int pyramidInterpolateLevels = 3;
    // Colour by this grid layer instead ("" = by `color`): a further step layer (velocity, ...: a field of the wet
    // cells, influence::Layer::WaterCells) colours the water and leaves dry terrain grey; a static layer colours the
    // terrain. Each hit's value is the exact evaluator's at the hit (in memory only: the scene needs its lists), on
    // a ramp over the layer's range in every step, with a legend in the layer's units. Both backends (GL: the values
    // from the CPU).
    std::string colorLayer;
    // Both backends: the rays of each tile of beamTilePx x beamTilePx pixels start their walks where a march of the
    // tile's beam over the max mipmaps shows none of them can hit before (the same hits; the tiles' marches start from
    // their block's of 4 x 4 tiles; on the GL backend a pass of its own, beams.comp); 0 or 1: every ray walks from its
    // cascade's start. 0..64. docs/benchmarks.md measures it.
    int beamTilePx = 4;
    // The error budget (0: none, the texel sizes as above): with a surface pyramid each cascade takes the coarsest of
    // its spacings whose rendered error over its ground (Scene::levelErrorM of its box) is within maxErrorM [m], or
    // within maxErrorPx pixels at the cascade's nearest point, or both (the smaller), and texels interpolated only from
    // levels within it; far and flat ground coarse, near and rough ground fine. Without a pyramid the errors are
    // predicted (detail::predictLevelErrorM) and the texels never finer than texelsPerSide gives. Timings says what
    // each cascade's bound is and where the texels (up to 2 texelsPerSide a side) could not meet the budget.
    double maxErrorM = 0, maxErrorPx = 0;
    std::string validate() const;  // "" or what is wrong
};

// Per-pixel results, row 0 at the top. Misses: distance +inf, position/normal 0, cascade -1.
struct Frame {
    int width = 0, height = 0;
    std::vector<uint8_t> rgb;             // 8-bit sRGB, 3 per pixel
    std::vector<float> distanceM;         // along the ray [m]; +inf where the ray misses
    std::vector<float> posX, posY, posZ;  // hit position relative to the grid origin [m], along the CRS's axes (for a
                                          // rotated grid too: world = origin + pos)
    std::vector<float> nX, nY, nZ;        // unit surface normal (z up), along the CRS's axes
    std::vector<float> cascade;           // index of the cascade that gave the hit (blend: the nearer), -1 miss
    std::vector<float> waterDepthM;       // water depth at the hit [m], 0 where dry or missed
    // 1 where the hit is on a cut face of the terrain block, else 0. The terrain is drawn as a solid block: the
    // smooth surface on top, vertical walls where the surface ends (the edges of holes and of the domain) down
    // to the grid's lowest elevation, and a flat bottom there. Wall normals are horizontal, the bottom's points
    // down; walls are coloured kWallColor (gpu_layout.h).
    std::vector<float> wall;
    // With RenderOptions::colorLayer: the layer's value at each hit it coloured, NaN elsewhere (EXR channel
    // "layer.NAME"); empty without.
    std::string colorLayer;
    std::vector<float> colorLayerValue;
    double originWorldX = 0, originWorldY = 0;
};

// How far a texel summed from the kernels in float may lie from the exact surface [m] (the tests' tolerance for
// summed texels against the exact evaluator: render_textures_test, TexelsEqualTheExactSurfaceWithin1mm).
constexpr double kSummedTexelErrorM = 1e-3;

struct CascadeStats {
    double nearM = 0, farM = 0;  // offsets along the projected view direction (far includes the overlap)
    double splitFarM = 0;        // where the blend with the next cascade starts
    double texelM = 0;           // texel size
    uint64_t visibleTexels = 0;
    uint64_t gaussians = 0;     // kernel evaluations in the approximation
    uint64_t reusedTexels = 0;  // visible texels copied from the last frame (renderFrame with a CascadeCache)
    uint64_t cellsVisited =
        0;  // CPU: grid cells whose squares the approximation examined for texels to evaluate (0 on GL)
    uint64_t cellsRead =
        0;  // CPU out of core (Scene): cells read from the grid file for the texels summed, kernel margins
    uint64_t regionsRead = 0;          // included, in that many blocks of texels (0 in memory and on GL)
    int pyramidLevel = -1;             // the surface pyramid level whose spacing is texelM, -1 without a pyramid
    uint64_t pyramidTexels = 0;        // visible texels copied from the pyramid's samples (the others: Gaussians)
    uint64_t pyramidInterpolated = 0;  // visible texels interpolated from a coarser level (pyramidInterpolateLevels)
    int pyramidInterpolatedUp = 0;     // the most levels above the texels' own one of them was interpolated from
    // The rendered surface's error against the exact one in this cascade [m]: with a surface pyramid the bilinear
    // patches' error at the texel spacing, or at the coarsest level a texel was interpolated from (Scene::levelErrorM
    // over the cascade's box), plus a float32 rounding of the heights, plus kSummedTexelErrorM where texels were summed
    // from the kernels; without one texelEstimateM plus the same two. errorBoundPx: the same in pixels at the nearest
    // hit that shows its surface (nearestHitM; error_bound.cpp). budgetM: its error budget, 0 none.
    double errorBoundM = 0, errorBoundPx = 0, budgetM = 0;
    // The distance of its nearest hit in the frame [m] (Frame::cascade: the nearer cascade of a blend); +inf where it
    // gave none; NaN where the backend did not measure it (the pixel bound is then charged at the nearest point the
    // fit could bound: Cascade::nearestM, the near plane for a camera below the highest terrain).
    double nearestHitM = std::numeric_limits<double>::quiet_NaN();
    // Without a surface pyramid: the largest error estimate of its patches from its texels alone (terrain and water
    // surface; gpu::patchErrorEstimateM) [m]; NaN with a pyramid.
    double texelEstimateM = std::numeric_limits<double>::quiet_NaN();
    double approximationMs = 0;
};

// verifyFrameError searches for the exact shore on rings of points, each this much (2^(1/8)) wider than the last: a
// distance it measures is up to this factor long.
inline constexpr double kShoreRingStep = 1.0905077326652577;

// What verifyFrameError measured.
struct ErrorCheck {
    uint64_t hits = 0;                       // the hits checked
    double maxM = 0, p99M = 0, medianM = 0;  // |rendered - exact| [m]
    double maxPx = 0;                        // the largest in pixels at its hit's distance
    // The shoreline, with water (`water`): hits drawn on dry ground whose ray came down through the exact water, and
    // hits drawn on water where the exact surface is dry: hits on the other side of the exact shoreline.
    bool water = false;
    uint64_t drawnDryOverWater = 0, drawnWetOverDry = 0;
    // Of those hits: the largest height of water drawn over the exact ground (drawnWetOverDry) [m]; the largest
    // distance to the exact shore [m], and in pixels at its hit's distance, from a hit drawn on water to the nearest
    // exact water and from where a ray drawn dry came down through the exact water to the nearest place without it
    // (measured on rings of points: verify_error.cpp). 0 where none is on the wrong side.
    double shoreMaxM = 0, shoreDistanceM = 0, shoreDistancePx = 0;
};

struct Timings {
    double viewDirX = 0, viewDirY = 1;  // the horizontal direction the cascade offsets are measured along
    double fittingMs = 0, approximationMs = 0, mipmapMs = 0, raycastMs = 0, shadingMs = 0, totalMs = 0;
    // GL backend only (0 on the CPU): the GPU's span from the first stage's start to shading's end, and the
    // copy of the finished frame to host memory (render(); a viewer drawing the texture has none). totalMs is
    // the wall time of the whole call, both included.
    double gpuMs = 0, readbackMs = 0;
    // GL backend: handing the driver each cascade's rows (the texels kept from the last frame, which stay on the GPU,
    // and the spans to evaluate) and, out of core, the texels the CPU evaluated, packed (in totalMs, not in gpuMs); and
    // the bytes handed over.
    double uploadMs = 0;
    uint64_t uploadBytes = 0;
    // GL backend out of core with a pyramid: the texels copied on the GPU from the pyramid tiles resident there (the
    // atlas; the uploads above hold the tiles not yet resident, atlasTilesUploaded of them, the tiles to copy from and
    // the rows' spans), and those interpolated there from level 0's tiles (texels finer than every level: counted in
    // their cascade's pyramidInterpolated too).
    uint64_t atlasTexels = 0, atlasTilesUploaded = 0, atlasInterpolated = 0;
    std::vector<CascadeStats> cascades;
    uint64_t rays = 0, hits = 0;
    // The frame's bound: the largest of its cascades'; and the budget asked (0: none). boundFromTexels: estimated from
    // the texels (CascadeStats::texelEstimateM), the scene having no surface pyramid.
    double errorBoundM = 0, errorBoundPx = 0, maxErrorM = 0, maxErrorPx = 0;
    bool boundFromTexels = false;
    // With water, the shoreline's bound, the largest of its cascades': a patch's diagonal, sqrt(2) times the spacing of
    // the samples its water came from (the texels', or the coarser level's they were interpolated from). The drawn
    // shore lies in the patch between a texel with water and one without, and so does the exact one: the texels are
    // the exact surface's samples (error_bound.cpp). Interpolated texels are not; they are taken to draw their level's
    // shore (an estimate: docs/tools/hc-render.md). Water shallower than RenderOptions::waterMinDepthM is not drawn,
    // and its own edge is not bounded. 0 without water.
    double shoreBoundM = 0, shoreBoundPx = 0;
    std::optional<ErrorCheck> verified;  // the frame's error measured at its hits (verifyFrameError), when asked
    // What the renderer changed from what the options asked, and why (the GL backend's textures held to what its
    // driver allows, say); printed by toTable, "notes" in toJson.
    std::vector<std::string> notes;
    std::string toJson() const;
    std::string toTable() const;
};

// What a frame renders: the grid, its surface pyramid (optional) and how the kernels are reached.
//   In memory: a grid with its influence lists and per-cell data prepared once for many frames (about 300 bytes
//   per cell with the lists; docs/benchmarks.md gives the largest grids that fit).
//   Out of core (docs/design.md section 4): a grid file read a region at a time (GridRegionReader) and no lists: the
//   texels that need the kernels read the cells around them, build their lists and drop them, a block of texels
//   at a time (influence/region.h), so memory follows the cascades, not the grid. The frames are the same bits.
// With a surface pyramid (influence/pyramid.h) cascade texel sizes are the pyramid's spacings (powers of two of the
// finest cell) and texels where the pyramid holds that level are copied from it instead of summed. In a scenario's
// later water steps the pyramid is the base (the first step's, whose elevation every step shares) and a water
// pyramid (the shown step's water channels) gives the water.
class Scene {
public:
    // All must outlive the scene. Throws hc::Error if the lists or the pyramid are not the grid's, or the
    // pyramid's kernel is not the lists'.
    // A water pyramid (channels 2) must be the grid's shown step's, and `pyramid` then the base: whole (3 channels),
    // built for the scenario's first step (Grid::steps[0]). `known`: the grid's hashes as its file checked them (else
    // computed here: a pass over every cell each, which a step switch of a large grid need not pay).
    Scene(const Grid& grid, const influence::InfluenceLists& lists, const influence::SurfacePyramid* pyramid = nullptr,
          const influence::SurfacePyramid* waterPyramid = nullptr, std::optional<GridHashes> known = std::nullopt);
    // Out of core: `file` and `pyramid` must outlive the scene. The bounds come from the file's stored summary
    // (format 1.2; older files are read whole once by GridRegionReader). Throws hc::Error if the pyramid is not the
    // file's grid's or was built for another kernel.
    Scene(const GridRegionReader& file, const influence::KernelParams& params,
          const influence::SurfacePyramid* pyramid = nullptr, const influence::SurfacePyramid* waterPyramid = nullptr);

    bool outOfCore() const { return file_ != nullptr; }
    // The grid: in memory its cells; out of core its shape only (geometry, CRS, layers; no cells).
    const Grid& grid() const { return grid_; }
    const GridRegionReader* file() const { return file_; }  // out of core, else nullptr
    uint64_t cellCount() const { return cellCount_; }
    const influence::KernelParams& params() const { return params_; }
    // In memory only (throws hc::Error out of core).
    const influence::InfluenceLists& lists() const;
    const influence::SurfacePyramid* pyramid() const { return pyramid_; }
    const influence::SurfacePyramid* waterPyramid() const { return waterPyramid_; }  // nullptr: the pyramid's own water
    // With a pyramid: per level, the error of drawing the surface (and the water level) as the bilinear interpolant of
    // that level's samples (influence::bilinearErrorByLevelM, the larger of the channels), plus the samples' float32
    // rounding [m]; empty without. Over the whole domain, and over a box [x0, x1] x [y0, y1] of local metres from the
    // tiles near it (influence::RegionalLevelErrors): what a cascade over that box carries.
    const std::vector<double>& levelErrorM() const { return levelErrorM_; }
    std::vector<double> levelErrorM(double x0, double y0, double x1, double y1) const;
    // Without those level errors a frame's bound comes from its own texels (error_bound.cpp), which then estimate it,
    // and an error budget's texel sizes from a prediction (detail::predictLevelErrorM).
    bool boundFromTexels() const { return levelErrorM_.empty(); }
    // Without a pyramid: the largest range of the cell values (elevations, and water levels of wet cells) whose kernels
    // reach a square of side spanM [m] with a corner in the box [x0, x1] x [y0, y1] of local metres: a bound of the
    // error of a bilinear patch of that side there (the exact surface and the patch are both convex combinations of
    // those values), from 64 x 64 regions over the domain in memory, the whole grid's range out of core.
    double reliefM(double x0, double y0, double x1, double y1, double spanM) const;
    bool hasWater() const { return waterLayer_ >= 0; }
    int waterLayer() const { return waterLayer_; }  // grid layer of water_depth, or -1
    // Per cell, computed once for every frame (in memory; out of core per region): centre [m local] and the
    // kernel's 1 / (2 sigma^2 c^2) and squared radius, in the form the approximation reads.
    struct CellKernel {
        double cx, cy;
        float a, r2;
    };
    static std::vector<CellKernel> kernelsOf(const Grid& grid, const influence::KernelParams& params);
    const std::vector<CellKernel>& kernels() const { return kernels_; }  // empty out of core
    // Local bounding box of the cells and the value range (terrain and water surface) [m]. Out of core the
    // water surface's top is bounded by the largest elevation plus the largest depth (the summary has no more).
    double xMin, yMin, xMax, yMax, zMin, zMax;
    double elevationMin, elevationMax, depthMax;
    // The water colours' scale [m]: the largest depth of every water step of the scenario (Grid::steps), not only
    // the shown one's, so that a colour means the same depth in every step of a sequence.
    double depthColorMaxM = 0;
    // The smooth terrain's height at a local point [m] (the RBF sum of docs/design.md section 3 over the list of
    // the cell containing it, as the approximation evaluates it, in double), or nullopt outside every cell.
    std::optional<double> terrainAt(double xLocal, double yLocal) const;
    // The square of the cell containing a local point, or nullopt (holes, outside the domain).
    std::optional<Grid::Square> cellSquareAt(double xLocal, double yLocal) const;
    // The exact evaluator over the grid and its lists, made on first use (in memory only: throws hc::Error out of
    // core): what RenderOptions::colorLayer's values come from.
    const influence::SurfaceEvaluator& evaluator() const;

private:
    const Grid& grid_;
    const influence::InfluenceLists* lists_ = nullptr;
    const GridRegionReader* file_ = nullptr;
    const influence::SurfacePyramid* pyramid_ = nullptr;
    const influence::SurfacePyramid* waterPyramid_ = nullptr;
    influence::KernelParams params_;
    uint64_t cellCount_ = 0;
    int waterLayer_ = -1;
    std::vector<CellKernel> kernels_;
    std::vector<double> levelErrorM_;
    influence::RegionalLevelErrors terrainErrors_, waterErrors_;
    double roundingErrorM_ = 0;
    void boundLevels();
    // reliefM's regions (in memory, without a pyramid): reliefSide_^2 of side reliefRegionM_, per region the least
    // and largest value of the cells whose kernel reach square meets it.
    int reliefSide_ = 0;
    double reliefRegionM_ = 0;
    std::vector<float> reliefMin_, reliefMax_;
    int reliefRegionAt(double x) const;  // the region column (or row) of a local coordinate [m], clamped to the grid's
    void boundRelief();
    mutable std::once_flag evaluatorMade_;
    mutable std::unique_ptr<influence::SurfaceEvaluator> evaluator_;
};

// Cascade textures kept from one frame to the next (docs/design.md section 5, incremental cascades). Stable fitting
// keeps a cascade's texel size and lattice while the camera moves a little, so most of a frame's visible texels
// were visible in the last one: renderFrame() copies those and evaluates only the newly exposed ones. A cascade
// is reused only with the same scene, texel size, texture side and water threshold; anything else starts afresh.
// One cache per stream of frames (the viewer's worker); not for two threads at once.
namespace detail {
struct CacheAccess;
}

class CascadeCache {
public:
    CascadeCache();
    ~CascadeCache();
    CascadeCache(const CascadeCache&) = delete;
    CascadeCache& operator=(const CascadeCache&) = delete;
    void clear();  // the next frame evaluates every texel
    struct Impl;

private:
    friend Frame renderFrame(const Scene&, const Camera&, const RenderOptions&, Timings&, CascadeCache*);
    friend struct detail::CacheAccess;  // the GL backend out of core keeps its cascades' shapes here
                                        // (detail::approximateOnCpu)
    std::unique_ptr<Impl> impl_;
};

// How far the camera is under the smooth terrain surface [m]: > 0 when it stands over a cell and below the
// surface there (inside the solid terrain, where every ray starts inside it and sees nothing), else <= 0;
// 0 over a hole or outside the domain. With a near plane given (Camera::nearM > 0) rays start there, not at
// the camera: then 0 as well.
double cameraBelowTerrainM(const Scene& scene, const Camera& camera);

// Renders one frame. A camera below the terrain (cameraBelowTerrainM > 0) sees nothing: the frame is all sky
// (every ray misses), and no cascade is fitted or evaluated (Timings::cascades is empty).
// Throws hc::Error for invalid camera or options. With a cache, reuses the texels the last
// frame of that cache evaluated (the same picture, to float rounding) and leaves this frame's there.
Frame renderFrame(const Scene& scene, const Camera& camera, const RenderOptions& options, Timings& timings,
                  CascadeCache* cache = nullptr);

// The rendered surface against the exact one (surface.h) at `samples` hits of a frame (spread evenly over the hits
// not on a wall; all of them if fewer): each hit's height against the exact terrain there, or the exact water level
// where it hit water. The error bound of the frame's Timings should lie above every one (error_bound.cpp); a caller
// keeps it in Timings::verified.
ErrorCheck verifyFrameError(const Scene& scene, const Camera& camera, const Frame& frame, size_t samples,
                            unsigned threads = 0);

// A camera that frames the whole grid obliquely, as a person would pick: from the south-south-west,
// 35 degrees down, far enough back that the grid's extent fills the view.
Camera overviewCamera(const Scene& scene, int width, int height);

}  // namespace hc::render
