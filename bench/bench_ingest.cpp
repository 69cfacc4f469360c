// hc-bench-ingest: how fast, and in how much memory, does ingest turn real SRTM data into a grid?
//
// Four inputs, prepared (untimed) in the work folder from the shared SRTM tiles:
//   a  N00E010.hgt as is: geographic Int16, projected to UTM by GeographicLib inside ingest
//   b  the same tile warped by GDAL to UTM 32N, Float32, 90 m squares: the projected case
//   c  the VRT mosaic N00E010 + N00E011 (2401 x 1201): the larger geographic case
//   d  that mosaic warped by GDAL to 30 m UTM squares (about 27 Mpx): how time and memory scale
// Each is ingested along two paths:
//   mem     hc::ingest::ingest() then hc::writeGrid(): the grid in memory (tests, small rasters)
//   stream  hc::ingest::ingestToFile(): cells stream into the file as they are built (hc-ingest)
// Each (input, tolerance, path) case runs --repeat times; times are the best run, memory the worst.
//
// Why every run is a forked child: peak RSS (getrusage maxrss) is per process and only grows, so a
// case measured in a process that already ran another case would report the larger of the two. The
// parent never loads GDAL or a raster (even the preparation runs in a child): each child starts from
// the same small process, does the first GDALAllRegister itself, reads its baseline RSS, ingests, and
// sends its numbers back through a pipe. (A forked child counts a shared-library page only once it
// touches it, so library code that runs for the first time inside ingest, such as GTiff, PROJ and
// SQLite, lands in the ingest's share: about 8 MB here. hc-ingest, a fresh process, maps part of it
// at start-up instead.)
#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <optional>
#include <string>
#include <type_traits>
#include <vector>

#include <cpl_error.h>
#include <gdal.h>
#include <gdal_utils.h>
#include <ogr_spatialref.h>
#include <sys/wait.h>
#include <unistd.h>

#include "bench_common.h"
#include "svg_plot.h"
#include "heightcast/support/cli.h"
#include "heightcast/core/error.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/core/progress.h"
#include "heightcast/core/timer.h"
#include "heightcast/ingest/ingest.h"

namespace fs = std::filesystem;

