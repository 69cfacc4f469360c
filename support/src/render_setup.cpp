#include "heightcast/support/render_setup.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <vector>

#include <fmt/format.h>

#include "heightcast/core/error.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/influence/surface.h"

namespace hc::cli {

void RenderSetup::addCameraOptions(Parser& p, const std::string& alsoExclusive) {
    p.option("--camera", "X,Y,Z,YAW,PITCH,FOV[,ROLL]",
             "camera position [m], yaw, pitch, vertical field of view and roll (default 0) [degrees]", cameraText);
    p.option("--look-at", "EX,EY,EZ,TX,TY,TZ[,FOV]",
             "camera at the eye E looking at the target T [m] (FOV default 50 degrees)", lookAt);
    p.option("--near", "M",
             "near clipping distance along each ray [m] (default: the far distance / 1e7, at least 1 mm)", nearM);
    p.option("--far", "M", "far clipping distance along each ray [m] (default: the scene's farthest corner)", farM);
    if (alsoExclusive.empty())
        p.exclusive({"--camera", "--look-at"});
    else
        p.exclusive({"--camera", "--look-at", alsoExclusive});
}

void RenderSetup::addRenderOptions(Parser& p) {
    p.option("--size", "WxH", "image size in pixels (default " + size + ")", size);
    p.option("--cascades", "K", "number of cascades, 1..4 (default 3)", options.cascades);
    p.option("--texels", "N", "texels per cascade side, 16..8192 (default 1024)", options.texelsPerSide);
    p.option("--threads", "N", "worker threads (default 0 = all cores)", options.threads);
    p.option("--color", "MODE",
             "elevation (hypsometric terrain, water by depth) or water_depth (grey terrain) (default elevation)",
             color);
    p.option(
        "--color-by", "LAYER",
        "colour by this grid layer, with its legend (hc-info lists them): a step layer such as velocity\n"
        "colours the water (its wet cells' field) and leaves dry land grey, a static layer colours the terrain; the\n"
        "exact surface at every hit, so the grid is read whole with its influence cache; CPU backend (default none)",
        colorBy);
    p.flag("--cells", "overlay the outlines of the adaptive cells", cells);
    p.flag("--no-legend", "leave the colour bar out", noLegend);
    p.option("--cache", "C.hci",
             "influence cache: the grid is read whole with its lists (default: the grid's path with .hci when\n"
             "that exists and no surface pyramid is beside the grid; rebuilt if stale)",
             cachePath);
    p.flag("--out-of-core",
           "read the grid a region at a time, without lists (the default when a surface pyramid or no cache\n"
           "      is beside the grid): memory follows the cascades, not the grid (105 M cells: 0.8 GB); the GL\n"
           "      backend then evaluates the texels a frame newly sees on the CPU, keeps its cascades on the GPU,\n"
           "      and draws no --cells",
           outOfCore);
    p.exclusive({"--cache", "--out-of-core"});
    p.option("--pyramid", "P.hcp",
             "surface pyramid (hc-influence) to copy texels from (default: the grid's path with .hcp, used if\n"
             "valid; cascade texel sizes are then its spacings, powers of two of the finest cell)",
             pyramidPath);
    p.flag("--no-pyramid", "sum every texel from the kernels, even with a pyramid beside the grid", noPyramid);
    p.flag("--pyramid-coarse",
           "with a pyramid: texels up to 2x coarser than without one (N a side: faster, less accurate)\n"
           "instead of up to 2x finer (up to 2N a side: as accurate as without a pyramid, or more)",
           options.pyramidCoarseTexels);
    p.option("--pyramid-interpolate", "L",
             "with a pyramid: texels finer than every level stored around them (over cells at least\n"
             "twice their size, no finer cell within a kernel's reach) are interpolated, bicubic, from a stored level "
             "at most\n"
             "L above; 0..8, 0 sums them from the kernels (default 3)",
             options.pyramidInterpolateLevels);
    p.option("--max-error", "M",
             "error budget [m]: with a surface pyramid each cascade takes the coarsest of its spacings whose\n"
             "rendered error is within M of the exact surface (far and flat ground coarse, near and rough fine;\n"
             "without one, predicted from a coarse probe); the summary says the frame's bound and where the texels\n"
             "could not meet it (default 0: none, texel sizes as --texels gives them)",
             options.maxErrorM);
    p.option("--max-error-px", "P",
             "error budget [pixels]: the same, each cascade within P pixels at its nearest point; with\n"
             "--max-error, the smaller of the two (default 0: none)",
             options.maxErrorPx);
    p.option("--beam-tile", "P",
             "each tile of P x P pixels marches its rays' beam over the max mipmaps first (both backends), and\n"
             "its rays start their walks where none of them can hit before (the same hits, fewer node visits); 0..64,\n"
             "0 walks every ray from its cascade's start (default 4)",
             options.beamTilePx);
    p.option("--step", "K", "water step to show, 0-based (default 0; hc-info lists a grid's steps and their times)",
             step);
    p.option("--sigma", "S", "kernel width in cell sizes (default 1.0)", params.sigma);
    p.option("--truncation", "R", "kernel cut-off in sigmas (default 3.5)", params.truncation);
}

void parseSize(const std::string& text, int& width, int& height) {
    auto wh = text.find('x');
    if (wh == std::string::npos) throw Error("--size " + text + ": expected WxH, e.g. 1920x1080");
    const double w = parseNumber(text.substr(0, wh), "--size"), h = parseNumber(text.substr(wh + 1), "--size");
    if (w != std::floor(w) || h != std::floor(h) || w < 1 || h < 1 || w > 16384 || h > 16384)
        throw Error("--size " + text + ": width and height must be whole numbers in 1..16384");
    width = int(w), height = int(h);
}

void RenderSetup::finish() {
    if (color == "elevation")
        options.color = render::ColorMode::Elevation;
    else if (color == "water_depth")
        options.color = render::ColorMode::WaterDepth;
    else
        throw Error("--color " + color + ": use elevation or water_depth");
    if (colorBy == "elevation" || colorBy == "water_depth" || colorBy == "water_surface")
        throw Error("--color-by " + colorBy +
                    ": use --color elevation or water_depth for those; --color-by takes a further layer");
    options.colorLayer = colorBy;
    if (!colorBy.empty() && outOfCore)
        throw Error("--color-by needs the grid in memory with its influence lists: leave out --out-of-core");
    options.cellOutlines = cells;
    options.legend = !noLegend;
    if (std::string why = options.validate(); !why.empty()) throw Error(why);
    if (std::string why = params.validate(); !why.empty()) throw Error("--sigma/--truncation: " + why);
    parseSize(size, width, height);
    std::vector<double> cam, look;
    auto num = [](double v) { return fmt::format("{:g}", v); };
    if (!(nearM >= 0) || !std::isfinite(nearM)) throw Error("--near " + num(nearM) + ": must be a distance >= 0 m");
    if (!(farM >= 0) || !std::isfinite(farM)) throw Error("--far " + num(farM) + ": must be a distance >= 0 m");
    if (farM > 0 && nearM >= farM) throw Error("--far " + num(farM) + " m is not beyond --near " + num(nearM) + " m");
    if (!cameraText.empty()) cam = parseNumberList(cameraText, "--camera", 6, 7);
    if (!lookAt.empty()) look = parseNumberList(lookAt, "--look-at", 6, 7);
    camera.reset();
    if (!cam.empty()) {
        render::Camera c;
        c.xWorld = cam[0], c.yWorld = cam[1], c.zWorld = cam[2];
        c.yawDeg = cam[3], c.pitchDeg = cam[4], c.fovYDeg = cam[5];
        if (cam.size() > 6) c.rollDeg = cam[6];
        c.width = width, c.height = height;
        camera = c;
    } else if (!look.empty()) {
        camera = render::Camera::lookAt({look[0], look[1], look[2]}, {look[3], look[4], look[5]},
                                        look.size() > 6 ? look[6] : 50.0, width, height);
    }
    if (camera) camera->validate();
}

namespace {

// The pyramid of the scene's current step (read when valid, saying which or why none is used) and a new scene over
// the grid or the file. `quiet`: say only what went wrong (the later steps of a sequence).
void attachScene(const char* program, LoadedScene& s, const std::string& gridPath, const RenderSetup& setup,
                 size_t step, bool quiet) {
    s.scene.reset();
    s.pyramid.reset();  // the base pyramid (the first step's) serves every later step: kept
    const size_t stepCount = s.file ? s.file->shape().stepCount() : s.grid.stepCount();
    const std::string pyramidPath =
        setup.pyramidPath.empty() ? influence::defaultPyramidPath(gridPath, step, stepCount) : setup.pyramidPath;
    std::error_code ec;
    const bool pyramidExists = std::filesystem::exists(pyramidPath, ec);
    if (setup.noPyramid) {
        if (!quiet) std::fprintf(stderr, "%s: --no-pyramid: every texel summed from the kernels\n", program);
    } else if (!pyramidExists) {
        if (!quiet)
            std::fprintf(
                stderr, "%s: no surface pyramid at %s: every texel summed from the kernels (hc-influence writes one)\n",
                program, pyramidPath.c_str());
    } else {
        try {
            s.pyramid = s.file     ? influence::readSurfacePyramid(pyramidPath, s.file->info(), setup.params)
                        : s.hashes ? influence::readSurfacePyramid(pyramidPath, s.grid, s.hashes->structure,
                                                                   s.hashes->content, setup.params)
                                   : influence::readSurfacePyramid(pyramidPath, s.grid, setup.params);
            // A later step's water pyramid: the terrain comes from the first step's (influence/pyramid.h).
            std::string basePath;
            if (s.pyramid->waterOnly()) {
                const Grid& shape = s.file ? s.file->shape() : s.grid;
                const uint64_t structure = s.file     ? s.file->info().structureHash
                                           : s.hashes ? s.hashes->structure
                                                      : s.grid.structureHash();
                basePath = influence::defaultPyramidPath(gridPath, 0, stepCount);
                if (shape.steps.empty())
                    throw Error(pyramidPath + ": a water pyramid, but the grid has no water steps");
                try {
                    if (!s.basePyramid)
                        s.basePyramid = influence::readSurfacePyramid(basePath, shape, structure,
                                                                      shape.steps[0].contentHash, setup.params);
                } catch (const Error& e) {
                    s.pyramid.reset();
                    throw Error(
                        pyramidPath +
                        " holds this step's water only and its base, the first step's pyramid, is not usable (" +
                        e.what() + ")");
                }
            }
            if (!quiet)
                std::fprintf(stderr, "%s: using surface pyramid %s%s\n", program, pyramidPath.c_str(),
                             basePath.empty() ? "" : (" (water; terrain from " + basePath + ")").c_str());
        } catch (const Error& e) {
            if (!setup.pyramidPath.empty()) throw;
            s.pyramid.reset();
            std::fprintf(stderr, "%s: %s: not used, every texel summed from the kernels (hc-influence rebuilds it)\n",
                         program, e.what());
        }
    }
    // An error budget reads the pyramid's measured level errors; without them the texel sizes come from a prediction
    // (detail::predictLevelErrorM), and the user is told.
    if (!s.pyramid && !quiet && (setup.options.maxErrorM > 0 || setup.options.maxErrorPx > 0))
        std::fprintf(stderr,
                     "%s: note: without the surface pyramid (hc-influence writes it) --max-error and --max-error-px "
                     "choose texel sizes from a prediction, a coarse probe of each cascade's ground; the accuracy line "
                     "gives the bound the texels carry\n",
                     program);
    const bool waterOnly = s.pyramid && s.pyramid->waterOnly();
    const influence::SurfacePyramid* base = waterOnly ? &*s.basePyramid : s.pyramid ? &*s.pyramid : nullptr;
    const influence::SurfacePyramid* water = waterOnly ? &*s.pyramid : nullptr;
    s.scene = s.file ? std::make_unique<render::Scene>(*s.file, setup.params, base, water)
                     : std::make_unique<render::Scene>(s.grid, s.lists, base, water, s.hashes);
}

}  // namespace

std::unique_ptr<LoadedScene> loadScene(const char* program, const std::string& gridPath, const RenderSetup& setup,
                                       bool allowOutOfCore) {
    // A pyramid asked for by name must exist (checked before any work); the default one is optional.
    std::error_code ec;
    if (!setup.noPyramid && !setup.pyramidPath.empty() && !std::filesystem::exists(setup.pyramidPath, ec))
        throw Error(setup.pyramidPath + ": no such file");
    // So must a --color-by layer (from the header and META alone: no cells read, no lists built).
    if (!setup.colorBy.empty()) (void)influence::Layer::byName(readGridInfo(gridPath).shape, setup.colorBy);
    const std::string cachePath = setup.cachePath.empty() ? influence::defaultCachePath(gridPath) : setup.cachePath;
    // The default is the cheaper path that draws the same image: out of core where a pyramid serves the texels (only
    // the regions a frame needs are read, not the grid and its cache whole) or where there is no cache to read.
    const bool cacheBeside = std::filesystem::exists(cachePath, ec);
    bool pyramidBeside = false;  // and belonging to the grid: a stale one serves nothing
    if (!setup.noPyramid && allowOutOfCore && !setup.outOfCore && setup.cachePath.empty() && cacheBeside) {
        const GridFileInfo info = readGridInfo(gridPath, setup.step);
        pyramidBeside = influence::pyramidBelongsTo(
            setup.pyramidPath.empty() ? influence::defaultPyramidPath(gridPath, setup.step, info.shape.stepCount())
                                      : setup.pyramidPath,
            info, setup.params);
    }
    const bool outOfCore =
        setup.outOfCore || (allowOutOfCore && setup.cachePath.empty() && (!cacheBeside || pyramidBeside));
    auto s = std::make_unique<LoadedScene>();
    if (outOfCore) {
        s->file = std::make_unique<GridRegionReader>(gridPath, setup.step);
        if (setup.outOfCore)
            std::fprintf(stderr, "%s: --out-of-core: the grid is read a region at a time, without an influence cache\n",
                         program);
        else if (pyramidBeside)
            std::fprintf(stderr,
                         "%s: the surface pyramid serves the texels: the grid is read a region at a time (out of "
                         "core);\n  the influence cache %s is not read (--cache %s reads the grid whole with it)\n",
                         program, cachePath.c_str(), cachePath.c_str());
        else
            std::fprintf(stderr,
                         "%s: no influence cache at %s: the grid is read a region at a time (out of core; hc-influence "
                         "writes a cache,\n"
                         "  --cache %s builds one here)\n",
                         program, cachePath.c_str(), cachePath.c_str());
    } else {
        s->grid = readGrid(gridPath, nullptr, setup.step);
        std::string note;
        s->lists = influence::loadOrBuildCache(s->grid, setup.params, cachePath, setup.options.threads, true, note);
        std::fprintf(stderr, "%s: %s\n", program, note.c_str());
        if (s->grid.steps.size() > 1) {  // steps to switch: hash the cells and static values once (readGridStep)
            s->digests = staticDigestsOf(s->grid);
            s->hashes = GridHashes{s->digests->structureHash, s->grid.steps[setup.step].contentHash};
        }
    }
    attachScene(program, *s, gridPath, setup, setup.step, false);
    return s;
}

void switchStep(const char* program, LoadedScene& s, const std::string& gridPath, const RenderSetup& setup,
                size_t step) {
    s.scene.reset();  // it refers to the grid or file replaced here
    if (s.file)
        s.file = std::make_unique<GridRegionReader>(gridPath, step);
    else
        readGridStep(gridPath, s.grid, step, s.digests ? &*s.digests : nullptr);
    if (s.digests) s.hashes = GridHashes{s.digests->structureHash, s.grid.steps.at(step).contentHash};
    attachScene(program, s, gridPath, setup, step, true);
}

render::Camera initialCamera(const RenderSetup& setup, const render::Scene& scene) {
    render::Camera c = setup.camera ? *setup.camera : render::overviewCamera(scene, setup.width, setup.height);
    c.nearM = setup.nearM, c.farM = setup.farM;  // validated by finish()
    return c;
}

}  // namespace hc::cli
