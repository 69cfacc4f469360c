// hc-probe: the exact smooth surface at given points.
#include <cstdio>
#include <string>
#include <vector>

#include "cli.h"
#include "heightcast/core/atomic_file.h"
#include "heightcast/core/error.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/influence/surface.h"

int main(int argc, char** argv) {
    return hc::cli::run("hc-probe", [&] {
        std::string gridPath, cachePath, layerName = "elevation", pointsPath, xy, out;
        hc::influence::KernelParams params;
        unsigned threads = 0;
        hc::cli::Parser p("hc-probe", "GRID.hcg [--cache C.hci] [--layer L] (--points IN.csv | --xy X,Y) [-o OUT.csv]",
                          "Evaluates the exact smooth surface (double precision) at points given in the grid's CRS [m].\n"
                          "Prints or writes x,y,value with full precision; the value is empty where the surface is\n"
                          "undefined (holes, outside the grid, or dry land for water_surface).\n"
                          "Water (DESIGN.md section 12): water_surface is the level of the wet cells alone (a level flood\n"
                          "stays level), drawn where wet cells hold >= 1/2 of the kernel weight and the level is above the\n"
                          "terrain; water_depth is that level - elevation there and 0 on dry land, in metres.");
        p.positional("GRID.hcg", "grid file", gridPath);
        p.option("--cache", "C.hci", "influence cache (default: the grid's path with .hci; built if missing or stale)", cachePath);
        p.option("--layer", "L", "elevation, water_depth, water_surface or another layer of the grid (default elevation)", layerName);
        p.option("--points", "IN.csv", "CSV with a header line starting x,y and one point per line", pointsPath);
        p.option("--xy", "X,Y", "a single point", xy);
        p.option("-o", "OUT.csv", "output CSV (default: standard output)", out);
        p.option("--sigma", "S", "kernel width in cell sizes (default 1.0)", params.sigma);
        p.option("--truncation", "R", "kernel cut-off in sigmas (default 3.5)", params.truncation);
        p.option("--threads", "N", "worker threads (default 0 = all cores)", threads);
        p.exclusive({"--points", "--xy"});
        if (!p.parse(argc, argv)) return 0;
        if (pointsPath.empty() && xy.empty()) throw hc::Error("give --points IN.csv or --xy X,Y");
        if (std::string why = params.validate(); !why.empty()) throw hc::Error("--sigma/--truncation: " + why);
        if (!out.empty()) {
            hc::cli::checkWritable(out, "output CSV");
            hc::cli::checkNotSame(out, gridPath, "output CSV");
            if (!pointsPath.empty()) hc::cli::checkNotSame(out, pointsPath, "output CSV");
        }
        std::vector<std::array<double, 2>> pts;
        if (!xy.empty()) {
            const auto v = hc::cli::parseNumberList(xy, "--xy", 2, 2);
            pts.push_back({v[0], v[1]});
        } else {
            pts = hc::cli::readPointsCsv(pointsPath);
        }

        hc::Grid grid = hc::readGrid(gridPath);
        const auto layer = hc::influence::Layer::byName(grid, layerName);
        if (cachePath.empty()) cachePath = hc::influence::defaultCachePath(gridPath);
        std::string note;
        auto lists = hc::influence::loadOrBuildCache(grid, params, cachePath, threads, false, note);
        std::fprintf(stderr, "hc-probe: %s\n", note.c_str());
        hc::influence::SurfaceEvaluator eval(grid, lists);

        std::vector<std::array<double, 2>> local(pts.size());
        for (size_t i = 0; i < pts.size(); ++i) local[i] = {pts[i][0] - grid.originWorldX, pts[i][1] - grid.originWorldY};
        const std::vector<std::optional<double>> values = eval.values(local, layer, threads);
        std::string text = "x,y,value\n";
        char buf[96];
        for (size_t i = 0; i < pts.size(); ++i) {
            std::snprintf(buf, sizeof buf, "%.17g,%.17g,", pts[i][0], pts[i][1]);
            text += buf;
            if (values[i]) {
                std::snprintf(buf, sizeof buf, "%.17g", *values[i]);
                text += buf;
            }
            text += '\n';
        }
        if (out.empty()) {
            std::fwrite(text.data(), 1, text.size(), stdout);
        } else {
            hc::AtomicFileWriter w(out);
            w.write(std::as_bytes(std::span(text)));
            w.commit();
        }
        return 0;
    });
}