namespace {

using namespace hc::bench;

// Targets of issue 2.
constexpr double kTargetMpxPerS = 10.0;        // source pixels per second of ingest, projected input
constexpr double kTargetRasterMultiple = 3.0;  // ingest RSS <= 3 x the source raster as float32

struct Input {
    char id;           // a, b, c
    std::string file;  // path: the shared tile itself, or a file prepared in the work folder
    std::string what;  // one line for the legend
    bool projected;    // the speed target applies to this one
};

// What a case child reports. Plain bytes through a pipe, so trivially copyable.
struct RunResult {
    uint64_t sourceWidth = 0, sourceHeight = 0;    // the input file (LoadReport)
    uint64_t workingWidth = 0, workingHeight = 0;  // the working raster after projection (grid stats)
    uint64_t cells = 0;
    double ingestS = 0, writeS = 0;         // stream: writing happens inside ingest, writeS stays 0
    uint64_t baselineRss = 0, peakRss = 0;  // bytes: after GDALAllRegister / after ingest returned
    double maxDevM = 0, rmsDevM = 0;
};
struct Nothing {};

enum class Path { Memory, Stream };
const char* pathName(Path p) { return p == Path::Memory ? "mem" : "stream"; }

std::string gdalMessage() {
    const char* m = CPLGetLastErrorMsg();
    return m && *m ? m : "no detail from GDAL";
}

// GDAL's utilities take argv-style option lists.
std::vector<char*> argvOf(std::vector<std::string>& args) {
    std::vector<char*> v;
    for (auto& a : args) v.push_back(a.data());
    v.push_back(nullptr);
    return v;
}

// Writes inputs b and c (input a is the tile itself). Runs in a child: see the top of the file.
void prepareInputs(const fs::path& tile, const fs::path& east, const fs::path& work) {
    GDALAllRegister();
    CPLSetErrorHandler(CPLQuietErrorHandler);  // our messages quote GDAL's; no "ERROR 1:" lines of its own

    GDALDatasetH src = GDALOpen(tile.c_str(), GA_ReadOnly);
    if (!src) throw hc::Error(tile.string() + ": cannot open: " + gdalMessage());
    std::vector<std::string> warpArgs{"-of", "GTiff",   "-t_srs", "EPSG:32632", "-r", "bilinear",
                                      "-ot", "Float32", "-tr",    "90",         "90"};
    GDALWarpAppOptions* warpOptions = GDALWarpAppOptionsNew(argvOf(warpArgs).data(), nullptr);
    const std::string projected = (work / "N00E010_utm32n.tif").string();
    fs::remove(projected);  // GDALWarp would otherwise warp into the existing file
    int usageError = 0;
    GDALDatasetH out = GDALWarp(projected.c_str(), nullptr, 1, &src, warpOptions, &usageError);
    GDALWarpAppOptionsFree(warpOptions);
    GDALClose(src);
    if (!out || usageError) throw hc::Error(projected + ": GDALWarp failed: " + gdalMessage());
    GDALClose(out);

    // d: the mosaic warped to 30 m UTM squares (27 Mpx of Float32, 110 MB): how memory scales.
    const std::string names0[2] = {fs::absolute(tile).string(), fs::absolute(east).string()};
    const char* sources0[2] = {names0[0].c_str(), names0[1].c_str()};
    GDALDatasetH vrt = GDALBuildVRT("", 2, nullptr, sources0, nullptr, &usageError);
    if (!vrt || usageError) throw hc::Error("GDALBuildVRT failed: " + gdalMessage());
    std::vector<std::string> fineArgs{"-of", "GTiff",   "-t_srs", "EPSG:32632", "-r", "bilinear",
                                      "-ot", "Float32", "-tr",    "30",         "30"};
    GDALWarpAppOptions* fineOptions = GDALWarpAppOptionsNew(argvOf(fineArgs).data(), nullptr);
    const std::string fine = (work / "N00E010+E011_utm32n_30m.tif").string();
    fs::remove(fine);
    out = GDALWarp(fine.c_str(), nullptr, 1, &vrt, fineOptions, &usageError);
    GDALWarpAppOptionsFree(fineOptions);
    GDALClose(vrt);
    if (!out || usageError) throw hc::Error(fine + ": GDALWarp failed: " + gdalMessage());
    GDALClose(out);

    const std::string names[2] = {fs::absolute(tile).string(), fs::absolute(east).string()};
    const char* sources[2] = {names[0].c_str(), names[1].c_str()};
    const std::string mosaic = (work / "N00E010+E011.vrt").string();
    out = GDALBuildVRT(mosaic.c_str(), 2, nullptr, sources, nullptr, &usageError);
    if (!out || usageError) throw hc::Error(mosaic + ": GDALBuildVRT failed: " + gdalMessage());
    GDALClose(out);
}

// One run of one case, in its own child.
RunResult runCase(const std::string& input, Path path, double toleranceM, std::optional<double> maxCellM,
                  unsigned threads, const std::string& gridPath) {
    return inChild<RunResult>(input, [&](RunResult& r) {
        GDALAllRegister();  // the baseline includes GDAL's drivers: they are not the ingest's memory
        {
            // ... nor PROJ's database and code, which the first CRS look-up maps in (a fixed ~10 MB
            // whatever the raster's size): warm them up before the baseline.
            OGRSpatialReference warm;
            warm.importFromEPSG(32632);
            char* wkt = nullptr;
            warm.exportToWkt(&wkt);
            CPLFree(wkt);
        }
        r.baselineRss = hc::currentRssBytes();

        hc::ingest::Options o;  // defaults, but for what the options below set and a silent terminal
        o.input = input;
        o.toleranceM = toleranceM;
        o.maxCellM = maxCellM;
        o.threads = threads;
        o.progress = false;
        hc::ingest::LoadReport report;
        const hc::IngestStats* stats = nullptr;
        hc::Grid g;
        hc::ingest::BuildSummary summary;
        hc::Stopwatch clock;
        if (path == Path::Memory) {
            g = hc::ingest::ingest(o, report);
            r.ingestS = clock.lap();
            r.peakRss = hc::peakRssBytes();  // before writing: the ingest's own peak
            hc::writeGrid(g, gridPath);
            r.writeS = clock.seconds();
            r.cells = g.cellCount();
            stats = &g.stats;
        } else {
            summary = hc::ingest::ingestToFile(o, gridPath, report);
            r.ingestS = clock.seconds();
            r.peakRss = hc::peakRssBytes();
            r.cells = summary.cellCount;
            stats = &summary.shape.stats;
        }
        r.sourceWidth = report.sourceWidth;
        r.sourceHeight = report.sourceHeight;
        r.workingWidth = stats->sourceWidth;
        r.workingHeight = stats->sourceHeight;
        r.maxDevM = stats->maxDevM;
        r.rmsDevM = stats->rmsDevM;
    });
}

// One table row: the best times and the largest memory over the repeats.
struct Row {
    const Input* input;
    Path path;
    double toleranceM;
    RunResult last;  // sizes, cells and deviations (the same in every run)
    double ingestS = 1e300, writeS = 1e300, totalS = 1e300;
    uint64_t peakRss = 0, ingestRss = 0;

