// heightcast/support/render_setup.h: what hc-render and hc-view share: their rendering and camera options (parsed,
// explained and validated the same way), the grid + influence cache + scene loading, and the camera.
#pragma once

#include <memory>
#include <optional>
#include <string>

#include "heightcast/support/cli.h"
#include "heightcast/grid/grid.h"
#include "heightcast/influence/influence.h"
#include "heightcast/influence/pyramid.h"
#include "heightcast/render/camera.h"
#include "heightcast/render/renderer.h"

namespace hc::cli {

struct RenderSetup {
    std::string cachePath, pyramidPath, cameraText, lookAt, size, color = "elevation", colorBy;
    render::RenderOptions options;
    influence::KernelParams params;
    bool cells = false, noLegend = false, noPyramid = false, outOfCore = false;
    double nearM = 0, farM = 0;  // --near, --far [m]; 0: from the scene
    unsigned step = 0;           // --step: the water step shown

    // Set by finish():
    int width = 0, height = 0;             // from --size [pixels]
    std::optional<render::Camera> camera;  // from --camera or --look-at, validated; empty: the overview

    explicit RenderSetup(std::string defaultSize) : size(std::move(defaultSize)) {}
    // --camera, --look-at (exclusive with each other and with `alsoExclusive`, e.g. "--view"), --near, --far.
    void addCameraOptions(Parser& p, const std::string& alsoExclusive = "");
    // --size, --cascades, --texels, --threads, --color, --cells, --no-legend, --cache, --out-of-core, --pyramid,
    // --no-pyramid, --max-error, --max-error-px, --step, --sigma, --truncation.
    void addRenderOptions(Parser& p);
    // After Parser::parse: validates every option and the camera's numbers (before any expensive work).
    // Throws hc::Error naming the option.
    void finish();
};

// "WxH" -> whole numbers in 1..16384; throws hc::Error naming --size.
void parseSize(const std::string& text, int& width, int& height);

// A grid, its influence lists (read from the cache, or built and written there) and the scene over them, or (out
// of core) the grid file read a region at a time, kept together: the scene refers to them.
struct LoadedScene {
    Grid grid;
    influence::InfluenceLists lists;
    std::unique_ptr<GridRegionReader> file;  // out of core; then grid and lists stay empty
    std::optional<influence::SurfacePyramid> pyramid;
    std::optional<influence::SurfacePyramid>
        basePyramid;  // where `pyramid` is a later step's water pyramid: the first step's
    // In memory, a grid of several water steps: its digests (hashed once at load) and the shown step's hashes (from the
    // file's step table, checked as the step was read): a step switch hashes the step's values only.
    std::optional<StaticDigests> digests;
    std::optional<GridHashes> hashes;
    std::unique_ptr<render::Scene> scene;
};
// Out of core (--out-of-core; or, where `allowOutOfCore` and no --cache is named, no cache beside the grid or a surface
// pyramid beside it, built for it (influence::pyramidBelongsTo), to serve the texels): opens the grid file for region
// reads (render::Scene), saying so and why. In memory (--cache, a cache beside the grid and no pyramid, or not
// `allowOutOfCore`: --color-by needs the lists): reads the grid, loads or (re)builds the cache saying why on stderr as
// "PROGRAM: NOTE". Then reads the surface pyramid (default: the grid's path with .hcp) when there is a valid one
// (saying which, or why none is used: missing, stale or damaged ones are not rebuilt here: hc-influence does), and
// prepares the scene, all for water step setup.step (the step's own pyramid: influence::defaultPyramidPath; a later
// step's water pyramid with the first step's as its base). Throws hc::Error.
std::unique_ptr<LoadedScene> loadScene(const char* program, const std::string& gridPath, const RenderSetup& setup,
                                       bool allowOutOfCore);

// Moves a loaded scene to water step `step`: in memory the grid reads that step's section only (the lists stay: they
// depend on the structure alone); out of core a reader of that step. Then that step's pyramid and a new scene (notes
// only for problems). Throws hc::Error.
void switchStep(const char* program, LoadedScene& s, const std::string& gridPath, const RenderSetup& setup,
                size_t step);

// The camera the options gave, or the overview framing the whole grid; of the given size, with --near/--far.
render::Camera initialCamera(const RenderSetup& setup, const render::Scene& scene);

}  // namespace hc::cli
