// hc-render: a picture (PNG, and EXR layers) of the smooth surface of a grid from a camera.
#include <chrono>
#include <optional>
#include <cstdio>
#include <vector>

#include "cli.h"
#include "heightcast/grid/atomic_file.h"
#include "heightcast/grid/error.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/render/image_io.h"
#include "heightcast/render/renderer.h"


int main(int argc, char** argv) {
    return hc::cli::run("hc-render", [&] {
        std::string gridPath, cachePath, cameraText, lookAt, view, size = "1280x720", out, exr, timingsPath, color = "elevation";
        hc::render::RenderOptions options;
        hc::influence::KernelParams params;
        bool cells = false, noLegend = false;
        hc::cli::Parser p("hc-render", "GRID.hcg -o OUT.png [--camera X,Y,Z,YAW,PITCH,FOV | --look-at EX,EY,EZ,TX,TY,TZ[,FOV] | --view overview] [options]",
                          "Ray-casts the smooth surface of a grid (terrain, and water where the grid has water_depth) into a PNG\n"
                          "and optionally EXR layers, and prints per-stage timings. Coordinates in the grid's CRS [m]; angles in\n"
                          "degrees: yaw 0 looks north, 90 east; pitch negative looks down.");
        p.positional("GRID.hcg", "grid file", gridPath);
        p.option("-o", "OUT.png", "colour image, 8-bit sRGB PNG (required)", out);
        p.option("--camera", "X,Y,Z,YAW,PITCH,FOV", "camera position [m], yaw, pitch and vertical field of view [degrees]", cameraText);
        p.option("--look-at", "EX,EY,EZ,TX,TY,TZ[,FOV]", "camera at the eye E looking at the target T [m] (FOV default 50 degrees)", lookAt);
        p.option("--view", "overview", "a camera framing the whole grid obliquely from the south-south-west (the default)", view);
        p.option("--size", "WxH", "image size in pixels (default 1280x720)", size);
        p.option("--exr", "OUT.exr", "also write float layers: Z, P.X/Y/Z, N.X/Y/Z, cascade, water_depth", exr);
        p.option("--timings", "OUT.json", "also write the per-stage timings as JSON", timingsPath);
        p.option("--cascades", "K", "number of cascades, 1..4 (default 3)", options.cascades);
        p.option("--texels", "N", "texels per cascade side, 16..8192 (default 1024)", options.texelsPerSide);
        p.option("--threads", "N", "worker threads (default 0 = all cores)", options.threads);
        p.option("--color", "MODE", "elevation (hypsometric terrain, water by depth) or water_depth (grey terrain) (default elevation)", color);
        p.flag("--cells", "overlay the outlines of the adaptive cells", cells);
        p.flag("--no-legend", "leave the colour bar out", noLegend);
        p.option("--cache", "C.hci", "influence cache (default: the grid's path with .hci; built if missing or stale)", cachePath);
        p.option("--sigma", "S", "kernel width in cell sizes (default 1.0)", params.sigma);
        p.option("--truncation", "R", "kernel cut-off in sigmas (default 3.5)", params.truncation);
        p.exclusive({"--camera", "--look-at", "--view"});
        if (!p.parse(argc, argv)) return 0;
        if (out.empty()) throw hc::Error("no output image: give -o OUT.png");
        if (!view.empty() && view != "overview") throw hc::Error("--view " + view + ": the only view is 'overview'");
        if (color == "elevation") options.color = hc::render::ColorMode::Elevation;
        else if (color == "water_depth") options.color = hc::render::ColorMode::WaterDepth;
        else throw hc::Error("--color " + color + ": use elevation or water_depth");
        options.cellOutlines = cells;
        options.legend = !noLegend;
        if (std::string why = options.validate(); !why.empty()) throw hc::Error(why);
        if (std::string why = params.validate(); !why.empty()) throw hc::Error("--sigma/--truncation: " + why);
        auto wh = size.find('x');
        if (wh == std::string::npos) throw hc::Error("--size " + size + ": expected WxH, e.g. 1920x1080");
        const double w = hc::cli::parseNumber(size.substr(0, wh), "--size"), h = hc::cli::parseNumber(size.substr(wh + 1), "--size");
        if (w != std::floor(w) || h != std::floor(h) || w < 1 || h < 1 || w > 16384 || h > 16384)
            throw hc::Error("--size " + size + ": width and height must be whole numbers in 1..16384");
        for (const std::string* o : {&out, &exr, &timingsPath})
            if (!o->empty()) {
                hc::cli::checkWritable(*o, "output");
                hc::cli::checkNotSame(*o, gridPath, "output");
            }
        // Validate the camera's numbers before any expensive work.
        std::vector<double> cam, look;
        if (!cameraText.empty()) cam = hc::cli::parseNumberList(cameraText, "--camera", 6, 6);
        if (!lookAt.empty()) look = hc::cli::parseNumberList(lookAt, "--look-at", 6, 7);
        std::optional<hc::render::Camera> given;
        if (!cam.empty()) {
            hc::render::Camera c;
            c.xWorld = cam[0], c.yWorld = cam[1], c.zWorld = cam[2];
            c.yawDeg = cam[3], c.pitchDeg = cam[4], c.fovYDeg = cam[5];
            c.width = int(w), c.height = int(h);
            given = c;
        } else if (!look.empty()) {
            given = hc::render::Camera::lookAt({look[0], look[1], look[2]}, {look[3], look[4], look[5]}, look.size() > 6 ? look[6] : 50.0,
                                               int(w), int(h));
        }
        if (given) given->validate();

        hc::Grid grid = hc::readGrid(gridPath);
        if (cachePath.empty()) cachePath = hc::influence::defaultCachePath(gridPath);
        std::string note;
        auto lists = hc::influence::loadOrBuildCache(grid, params, cachePath, options.threads, true, note);
        std::fprintf(stderr, "hc-render: %s\n", note.c_str());
        hc::render::Scene scene(grid, lists);
        const hc::render::Camera camera = given ? *given : hc::render::overviewCamera(scene, int(w), int(h));

        hc::render::Timings timings;
        hc::render::Frame frame = hc::render::renderFrame(scene, camera, options, timings);
        hc::render::writePng(frame, out);
        if (!exr.empty()) hc::render::writeFrameExr(frame, exr);
        if (!timingsPath.empty()) {
            hc::AtomicFileWriter tw(timingsPath);
            const std::string j = timings.toJson();
            tw.write(std::as_bytes(std::span(j)));
            tw.commit();
        }
        std::printf("hc-render: %s -> %s%s%s\n", gridPath.c_str(), out.c_str(), exr.empty() ? "" : " + ", exr.c_str());
        std::printf("  camera       %.3f, %.3f, %.3f  yaw %.2f  pitch %.2f  fov %.1f  %dx%d\n", camera.xWorld, camera.yWorld, camera.zWorld,
                    camera.yawDeg, camera.pitchDeg, camera.fovYDeg, camera.width, camera.height);
        std::printf("%s", timings.toTable().c_str());
        return 0;
    });
}
