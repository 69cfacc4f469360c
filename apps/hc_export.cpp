// hc-export: the smooth surface sampled on a regular raster -> GeoTIFF, OpenEXR or OpenVDB.
#include <algorithm>
#include <cctype>
#include <cstdio>
#include <filesystem>

#include "cli.h"
#include "heightcast/export/export.h"
#include "heightcast/core/error.h"
#include "heightcast/core/timer.h"
#include "heightcast/grid/grid_file.h"

int main(int argc, char** argv) {
    return hc::cli::run("hc-export", [&] {
        std::string gridPath, cachePath, layerName = "elevation", bbox, out;
        double resolution = 0;
        hc::influence::KernelParams params;
        unsigned threads = 0;
        bool quiet = false;
        hc::cli::Parser p("hc-export", "GRID.hcg --resolution M -o OUT.tif|OUT.exr|OUT.vdb [options]",
                          "Samples the exact smooth surface at the centres of a regular raster and writes it for other tools:\n"
                          "  .tif  GeoTIFF (Float32; CRS, geotransform and nodata for holes) for QGIS, gdalinfo, ...\n"
                          "  .exr  OpenEXR (the layer as a FLOAT channel, NaN and A = 0 where undefined; georeference\n"
                          "        in heightcast.* header attributes)\n"
                          "  .vdb  OpenVDB narrow-band level sets 'terrain' and, when the grid has water, 'water_surface'\n"
                          "        (voxel = --resolution; georeference in grid metadata) for film and VFX tools");
        p.positional("GRID.hcg", "grid file", gridPath);
        p.option("--resolution", "M", "pixel (voxel) size, metres (required)", resolution);
        p.option("-o", "OUT", "output file; the format follows the extension .tif/.tiff, .exr or .vdb (required)", out);
        p.option("--bbox", "XMIN,YMIN,XMAX,YMAX", "area in the grid's CRS, metres (default: the grid's extent)", bbox);
        p.option("--layer", "L", "elevation, water_depth, water_surface or another layer (default elevation; .vdb always\n"
                 "      writes terrain and, with water, the water surface). Water as hc-probe gives it: the wet cells'\n"
                 "      level where water is drawn, depth = level - elevation there and 0 on dry land [m]", layerName);
        p.option("--cache", "C.hci", "influence cache (default: the grid's path with .hci; built if missing or stale)", cachePath);
        p.option("--sigma", "S", "kernel width in cell sizes (default 1.0)", params.sigma);
        p.option("--truncation", "R", "kernel cut-off in sigmas (default 3.5)", params.truncation);
        p.option("--threads", "N", "worker threads (default 0 = all cores)", threads);
        p.flag("--quiet", "no progress output", quiet);
        if (!p.parse(argc, argv)) return 0;
        if (!p.given("--resolution")) throw hc::Error("give --resolution M");
        if (out.empty()) throw hc::Error("no output file: give -o OUT.tif|OUT.exr|OUT.vdb");
        std::string ext = std::filesystem::path(out).extension().string();
        std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
        if (ext != ".tif" && ext != ".tiff" && ext != ".exr" && ext != ".vdb")
            throw hc::Error(out + ": unknown output format '" + ext + "' (use .tif, .exr or .vdb)");
        if (ext == ".vdb" && p.given("--layer") && layerName != "elevation")
            throw hc::Error("--layer: a .vdb always holds the terrain and, with water, the water surface");
        if (ext == ".vdb") hc::exporting::checkVdbAvailable(out);
        if (std::string why = params.validate(); !why.empty()) throw hc::Error("--sigma/--truncation: " + why);
        std::optional<hc::exporting::BoxWorld> box;
        if (!bbox.empty()) {
            const auto v = hc::cli::parseNumberList(bbox, "--bbox", 4, 4);
            box = hc::exporting::BoxWorld{v[0], v[1], v[2], v[3]};
        }
        hc::cli::checkWritable(out, "export");
        hc::cli::checkNotSame(out, gridPath, "export");

        const hc::Stopwatch clock;
        hc::Grid grid = hc::readGrid(gridPath);
        hc::exporting::planRaster(grid, resolution, box);  // refuse a bad request before any real work
        const auto layer = hc::influence::Layer::byName(grid, ext == ".vdb" ? "elevation" : layerName);
        if (cachePath.empty()) cachePath = hc::influence::defaultCachePath(gridPath);
        std::string note;
        auto lists = hc::influence::loadOrBuildCache(grid, params, cachePath, threads, !quiet, note);
        std::fprintf(stderr, "hc-export: %s\n", note.c_str());
        hc::influence::SurfaceEvaluator eval(grid, lists);

        const bool vdb = ext == ".vdb";
        auto raster = hc::exporting::sampleSurface(eval, layer, vdb ? "elevation" : layerName, resolution, box, vdb, threads, !quiet);
        if (raster.definedCount() == 0) throw hc::Error("the surface is undefined everywhere in the requested area (all holes)");
        size_t waterDefined = 0;
        if (vdb) {
            std::optional<hc::exporting::SampledRaster> water;
            if (grid.findLayer("water_depth") >= 0) {
                water = hc::exporting::sampleSurface(eval, hc::influence::Layer::byName(grid, "water_surface"), "water_surface",
                                                     resolution, box, true, threads, !quiet);
                waterDefined = water->definedCount();
            }
            hc::exporting::writeVdb(raster, water && waterDefined ? &*water : nullptr, out);
        } else if (ext == ".exr") {
            hc::exporting::writeExr(raster, out);
        } else {
            hc::exporting::writeGeoTiff(raster, out);
        }
        const double seconds = clock.seconds();
        std::printf("hc-export: %s -> %s\n", gridPath.c_str(), out.c_str());
        std::printf("  raster       %zu x %zu px of %g m, west %.3f north %.3f\n", raster.width, raster.height, raster.pixelSizeM,
                    raster.westWorld, raster.northWorld);
        std::printf("  layer        %s [%s], defined at %zu of %zu samples\n", raster.layer.c_str(), raster.units.c_str(),
                    raster.definedCount(), raster.values.size());
        if (vdb) std::printf("  water        %s\n", waterDefined ? "water_surface level set written" : "none");
        std::printf("  time         %.3f s\n", seconds);
        return 0;
    });
}