    double sourcePixels() const { return double(last.sourceWidth) * double(last.sourceHeight); }
    double mpxPerS() const { return sourcePixels() / ingestS / 1e6; }
    double rasterMultiple() const { return double(ingestRss) / (sourcePixels() * 4.0); }
    bool meetsSpeed() const { return mpxPerS() >= kTargetMpxPerS; }
    bool meetsMemory() const { return rasterMultiple() <= kTargetRasterMultiple; }
};

std::string dims(uint64_t w, uint64_t h) { return std::to_string(w) + "x" + std::to_string(h); }
double mb(uint64_t bytes) { return double(bytes) / 1e6; }

void printTable(const std::vector<Row>& rows) {
    std::printf("%-5s %-6s %5s %11s %11s %9s %9s %8s %8s %12s %11s %13s %12s %9s %7s\n", "input", "path", "tol m",
                "source px", "working px", "cells", "ingest ms", "write ms", "total ms", "source Mpx/s", "peak RSS MB",
                "ingest RSS MB", "x raster f32", "max dev m", "RMS m");
    for (const Row& r : rows) {
        // stream: the write happens inside ingest
        const std::string write = r.path == Path::Memory ? fmt::format("{:.1f}", r.writeS * 1e3) : "incl.";
        std::printf("%-5c %-6s %5.3g %11s %11s %9llu %9.1f %8s %8.1f %12.2f %11.1f %13.1f %12.2f %9.4f %7.4f\n",
                    r.input->id, pathName(r.path), r.toleranceM, dims(r.last.sourceWidth, r.last.sourceHeight).c_str(),
                    dims(r.last.workingWidth, r.last.workingHeight).c_str(), (unsigned long long)r.last.cells,
                    r.ingestS * 1e3, write.c_str(), r.totalS * 1e3, r.mpxPerS(), mb(r.peakRss), mb(r.ingestRss),
                    r.rasterMultiple(), r.last.maxDevM, r.last.rmsDevM);
    }
}

void printTargets(const std::vector<Row>& rows) {
    std::printf("\ntargets\n  speed: >= %.0f M source pixels/s of ingest, projected input (b)\n", kTargetMpxPerS);
    for (const Row& r : rows)
        if (r.input->projected)
            std::printf("    %c %-6s tol %-5.3g %7.2f Mpx/s   %s\n", r.input->id, pathName(r.path), r.toleranceM,
                        r.mpxPerS(), r.meetsSpeed() ? "met" : "MISSED");
    std::printf("  memory: ingest RSS <= %.0f x the source raster as float32 (source px x 4 bytes), every input\n",
                kTargetRasterMultiple);
    for (const Row& r : rows)
        std::printf("    %c %-6s tol %-5.3g %7.1f MB = %5.2f x %6.1f MB   %s\n", r.input->id, pathName(r.path),
                    r.toleranceM, mb(r.ingestRss), r.rasterMultiple(), r.sourcePixels() * 4 / 1e6,
                    r.meetsMemory() ? "met" : "MISSED");
}

void writeCsv(const std::vector<Row>& rows, const std::string& path) {
    std::ofstream f(path);
    if (!f) throw hc::Error(path + ": cannot open for writing (--csv)");
    f << "input,file,path,tolerance_m,source_width,source_height,working_width,working_height,cells,ingest_ms,write_ms,"
         "total_ms,source_mpx_per_s,peak_rss_mb,ingest_rss_mb,x_raster_f32,max_dev_m,rms_m,speed_target,memory_"
         "target\n";
    for (const Row& r : rows) {
        // write_ms is empty for stream: the write happens inside ingest
        const std::string write = r.path == Path::Memory ? fmt::format("{:.3f}", r.writeS * 1e3) : "";
        f << fmt::format(
            "{},{},{},{:g},{},{},{},{},{},{:.3f},{},{:.3f},{:.4f},{:.2f},{:.2f},{:.4f},{:.6g},{:.6g},{},{}\n",
            r.input->id, r.input->file, pathName(r.path), r.toleranceM, r.last.sourceWidth, r.last.sourceHeight,
            r.last.workingWidth, r.last.workingHeight, r.last.cells, r.ingestS * 1e3, write, r.totalS * 1e3,
            r.mpxPerS(), mb(r.peakRss), mb(r.ingestRss), r.rasterMultiple(), r.last.maxDevM, r.last.rmsDevM,
            r.input->projected ? (r.meetsSpeed() ? "met" : "MISSED") : "n/a", r.meetsMemory() ? "met" : "MISSED");
    }
    if (!f.flush()) throw hc::Error(path + ": write failed (--csv)");
}

// The default work folder is ours: removed at exit, on errors too. A --work folder is the user's: kept.
struct TempDir {
    fs::path path;
    ~TempDir() {
        std::error_code ec;
        if (!path.empty()) fs::remove_all(path, ec);
    }
};

}  // namespace

