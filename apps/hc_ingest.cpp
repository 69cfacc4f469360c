// hc-ingest: raster DEM (+ water) -> adaptive quadtree grid file (.hcg).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>

#include <fmt/format.h>

#include "heightcast/support/cli.h"
#include "heightcast/support/on_ranks.h"
#include "heightcast/core/ranks.h"
#include "heightcast/core/timer.h"
#include "heightcast/core/error.h"
#include "heightcast/core/heap.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/core/progress.h"
#include "heightcast/ingest/ingest.h"
#include "heightcast/ingest/mesh.h"
#include "heightcast/ingest/model.h"

namespace {

constexpr int kBandNotGiven =
    -1000000;  // --band's value before parsing: tells "not given" from any number a user types

void printSummary(const hc::ingest::BuildSummary& b, const hc::ingest::LoadReport& r, const std::string& out,
                  bool timesGuessed, double heldMB) {
    const hc::Grid& g = b.shape;
    const hc::IngestStats& s = g.stats;
    const bool mesh = !s.sourceKind.empty();  // faces taken as cells (a sampled mesh is built as a raster)
    std::printf("hc-ingest: %s -> %s\n", s.sourcePath.c_str(), out.c_str());
    std::printf("  input        %s\n", r.sourceDescription.c_str());
    std::printf("  input CRS    %s\n", r.sourceCrsName.empty() ? "none" : r.sourceCrsName.c_str());
    std::printf("  grid CRS     %s\n", r.gridCrsName.empty() ? "none (local metres)" : r.gridCrsName.c_str());
    std::printf("  method       %s\n", r.method.c_str());
    if (mesh)
        std::printf("  finest face  %.9g m%s; nodes within %.3g m of the fitted lattice\n", g.finestCellM,
                    g.rotationDeg != 0 ? fmt::format(", grid turned {:.9g} degrees", g.rotationDeg).c_str() : "",
                    s.latticeResidualM);
    else
        std::printf("  working      %llu x %llu px of %.6g m, %llu valid\n", (unsigned long long)s.sourceWidth,
                    (unsigned long long)s.sourceHeight, g.finestCellM, (unsigned long long)s.validPixels);
    if (mesh)
        std::printf("  cells        %llu (one per face), %zu layer%s:", (unsigned long long)b.cellCount, g.layerCount(),
                    g.layerCount() == 1 ? "" : "s");
    else
        std::printf("  cells        %llu (%.3f pixels per cell), %zu layer%s:", (unsigned long long)b.cellCount,
                    b.cellCount ? double(s.validPixels) / double(b.cellCount) : 0.0, g.layerCount(),
                    g.layerCount() == 1 ? "" : "s");
    for (const auto& l : g.layers) std::printf(" %s [%s]", l.name.c_str(), l.units.c_str());
    std::printf("\n");
    for (size_t l = 0; l < b.cellsPerLevel.size(); ++l)
        std::printf("    level %zu  %10.4g m  %10llu cells  %6.2f %%\n", l, g.levelSizeM(int(l)),
                    (unsigned long long)b.cellsPerLevel[l],
                    b.cellCount ? 100.0 * double(b.cellsPerLevel[l]) / double(b.cellCount) : 0.0);
    if (b.steps.size() == 1) {
        std::printf("  water        %llu wet cells of %llu\n", (unsigned long long)b.wetCells,
                    (unsigned long long)b.cellCount);
    } else if (b.steps.size() > 1) {
        uint64_t lo = UINT64_MAX, hi = 0;
        for (const auto& st : b.steps) lo = std::min(lo, st.wetCells), hi = std::max(hi, st.wetCells);
        std::printf(
            "  water        %zu steps, %.6g s .. %.6g s%s; %llu .. %llu wet cells of %llu; %.1f kB a step on average\n",
            b.steps.size(), b.steps.front().timeS, b.steps.back().timeS,
            timesGuessed ? " (the step index: no --times given)" : "", (unsigned long long)lo, (unsigned long long)hi,
            (unsigned long long)b.cellCount, double(b.stepBytes) / double(b.steps.size()) / 1e3);
    }
    // Which pixels the deviation is measured on, said plainly: the working raster is the source
    // itself only when nothing was projected or resampled. A mesh is taken as it is: nothing to measure.
    const auto& c = r.sourceCheck;
    if (mesh) {
        std::printf("  values       each face's own, as float32 (no merging, no resampling)\n");
    } else if (!c.done) {
        std::printf("  deviation    max %.4g m, RMS %.4g m (tolerance %.4g m; every valid source pixel checked%s)\n",
                    s.maxDevM, s.rmsDevM, s.toleranceM,
                    r.sourcePrecisionDouble ? ", in the source's own precision" : "");
    } else {
        std::printf(
            "  deviation    max %.4g m, RMS %.4g m against the %llu valid pixels of the resampled working raster "
            "(tolerance %.4g m)\n",
            s.maxDevM, s.rmsDevM, (unsigned long long)s.validPixels, s.toleranceM);
        std::printf(
            "  vs source    max %.4g m, RMS %.4g m against the %llu valid source pixels (at each pixel centre)%s\n",
            c.maxDevM, c.rmsDevM, (unsigned long long)c.checked,
            r.sourcePrecisionDouble ? ", in the source's own precision" : "");
        std::printf("  lost         %llu valid source pixels reached no cell (%.3g %%)\n", (unsigned long long)c.missed,
                    c.checked + c.missed ? 100.0 * double(c.missed) / double(c.checked + c.missed) : 0.0);
    }
    if (r.infPixels)
        std::printf("  infinite     %llu pixels of +-inf taken as nodata\n", (unsigned long long)r.infPixels);
    std::printf("  time         %.3f s (read, project, build, write)\n", s.seconds);
    std::printf("  memory       peak %.1f MB resident (the grid streams to disk: %zu bytes per cell there%s)\n",
                double(hc::peakRssBytes()) / 1e6, size_t(8 + 4 * g.firstStepLayer()),
                b.steps.empty() ? "" : ", and 8 per wet cell and step");
    if (r.heldInPieces)
        std::printf(
            "  raster       read window by window in pieces of at most %.3g MB (float32), each read twice "
            "(--raster-memory)\n",
            double(heldMB));
}

// A variable of a model's results named as a raster (NETCDF:"run.nc":zs, HDF5:"plan.hdf"://...): the file behind it, if
// it holds model results read here ("" otherwise). Such a variable has no georeferencing of its own: the model's
// coordinates are in other variables, which only the model readers take.
std::string modelBehind(const std::string& name) {
    for (const char* driver : {"NETCDF:", "HDF5:"}) {
        if (name.rfind(driver, 0) != 0) continue;
        std::string rest = name.substr(std::string(driver).size());
        std::string file = rest[0] == '"' ? rest.substr(1, rest.find('"', 1) - 1) : rest.substr(0, rest.rfind(':'));
        return !file.empty() && !hc::ingest::modelFormatOf(file).empty() ? file : "";
    }
    return "";
}

// The options into `o`, validated before any work; false after --help.
bool parseOptions(int argc, char** argv, hc::ingest::Options& o, std::string& out, bool& quiet, bool& mesh) {
    std::string water, waterSurface, waterLevel, times, faceLayers, meshMode = "auto";
    std::optional<double> nodata;
    hc::cli::Parser p(
        "hc-ingest", "INPUT -o OUT.hcg [options]",
        "Converts a raster DEM (any format GDAL reads, any CRS), or a flood model's results (SFINCS, D-Flow FM and\n"
        "other UGRID maps, HEC-RAS 2D, ANUGA, TELEMAC, 3Di, TUFLOW FV), into an adaptive quadtree grid file.\n"
        "Four cells merge into one while their mean stays within --tolerance of every pixel they\n"
        "cover (in every layer); the achieved max and RMS deviation is measured and reported.\n"
        "Under `mpirun -np N` the ranks share the build and write the same bytes as one process: each reads\n"
        "only its windows of the raster and of the water rasters and writes its own cells\n"
        "into the one output, whose folder every rank must see (docs/mpi.md).");
    p.positional(
        "INPUT",
        "terrain raster: GeoTIFF, SRTM .hgt / .hgt.zip, ESRI ASCII, NetCDF, PNG, ... (GDAL); or model results\n"
        "      (docs/models.md: terrain and every water step from the one file)",
        o.input);
    p.option("-o", "OUT.hcg", "output grid file (required; written atomically)", out);
    p.option(
        "--tolerance", "M",
        fmt::format("max |pixel - cell value| in every layer, metres (default {:g})", hc::ingest::kDefaultToleranceM),
        o.toleranceM);
    p.option("--min-cell", "M", "finest cell size, metres (default: the source pixel size after projection)",
             o.minCellM);
    p.option("--max-cell", "M", "coarsest cell size, metres, rounded down to finest * 2^k (default: largest <= 96 m)",
             o.maxCellM);
    p.option("--t_srs", "CRS",
             "project into this CRS (EPSG:xxxx, WKT, PROJ string) with GDAL, bilinear, exact transformer; a\n"
             "      geographic input across 180 degrees is split there (default: a projected input keeps its CRS; a "
             "geographic\n"
             "      one goes to the UTM zone of its centre via GeographicLib, longitudes 0..360 accepted)",
             o.targetSrs);
    p.option("--s_srs", "CRS",
             "CRS of the input, overriding or supplying its own (e.g. EPSG:27700 for an .asc without .prj);\n"
             "      'local' takes the coordinates as metres in a local frame (no CRS; without --s_srs, coordinates "
             "that look like\n"
             "      degrees are taken as WGS 84, with a warning)",
             o.sourceSrs);
    o.band = kBandNotGiven;
    p.option("--band", "N",
             "band to read, 1-based (default 1; a 3-band 8-bit image is refused without it or --terrain-rgb)", o.band);
    p.option("--nodata", "V",
             "a further nodata value (the band's own nodata, NaN and +-inf always count; a warning names\n"
             "      classic sentinels such as -9999 that the file holds without declaring them); for model results, "
             "bed and\n"
             "      water levels equal to V are no value (a hole, dry)",
             nodata);
    p.option("--z-scale", "F", "multiply elevations by F after unit conversion (default 1)", o.zScale);
    p.flag("--terrain-rgb", "decode Terrain-RGB bands 1-3: h = -10000 + 0.1 * (R * 65536 + G * 256 + B) metres",
           o.terrainRgb);
    p.option(
        "--water", "RASTERS",
        "water depth raster(s), metres (resampled onto the terrain; nodata and <= 0 are dry); several\n"
        "      make a flood scenario, one water step each, in the order given: A.tif,B.tif or a quoted glob "
        "'depth_*.tif'\n"
        "      (natural order: depth_9 before depth_10); every step must share the first's size, georeferencing and "
        "CRS;\n"
        "      a NetCDF variable over time ('NETCDF:\"run.nc\":depth') is a series in itself: one step per time, the\n"
        "      times (CF units) from the file",
        water);
    p.option("--water-surface", "RASTERS",
             "water surface elevation raster(s), metres (depth = surface - terrain; <= 0 is dry); a list\n"
             "      or glob makes steps, as for --water",
             waterSurface);
    p.option("--water-level", "L[,L...]",
             "bathtub flood: depth = L - z, metres, where below L and connected to the domain boundary\n"
             "      (raster edge or nodata) through pixels below L, 4-connected: pixels touching only at a corner do "
             "not connect;\n"
             "      several levels make several steps (a rising flood: 300,302,304)",
             waterLevel);
    p.option("--times", "T[,T...]",
             "time of each water step, seconds, strictly increasing (default: the step index 0, 1, 2, ...)", times);
    p.option("--water-mesh", "RESULTS",
             "flood model results whose water levels flood the raster's terrain, one step per time\n"
             "      (depth = level - terrain; dry where the model is dry, outside its faces, or depth <= 0)",
             o.waterMesh);
    p.option("--mesh", "auto|cells|sample",
             "model results: 'cells' takes a quadtree's faces as cells (refusing any other mesh),\n"
             "      'sample' samples the faces onto the grid (terrain as for a raster: --min-cell, --tolerance); "
             "default auto:\n"
             "      cells for quadtree models (SFINCS, 3Di) and meshes of square power-of-two faces, sampled otherwise",
             meshMode);
    p.option("--mesh-tolerance", "M",
             "a quadtree's nodes may lie this far from the lattice fitted to them, metres (default: a few\n"
             "      ulps of the coordinates' storage at their magnitude, e.g. 1 m for float32 at y = 5e6)",
             o.meshToleranceM);
    p.option("--mesh-srs", "CRS", "CRS of --water-mesh's coordinates, overriding or supplying the file's own",
             o.meshSrs);
    p.option("--terrain-var", "NAME",
             "model results: the bed level variable; faces where it is a fill value are holes\n"
             "      (default: the format's own: zb, mesh2d_flowelem_bl, mesh2d_node_z, ...)",
             o.terrainVar);
    p.option("--water-surface-var", "NAME",
             "model results: the water level variable over time, one step per time; fill values\n"
             "      and levels not above the bed are dry; '-' reads the terrain only (default: the format's own: zs,\n"
             "      mesh2d_s1, ...)",
             o.waterSurfaceVar);
    p.option("--face-layers", "NAME[,NAME...]",
             "quadtree model results: further variables over time (velocity magnitude, ...), each\n"
             "      stored per step on the wet faces as a layer of that name and the variable's units (default none)",
             faceLayers);
    p.option("--threads", "N", "worker threads (default 0 = all cores; under mpirun: per rank)", o.threads);
    p.option(
        "--raster-memory", "MB",
        fmt::format("one process, terrain without water: the most memory the working raster may take as\n"
                    "      float32, MB; a larger one is read window by window in pieces, each read twice, into the "
                    "same\n      bytes (default {:.0f})",
                    hc::ingest::kDefaultRasterMemoryMB),
        o.rasterMemoryMB);
    p.flag("--quiet", "print only warnings and failures (no progress, no summary)", quiet);
    p.exclusive({"--water", "--water-surface", "--water-level"});
    if (!p.parse(argc, argv)) return false;
    if (out.empty()) throw hc::Error("no output file: give -o OUT.hcg");
    if (meshMode != "auto" && meshMode != "cells" && meshMode != "sample")
        throw hc::Error("--mesh " + meshMode + ": not auto, cells or sample");
    o.meshMode = meshMode == "cells"    ? hc::ingest::MeshMode::Cells
                 : meshMode == "sample" ? hc::ingest::MeshMode::Sample
                                        : hc::ingest::MeshMode::Auto;
    if (o.meshToleranceM && !(*o.meshToleranceM >= 0)) throw hc::Error("--mesh-tolerance must be a length >= 0");
    // Flood model results (a SFINCS map, a HEC-RAS plan, ...) carry terrain and water steps in one file.
    mesh = !o.input.empty() && !hc::ingest::modelFormatOf(o.input).empty();
    if (!mesh && std::filesystem::exists(o.input))
        if (std::string hint = hc::ingest::unreadModelFormat(o.input); !hint.empty())
            throw hc::Error(o.input + ": " + hint);
    if (std::string file = modelBehind(o.input); !file.empty())
        throw hc::Error(o.input + ": a variable of flood model results (" + hc::ingest::modelFormatOf(file) +
                        "), which has no georeferencing of "
                        "its own: give the file itself (hc-ingest " +
                        file + " -o OUT.hcg: terrain and every step)");
    if (!o.waterMesh.empty()) {
        if (mesh)
            throw hc::Error("--water-mesh: the input " + o.input +
                            " is itself model results; give a terrain raster as INPUT");
        for (const char* opt : {"--water", "--water-surface", "--water-level", "--times"})
            if (p.given(opt)) throw hc::Error(std::string(opt) + " and --water-mesh both give water: choose one");
        if (hc::ingest::modelFormatOf(o.waterMesh).empty())
            throw hc::Error("--water-mesh " + o.waterMesh + ": not model results read here" +
                            (hc::ingest::unreadModelFormat(o.waterMesh).empty()
                                 ? ""
                                 : ": " + hc::ingest::unreadModelFormat(o.waterMesh)));
        hc::cli::checkNotSame(out, o.waterMesh, "output grid");
    }
    if (mesh) {
        o.samplingGiven = p.given("--tolerance") || p.given("--min-cell") || p.given("--max-cell");
        o.nodata = nodata;
        o.band = 1;  // no band: --band is refused below
        for (const char* opt : {"--water", "--water-surface", "--water-level", "--times", "--t_srs", "--band",
                                "--z-scale", "--terrain-rgb", "--mesh-srs"})
            if (p.given(opt))
                throw hc::Error(std::string(opt) + ": " + o.input +
                                " is flood model results (terrain and water steps from the file): " +
                                "--terrain-var, --water-surface-var, --face-layers, --mesh, --mesh-tolerance, --s_srs, "
                                "--nodata and, for a sampled mesh, " +
                                "--tolerance, --min-cell and --max-cell apply");
        for (size_t b = 0, e = 0; b < faceLayers.size(); b = e + 1) {
            e = std::min(faceLayers.find(',', b), faceLayers.size());
            if (e == b) throw hc::Error("--face-layers " + faceLayers + ": an empty name");
            o.faceLayerVars.push_back(faceLayers.substr(b, e - b));
        }
        hc::cli::checkWritable(out, "output grid");
        hc::cli::checkNotSame(out, o.input, "output grid");
        return true;
    }
    if (o.waterMesh.empty() && (p.given("--terrain-var") || p.given("--water-surface-var") || p.given("--face-layers")))
        throw hc::Error("--terrain-var / --water-surface-var / --face-layers: " + o.input +
                        " is not model results read here");
    o.bandGiven = o.band != kBandNotGiven;
    if (!o.bandGiven) o.band = 1;
    o.nodata = nodata;
    if (!water.empty())
        o.water = hc::ingest::WaterSource::Depth, o.waterPaths = hc::cli::expandFileList(water, "--water");
    if (!waterSurface.empty())
        o.water = hc::ingest::WaterSource::Surface,
        o.waterPaths = hc::cli::expandFileList(waterSurface, "--water-surface");
    if (!waterLevel.empty())
        o.water = hc::ingest::WaterSource::Level,
        o.waterLevelsM = hc::cli::parseNumberList(waterLevel, "--water-level", 1, SIZE_MAX);
    if (!times.empty()) o.timesS = hc::cli::parseNumberList(times, "--times", 1, SIZE_MAX);
    for (const auto& w : o.waterPaths) {
        hc::cli::checkNotSame(out, w, "output grid");
        if (std::string file = modelBehind(w); !file.empty())
            throw hc::Error(w + ": a variable of flood model results (" + hc::ingest::modelFormatOf(file) +
                            "), which has no georeferencing of its "
                            "own: give the file with --water-mesh " +
                            file + " (its levels over time on the terrain)");
    }
    if (o.waterPaths.size() == 1) o.waterPath = o.waterPaths[0], o.waterPaths.clear();
    if (o.waterLevelsM.size() == 1) o.waterLevelM = o.waterLevelsM[0], o.waterLevelsM.clear();
    o.progress = !quiet;
    hc::ingest::validateOptions(o);
    hc::cli::checkWritable(out, "output grid");
    hc::cli::checkNotSame(out, o.input, "output grid");
    return true;
}

// Builds the grid into `out`; the reader's warnings go to stderr also when the build fails (what was guessed
// before the failure, degrees or units, often explains it).
hc::ingest::BuildSummary buildGrid(const hc::ingest::Options& o, const std::string& out, hc::ingest::LoadReport& report,
                                   bool mesh) {
    auto printWarnings = [&] {
        if (hc::ranks::rank() != 0) return;  // under mpirun every rank reads the same input: rank 0 says what it found
        std::vector<std::string> said;       // a series read twice repeats its warnings: each is said once
        for (const auto& w : report.warnings)
            if (std::find(said.begin(), said.end(), w) == said.end()) {
                std::fprintf(stderr, "hc-ingest: warning: %s\n", w.c_str());
                said.push_back(w);
            }
    };
    hc::ingest::BuildSummary summary;
    try {
        summary = mesh ? hc::ingest::ingestModelToFile(o, out, report) : hc::ingest::ingestToFile(o, out, report);
    } catch (...) {
        printWarnings();
        throw;
    }
    printWarnings();
    return summary;
}

}  // namespace

