// hc-export: the smooth surface sampled on a regular raster -> GeoTIFF, OpenEXR or OpenVDB.
#include <algorithm>
#include <cctype>
#include <cstdio>
#include <filesystem>

#include "heightcast/support/cli.h"
#include "heightcast/export/export.h"
#include "heightcast/core/error.h"
#include "heightcast/core/timer.h"
#include "heightcast/grid/grid_file.h"

namespace {

struct ExportArgs {
    std::string gridPath, cachePath, layerName = "elevation", out;
    std::string ext;  // the output's extension, lower case: .tif, .tiff, .exr or .vdb
    double resolution = 0;
    std::optional<hc::exporting::BoxWorld> box;
    hc::influence::KernelParams params;
    unsigned threads = 0;
    unsigned step = 0;   // --step
    int startIndex = 0;  // .nc: the UGRID connectivity's start_index
    bool quiet = false;
    bool vdb() const { return ext == ".vdb"; }
    bool ugrid() const { return ext == ".nc"; }
};

// The options, validated before any work; false after --help.
bool parseOptions(int argc, char** argv, ExportArgs& a) {
    std::string bbox;
    hc::cli::Parser p(
        "hc-export", "GRID.hcg --resolution M -o OUT.tif|OUT.exr|OUT.vdb [options]  |  GRID.hcg -o MESH.nc",
        "Samples the exact smooth surface at the centres of a regular raster and writes it for other tools:\n"
        "  .tif  GeoTIFF (Float32; CRS, geotransform and nodata for holes) for QGIS, gdalinfo, ...\n"
        "  .exr  OpenEXR (the layer as a FLOAT channel, NaN and A = 0 where undefined; georeference\n"
        "        in heightcast.* header attributes)\n"
        "  .vdb  OpenVDB narrow-band level sets 'terrain' and, when the grid has water, 'water_surface'\n"
        "        (voxel = --resolution; georeference in grid metadata) for film and VFX tools\n"
        "and writes the grid's cells themselves (no sampling) as\n"
        "  .nc   a UGRID-1.0 mesh in NetCDF: one square face per cell, elevation zb, every water step's level\n"
        "        zs(time, face), as quadtree flood models (SFINCS) write theirs; hc-ingest reads it back");
    p.positional("GRID.hcg", "grid file", a.gridPath);
    p.option("--resolution", "M", "pixel (voxel) size, metres (required)", a.resolution);
    p.option("-o", "OUT", "output file; the format follows the extension .tif/.tiff, .exr or .vdb (required)", a.out);
    p.option("--bbox", "XMIN,YMIN,XMAX,YMAX", "area in the grid's CRS, metres (default: the grid's extent)", bbox);
    p.option("--layer", "L",
             "elevation, water_depth, water_surface or another layer (default elevation; .vdb always\n"
             "      writes terrain and, with water, the water surface). Water as hc-probe gives it: the wet cells'\n"
             "      level where water is drawn, depth = level - elevation there and 0 on dry land [m]",
             a.layerName);
    p.option("--cache", "C.hci",
             "read the whole grid and this influence cache (built if missing or stale; default: the grid's\n"
             "path with .hci when that exists and the grid has at most 4.5 M cells); without one the grid is\n"
             "read a tile at a time (out of core, the same values)",
             a.cachePath);
    p.option("--step", "K",
             "water step to export, 0-based (default 0; hc-info lists a grid's steps and their times; a .nc\n"
             "      holds every step)",
             a.step);
    p.option("--start-index", "0|1",
             ".nc: the first node's index in the face connectivity (UGRID start_index, default 0)", a.startIndex);
    p.option("--sigma", "S", "kernel width in cell sizes (default 1.0)", a.params.sigma);
    p.option("--truncation", "R", "kernel cut-off in sigmas (default 3.5)", a.params.truncation);
    p.option("--threads", "N", "worker threads (default 0 = all cores)", a.threads);
    p.flag("--quiet", "no progress output", a.quiet);
    if (!p.parse(argc, argv)) return false;
    if (a.out.empty()) throw hc::Error("no output file: give -o OUT.tif|OUT.exr|OUT.vdb|MESH.nc");
    a.ext = std::filesystem::path(a.out).extension().string();
    std::transform(a.ext.begin(), a.ext.end(), a.ext.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    if (a.ext != ".tif" && a.ext != ".tiff" && a.ext != ".exr" && a.ext != ".vdb" && a.ext != ".nc")
        throw hc::Error(a.out + ": unknown output format '" + a.ext + "' (use .tif, .exr, .vdb or .nc)");
    if (a.ugrid()) {
        for (const char* o : {"--resolution", "--bbox", "--layer", "--step", "--cache"})
            if (p.given(o))
                throw hc::Error(std::string(o) +
                                ": a .nc mesh holds the cells themselves, every layer and step, unsampled");
        if (a.startIndex != 0 && a.startIndex != 1)
            throw hc::Error("--start-index " + std::to_string(a.startIndex) + ": use 0 or 1");
        hc::cli::checkWritable(a.out, "export");
        hc::cli::checkNotSame(a.out, a.gridPath, "export");
        return true;
    }
    if (p.given("--start-index")) throw hc::Error("--start-index: only for a .nc mesh");
    if (!p.given("--resolution")) throw hc::Error("give --resolution M");
    if (a.vdb() && p.given("--layer") && a.layerName != "elevation")
        throw hc::Error("--layer: a .vdb always holds the terrain and, with water, the water surface");
    if (a.vdb()) hc::exporting::checkVdbAvailable(a.out);
    if (std::string why = a.params.validate(); !why.empty()) throw hc::Error("--sigma/--truncation: " + why);
    if (!bbox.empty()) {
        const auto v = hc::cli::parseNumberList(bbox, "--bbox", 4, 4);
        a.box = hc::exporting::BoxWorld{v[0], v[1], v[2], v[3]};
    }
    hc::cli::checkWritable(a.out, "export");
    hc::cli::checkNotSame(a.out, a.gridPath, "export");
    return true;
}

struct Exported {
    hc::exporting::SampledRaster raster;
    size_t waterDefined = 0;  // .vdb: samples of the water surface's level set that are defined
};

// Where the surface comes from: the whole grid and its lists, or (out of core) the grid file a band at a time.
struct Source {
    const hc::Grid& shape;                                  // geometry and layers
    const hc::influence::SurfaceEvaluator* eval = nullptr;  // in memory
    const hc::GridRegionReader* file = nullptr;             // out of core
    hc::influence::KernelParams params;
    hc::exporting::SampledRaster sample(const ExportArgs& a, const hc::influence::Layer& layer,
                                        const std::string& name) const {
        const bool grads = a.vdb();
        return eval ? hc::exporting::sampleSurface(*eval, layer, name, a.resolution, a.box, grads, a.threads, !a.quiet)
                    : hc::exporting::sampleSurface(*file, params, layer, name, a.resolution, a.box, grads, a.threads,
                                                   !a.quiet);
    }
};

// Samples `layer` (a .vdb: the terrain and, with water, the water surface) and writes the file.
Exported sampleAndWrite(const ExportArgs& a, const Source& src, const hc::influence::Layer& layer) {
    const bool vdb = a.vdb();
    Exported e{src.sample(a, layer, vdb ? "elevation" : a.layerName)};
    if (e.raster.definedCount() == 0)
        throw hc::Error("the surface is undefined everywhere in the requested area (all holes)");
    if (vdb) {
        std::optional<hc::exporting::SampledRaster> water;
        if (src.shape.findLayer("water_depth") >= 0) {
            water = src.sample(a, hc::influence::Layer::byName(src.shape, "water_surface"), "water_surface");
            e.waterDefined = water->definedCount();
        }
        hc::exporting::writeVdb(e.raster, water && e.waterDefined ? &*water : nullptr, a.out);
    } else if (a.ext == ".exr") {
        hc::exporting::writeExr(e.raster, a.out);
    } else {
        hc::exporting::writeGeoTiff(e.raster, a.out);
    }
    return e;
}

void printSummary(const ExportArgs& a, const Exported& e, double seconds) {
    const hc::exporting::SampledRaster& raster = e.raster;
    std::printf("hc-export: %s -> %s\n", a.gridPath.c_str(), a.out.c_str());
    std::printf("  raster       %zu x %zu px of %g m, west %.3f north %.3f\n", raster.width, raster.height,
                raster.pixelSizeM, raster.westWorld, raster.northWorld);
    std::printf("  layer        %s [%s], defined at %zu of %zu samples\n", raster.layer.c_str(), raster.units.c_str(),
                raster.definedCount(), raster.values.size());
    if (a.vdb()) std::printf("  water        %s\n", e.waterDefined ? "water_surface level set written" : "none");
    std::printf("  time         %.3f s\n", seconds);
}

}  // namespace

int main(int argc, char** argv) {
    return hc::cli::run("hc-export", [&] {
        ExportArgs a;
        if (!parseOptions(argc, argv, a)) return 0;
        const hc::Stopwatch clock;
        if (a.ugrid()) {
            const hc::exporting::UgridSummary m = hc::exporting::writeUgrid(a.gridPath, a.out, {a.startIndex});
            std::printf("hc-export: %s -> %s\n", a.gridPath.c_str(), a.out.c_str());
            std::printf("  mesh         UGRID-1.0: %zu faces (one per cell), %zu nodes, start_index %d\n", m.faces,
                        m.nodes, a.startIndex);
            std::printf("  steps        %zu (zs over time; %llu wet faces in all)\n", m.steps,
                        (unsigned long long)m.wetFaces);
            std::printf("  time         %.3f s\n", clock.seconds());
            return 0;
        }
        const std::string cachePath = a.cachePath.empty() ? hc::influence::defaultCachePath(a.gridPath) : a.cachePath;
        std::error_code ec;
        Exported exported;
        const bool cacheBeside = std::filesystem::exists(cachePath, ec);
        if (a.cachePath.empty() &&
            (!cacheBeside || hc::readGridInfo(a.gridPath).cellCount > hc::influence::kListsDefaultMaxCells)) {
            // No cache, or a grid whose cache costs more to read than its regions: out of core, a tile at a time (the
            // same bits).
            const hc::GridRegionReader file(a.gridPath, a.step);
            hc::exporting::planRaster(file.info(), a.resolution, a.box);  // refuse a bad request before any real work
            const auto layer = hc::influence::Layer::byName(file.shape(), a.vdb() ? "elevation" : a.layerName);
            if (cacheBeside)
                std::fprintf(stderr,
                             "hc-export: %llu cells: the grid is read a tile at a time (out of core), its influence "
                             "cache %s not read (--cache %s reads it)\n",
                             (unsigned long long)file.cellCount(), cachePath.c_str(), cachePath.c_str());
            else
                std::fprintf(stderr,
                             "hc-export: no influence cache at %s: the grid is read a tile at a time (out of core)\n",
                             cachePath.c_str());
            exported = sampleAndWrite(a, Source{file.shape(), nullptr, &file, a.params}, layer);
        } else {
            const hc::Grid grid = hc::readGrid(a.gridPath, nullptr, a.step);
            hc::exporting::planRaster(grid, a.resolution, a.box);  // refuse a bad request before any real work
            const auto layer = hc::influence::Layer::byName(grid, a.vdb() ? "elevation" : a.layerName);
            std::string note;
            const auto lists = hc::influence::loadOrBuildCache(grid, a.params, cachePath, a.threads, !a.quiet, note);
            std::fprintf(stderr, "hc-export: %s\n", note.c_str());
            const hc::influence::SurfaceEvaluator eval(grid, lists);
            exported = sampleAndWrite(a, Source{grid, &eval, nullptr, a.params}, layer);
        }
        printSummary(a, exported, clock.seconds());
        return 0;
    });
}