int main(int argc, char** argv) {
    return hc::cli::run("hc-bench-ingest", [&] {
        std::string dataDir = "../shared/data", workDir, tolerances = "0.25,1", paths = "mem,stream", csv, plot;
        std::optional<double> maxCellM;
        int repeat = 3;
        unsigned threads = 0;
        hc::cli::Parser p(
            "hc-bench-ingest", "[options]",
            "Benchmarks ingest (raster -> grid) on real SRTM3 data: (a) N00E010.hgt, geographic, projected\n"
            "to UTM by the ingest; (b) the same tile warped to UTM 32N, Float32, 90 m (the projected case);\n"
            "(c) the mosaic N00E010 + N00E011, 2401 x 1201. Each input, tolerance and path runs in fresh\n"
            "child processes; it prints best times, peak memory and achieved deviation, then checks the\n"
            "targets (>= 10 M source px/s for (b); ingest memory <= 3 x the raster as float32). MB = 10^6 bytes.");
        p.option("--data", "DIR",
                 "folder holding N00E010.hgt and N00E011.hgt.zip (default ../shared/data, from the current directory)",
                 dataDir);
        p.option("--work", "DIR",
                 "folder for the prepared inputs and written grids; created if missing and kept\n"
                 "      (default: a fresh /tmp/hc-bench-ingest-XXXXXX, removed at exit)",
                 workDir);
        p.option("--tolerances", "LIST",
                 "comma-separated ingest tolerances, metres; one row per input and tolerance (default 0.25,1)",
                 tolerances);
        p.option("--paths", "LIST",
                 "comma-separated: mem = ingest() then writeGrid(), the grid in memory; stream =\n"
                 "      ingestToFile(), cells streamed into the file as hc-ingest does (default mem,stream)",
                 paths);
        p.option("--repeat", "N",
                 "runs per case, each in a fresh process; times are the best run, memory the largest (default 3)",
                 repeat);
        p.option("--max-cell", "M",
                 "coarsest cell, metres (default: the ingest's, largest finest * 2^k <= 96 m, which for\n"
                 "      90 m SRTM pixels is the pixel itself: no cell merges and the tolerance changes nothing)",
                 maxCellM);
        p.option("--threads", "N", "ingest worker threads (default 0 = all cores)", threads);
        p.option("--csv", "OUT.csv", "also write the table's rows as CSV with a header line (default: none)", csv);
        p.option("--plot", "PREFIX",
                 "also draw the table as two SVG plots, PREFIX_speed.svg (source Mpx/s per row, the\n"
                 "      10 Mpx/s target) and PREFIX_memory.svg (ingest RSS / raster float32 size, the 3x target) "
                 "(default: none)",
                 plot);
        if (!p.parse(argc, argv)) return 0;
        if (repeat < 1) throw hc::Error("--repeat " + std::to_string(repeat) + ": must be at least 1");
        std::vector<double> tols;
        for (const std::string& t : splitList(tolerances, "--tolerances")) {
            tols.push_back(hc::cli::parseNumber(t, "--tolerances"));
            if (tols.back() < 0) throw hc::Error("--tolerances " + t + ": tolerances are metres >= 0");
        }
        std::vector<Path> pathList;
        for (const std::string& name : splitList(paths, "--paths")) {
            if (name != "mem" && name != "stream") throw hc::Error("--paths " + name + ": not a path (mem or stream)");
            pathList.push_back(name == "mem" ? Path::Memory : Path::Stream);
        }
        if (!csv.empty()) hc::cli::checkWritable(csv, "--csv");
        if (!plot.empty()) hc::cli::checkWritable(plot + "_speed.svg", "--plot");
        const fs::path tile = fs::path(dataDir) / "N00E010.hgt", east = fs::path(dataDir) / "N00E011.hgt.zip";
        for (const fs::path& f : {tile, east})
            if (!fs::is_regular_file(f))
                throw hc::Error(
                    f.string() +
                    ": missing (the SRTM tile this benchmark needs; point --data at the folder holding it)");

        TempDir temp;
        fs::path work;
        if (workDir.empty()) {
            std::string pattern = (fs::temp_directory_path() / "hc-bench-ingest-XXXXXX").string();
            if (!mkdtemp(pattern.data()))
                throw hc::Error(pattern + ": cannot create a work folder: " + std::strerror(errno));
            work = temp.path = pattern;
        } else {
            work = workDir;
            std::error_code ec;
            fs::create_directories(work, ec);
            if (!fs::is_directory(work)) throw hc::Error(workDir + ": cannot create the work folder (--work)");
        }

        std::printf("preparing inputs in %s ...\n", work.c_str());
        inChild<Nothing>("preparing the inputs", [&](Nothing&) { prepareInputs(tile, east, work); });
        const std::vector<Input> inputs{
            {'a', tile.string(), "N00E010.hgt: geographic Int16, projected to UTM 32N by the ingest (GeographicLib)",
             false},
            {'b', (work / "N00E010_utm32n.tif").string(),
             "N00E010_utm32n.tif: warped by GDAL to EPSG:32632, Float32, 90 m, kept as is", true},
            {'c', (work / "N00E010+E011.vrt").string(),
             "N00E010+E011.vrt: VRT mosaic of the two tiles, geographic, like a", false},
            {'d', (work / "N00E010+E011_utm32n_30m.tif").string(),
             "N00E010+E011_utm32n_30m.tif: the mosaic warped to 30 m UTM 32N, Float32 (scaling)", true},
        };

        std::vector<Row> rows;
        const bool interactive = isatty(STDERR_FILENO);  // a "run k of n" line only for a person watching
        for (const Input& in : inputs)
            for (double tol : tols)
                for (Path path : pathList) {
                    Row row{&in, path, tol, {}};
                    const std::string gridName = fmt::format("{}-{}-tol{:g}.hcg", in.id, pathName(path), tol);
                    for (int k = 0; k < repeat; ++k) {
                        if (interactive)
                            std::fprintf(stderr, "\r%c %s tolerance %g m: run %d of %d ", in.id, pathName(path), tol,
                                         k + 1, repeat);
                        RunResult r = runCase(in.file, path, tol, maxCellM, threads, (work / gridName).string());
                        if (k > 0 && r.cells != row.last.cells)
                            std::fprintf(stderr,
                                         "\nhc-bench-ingest: warning: %c at %g m gave %llu cells, then %llu: not "
                                         "deterministic\n",
                                         in.id, tol, (unsigned long long)row.last.cells, (unsigned long long)r.cells);
                        row.last = r;
                        row.ingestS = std::min(row.ingestS, r.ingestS);
                        row.writeS = std::min(row.writeS, r.writeS);
                        row.totalS = std::min(row.totalS, r.ingestS + r.writeS);
                        row.peakRss = std::max(row.peakRss, r.peakRss);
                        row.ingestRss =
                            std::max(row.ingestRss, r.peakRss > r.baselineRss ? r.peakRss - r.baselineRss : 0);
                    }
                    rows.push_back(row);
                }
        if (interactive) std::fprintf(stderr, "\r%60s\r", "");

        std::printf("\ninputs\n");
        for (const Input& in : inputs) std::printf("  %c  %s\n", in.id, in.what.c_str());
        const std::string maxCell = maxCellM ? fmt::format("{:g} m", *maxCellM) : "default";
        std::printf(
            "\nbest of %d run%s, ingest threads %s, max cell %s; paths: mem = ingest() then writeGrid(), stream =\n"
            "ingestToFile() (hc-ingest; its ingest ms includes writing); peak = max RSS of the run's process when "
            "ingest\n"
            "returned; ingest RSS = peak - RSS before ingest (after GDALAllRegister and a first CRS look-up); x raster "
            "f32 = ingest RSS / (source\n"
            "px x 4 B); total = best of ingest + write; source Mpx/s = source px / best ingest time; MB = 10^6 "
            "bytes\n\n",
            repeat, repeat == 1 ? "" : "s", threads ? std::to_string(threads).c_str() : "all cores", maxCell.c_str());
        printTable(rows);
        printTargets(rows);
        if (!csv.empty()) {
            writeCsv(rows, csv);
            std::printf("\nrows written to %s\n", csv.c_str());
        }
        if (!plot.empty() && !rows.empty()) {
            hc::bench::BarPlot speed, memory;
            speed.title =
                "hc-bench-ingest: source pixels per second of ingest (best of " + std::to_string(repeat) + ")";
            speed.xLabel = "M source pixels / s";
            speed.segmentNames = {"Mpx/s"};
            speed.markers = {
                {"target " + fmt::format("{:g}", kTargetMpxPerS) + " Mpx/s (projected input b)", kTargetMpxPerS}};
            memory.title = "hc-bench-ingest: ingest memory as a multiple of the raster's float32 size";
            memory.xLabel = "ingest RSS / (source px x 4 bytes)";
            memory.segmentNames = {"x raster f32"};
            memory.markers = {{"target " + fmt::format("{:g}", kTargetRasterMultiple) + "x", kTargetRasterMultiple}};
            for (const Row& r : rows) {
                const std::string label =
                    std::string(1, r.input->id) + " " + pathName(r.path) + " tol " + fmt::format("{:g}", r.toleranceM);
                speed.rows.push_back({label, {r.mpxPerS()}});
                memory.rows.push_back({label, {r.rasterMultiple()}});
            }
            hc::bench::writeSvg(plot + "_speed.svg", speed.svg());
            hc::bench::writeSvg(plot + "_memory.svg", memory.svg());
            std::printf("plots written to %s_speed.svg and %s_memory.svg\n", plot.c_str(), plot.c_str());
        }
        return 0;
    });
}
