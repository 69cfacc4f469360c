// hc-probe: the exact smooth surface at given points.
#include <cstdio>
#include <string>
#include <vector>

#include "cli.h"
#include "heightcast/core/atomic_file.h"
#include "heightcast/core/error.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/influence/region.h"
#include "heightcast/influence/surface.h"

namespace {

struct ProbeArgs {
    std::string gridPath, cachePath, layerName = "elevation", pointsPath, xy, out;
    hc::influence::KernelParams params;
    unsigned threads = 0;
};

// The options, validated before any work; false after --help.
bool parseOptions(int argc, char** argv, ProbeArgs& a) {
    hc::cli::Parser p("hc-probe", "GRID.hcg [--cache C.hci] [--layer L] (--points IN.csv | --xy X,Y) [-o OUT.csv]",
                      "Evaluates the exact smooth surface (double precision) at points given in the grid's CRS [m].\n"
                      "Reads only the cells whose kernels reach the points (a group of points at a time), so one point\n"
                      "of a 100 M-cell grid takes milliseconds and no influence cache.\n"
                      "Prints or writes x,y,value with full precision; the value is empty where the surface is\n"
                      "undefined (holes, outside the grid, or dry land for water_surface).\n"
                      "Water (DESIGN.md section 12): water_surface is the level of the wet cells alone (a level flood\n"
                      "stays level), drawn where wet cells hold >= 1/2 of the kernel weight and the level is above the\n"
                      "terrain; water_depth is that level - elevation there and 0 on dry land, in metres.");
    p.positional("GRID.hcg", "grid file", a.gridPath);
    p.option("--cache", "C.hci", "read the whole grid and this influence cache (built if missing or stale) instead of the cells\n"
             "around the points (default: those cells only, read from the grid file with their lists built on\n"
             "the spot: no cache needed, memory follows the points; the values are the same bits)", a.cachePath);
    p.option("--layer", "L", "elevation, water_depth, water_surface or another layer of the grid (default elevation)", a.layerName);
    p.option("--points", "IN.csv", "CSV with a header line starting x,y and one point per line", a.pointsPath);
    p.option("--xy", "X,Y", "a single point", a.xy);
    p.option("-o", "OUT.csv", "output CSV (default: standard output)", a.out);
    p.option("--sigma", "S", "kernel width in cell sizes (default 1.0)", a.params.sigma);
    p.option("--truncation", "R", "kernel cut-off in sigmas (default 3.5)", a.params.truncation);
    p.option("--threads", "N", "worker threads (default 0 = all cores)", a.threads);
    p.exclusive({"--points", "--xy"});
    if (!p.parse(argc, argv)) return false;
    if (a.pointsPath.empty() && a.xy.empty()) throw hc::Error("give --points IN.csv or --xy X,Y");
    if (std::string why = a.params.validate(); !why.empty()) throw hc::Error("--sigma/--truncation: " + why);
    if (!a.out.empty()) {
        hc::cli::checkWritable(a.out, "output CSV");
        hc::cli::checkNotSame(a.out, a.gridPath, "output CSV");
        if (!a.pointsPath.empty()) hc::cli::checkNotSame(a.out, a.pointsPath, "output CSV");
    }
    return true;
}

// The --xy point or the --points file's, in the grid's CRS [m].
std::vector<std::array<double, 2>> readPoints(const ProbeArgs& a) {
    if (a.xy.empty()) return hc::cli::readPointsCsv(a.pointsPath);
    const auto v = hc::cli::parseNumberList(a.xy, "--xy", 2, 2);
    return {{v[0], v[1]}};
}

// The surface's layer at each point; empty where it is undefined. By default from the cells around the points
// (influence/region.h), saying how many were read; with --cache from the whole grid and that cache (loaded or
// built, saying which). Both give the same bits.
std::vector<std::optional<double>> evaluate(const ProbeArgs& a, const std::vector<std::array<double, 2>>& pts) {
    if (a.cachePath.empty()) {
        const hc::GridRegionReader file(a.gridPath);
        const hc::Grid& shape = file.shape();
        const auto layer = hc::influence::Layer::byName(shape, a.layerName);
        std::vector<std::array<double, 2>> local(pts.size());
        for (size_t i = 0; i < pts.size(); ++i) local[i] = {pts[i][0] - shape.originWorldX, pts[i][1] - shape.originWorldY};
        hc::influence::RegionReadStats st;
        auto values = hc::influence::valuesFromFile(file, local, layer, a.params, a.threads, &st);
        std::fprintf(stderr,
                     "hc-probe: read %llu of the grid's %llu cells around the points (%llu region%s, the largest %llu cells; "
                     "%.1f MB of the file checked) and built their lists: no influence cache used\n",
                     (unsigned long long)st.cellsRead, (unsigned long long)file.cellCount(), (unsigned long long)st.regions,
                     st.regions == 1 ? "" : "s", (unsigned long long)st.largestRegion, double(file.bytesChecked()) / 1e6);
        return values;
    }
    const hc::Grid grid = hc::readGrid(a.gridPath);
    const auto layer = hc::influence::Layer::byName(grid, a.layerName);
    std::string note;
    const auto lists = hc::influence::loadOrBuildCache(grid, a.params, a.cachePath, a.threads, false, note);
    std::fprintf(stderr, "hc-probe: %s\n", note.c_str());
    const hc::influence::SurfaceEvaluator eval(grid, lists);
    std::vector<std::array<double, 2>> local(pts.size());
    for (size_t i = 0; i < pts.size(); ++i) local[i] = {pts[i][0] - grid.originWorldX, pts[i][1] - grid.originWorldY};
    return eval.values(local, layer, a.threads);
}

// x,y,value lines in full precision (%.17g), the value empty where it is undefined.
std::string toCsv(const std::vector<std::array<double, 2>>& pts, const std::vector<std::optional<double>>& values) {
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
    return text;
}

// To -o's file (atomically) or to standard output.
void writeOutput(const std::string& out, const std::string& text) {
    if (out.empty()) {
        std::fwrite(text.data(), 1, text.size(), stdout);
        return;
    }
    hc::AtomicFileWriter w(out);
    w.write(std::as_bytes(std::span(text)));
    w.commit();
}

}  // namespace

int main(int argc, char** argv) {
    return hc::cli::run("hc-probe", [&] {
        ProbeArgs a;
        if (!parseOptions(argc, argv, a)) return 0;
        const std::vector<std::array<double, 2>> pts = readPoints(a);
        const std::vector<std::optional<double>> values = evaluate(a, pts);
        writeOutput(a.out, toCsv(pts, values));
        return 0;
    });
}