int main(int argc, char** argv) {
    // GDAL's block buffers (256 kB for a 256 x 256 float32 tile) from the heap, reused: as fresh mmaps, each window
    // read by windows (mpirun, --raster-memory) faulted its blocks' pages in again (a third of its time at 419 M px).
    hc::keepFreedMemory(size_t(1) << 20, size_t(64) << 20);
    return hc::cli::runOnRanks("hc-ingest", argc, argv, [&] {
        namespace ranks = hc::ranks;
        hc::ingest::Options o;
        std::string out;
        bool quiet = false, mesh = false, go = true;
        ranks::together([&] { go = parseOptions(argc, argv, o, out, quiet, mesh); });
        if (!go) return 0;
        o.progress =
            o.progress && ranks::rank() == 0;  // one progress line: rank 0's (its bar counts every rank's share)
        const hc::Stopwatch clock;
        hc::ingest::LoadReport report;
        hc::ingest::BuildSummary summary;
        if (mesh) {
            // Model results are read by rank 0 alone (a quadtree's cells one per face; a sampled mesh in one process).
            ranks::together([&] {
                if (ranks::rank() == 0) summary = buildGrid(o, out, report, mesh);
            });
            ranks::log("hc-ingest", ranks::rank() == 0 ? "the model results read and built in one process"
                                                       : "idle: model results are read by rank 1");
        } else {
            // A NetCDF water variable over time is a series in one file: one step per time, times from the file.
            ranks::together([&] {
                if (hc::ingest::expandWaterTimeSeries(o, report) > 0) hc::ingest::validateOptions(o);
            });
            ranks::together([&] { summary = buildGrid(o, out, report, mesh); });
        }
        if (!quiet && ranks::rank() == 0)
            printSummary(summary, report, out, o.timesS.empty() && !mesh && o.waterMesh.empty(),
                         double(hc::ingest::heldPixelsMax(o)) * sizeof(float) / 1e6);
        if (ranks::distributed() && ranks::rank() == 0)
            ranks::log("hc-ingest", fmt::format("{} ranks, {:.3f} s in all", ranks::count(), clock.seconds()));
        return 0;
    });
}
