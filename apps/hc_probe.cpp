// hc-probe: the exact smooth surface at given points.
#include <algorithm>
#include <cstdio>
#include <optional>
#include <string>
#include <vector>

#include "heightcast/support/cli.h"
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
    unsigned step = 0;      // --step
    bool allSteps = false;  // --all-steps: the hydrograph
};

// The options, validated before any work; false after --help.
bool parseOptions(int argc, char** argv, ProbeArgs& a) {
    hc::cli::Parser p(
        "hc-probe", "GRID.hcg [--cache C.hci] [--layer L] (--points IN.csv | --xy X,Y) [-o OUT.csv]",
        "Evaluates the exact smooth surface (double precision) at points given in the grid's CRS [m].\n"
        "Reads only the cells whose kernels reach the points (a group of points at a time), so one point\n"
        "of a 100 M-cell grid takes milliseconds and no influence cache.\n"
        "Prints or writes x,y,value with full precision; the value is empty where the surface is\n"
        "undefined (holes, outside the grid, or dry land for water_surface).\n"
        "Water (docs/design.md section 6): water_surface is the level of the wet cells alone (a level flood\n"
        "stays level), drawn where wet cells hold >= 1/2 of the kernel weight and the level is above the\n"
        "terrain; water_depth is that level - elevation there and 0 on dry land, in metres.");
    p.positional("GRID.hcg", "grid file", a.gridPath);
    p.option("--cache", "C.hci",
             "read the whole grid and this influence cache (built if missing or stale) instead of the cells\n"
             "around the points (default: those cells only, read from the grid file with their lists built on\n"
             "the spot: no cache needed, memory follows the points; the values are the same bits)",
             a.cachePath);
    p.option("--layer", "L", "elevation, water_depth, water_surface or another layer of the grid (default elevation)",
             a.layerName);
    p.option("--points", "IN.csv", "CSV with a header line starting x,y and one point per line", a.pointsPath);
    p.option("--xy", "X,Y", "a single point", a.xy);
    p.option("-o", "OUT.csv", "output CSV (default: standard output)", a.out);
    p.option("--step", "K", "water step to evaluate, 0-based (default 0; hc-info lists a grid's steps and their times)",
             a.step);
    p.flag("--all-steps",
           "every water step, in order: each point's hydrograph as CSV x,y,step,time_s,value (time in seconds;\n"
           "      the influence data is shared, each step reads its own water only)",
           a.allSteps);
    p.exclusive({"--step", "--all-steps"});
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
class Prober {
public:
    Prober(const ProbeArgs& a) : a_(a) {}
    // The layer at each point for water step `step`; `quiet`: no note on stderr.
    std::vector<std::optional<double>> values(const std::vector<std::array<double, 2>>& pts, size_t step, bool quiet);

private:
    const ProbeArgs& a_;
    std::optional<hc::Grid> grid_;  // --cache: the whole grid, its step switched in place
    std::optional<hc::influence::InfluenceLists> lists_;
};

std::vector<std::optional<double>> Prober::values(const std::vector<std::array<double, 2>>& pts, size_t step,
                                                  bool quiet) {
    const ProbeArgs& a = a_;
    if (a.cachePath.empty()) {
        const hc::GridRegionReader file(a.gridPath, step);
        const hc::Grid& shape = file.shape();
        const auto layer = hc::influence::Layer::byName(shape, a.layerName);
        std::vector<std::array<double, 2>> local(pts.size());
        for (size_t i = 0; i < pts.size(); ++i) shape.worldToLocal(pts[i][0], pts[i][1], local[i][0], local[i][1]);
        hc::influence::RegionReadStats st;
        auto values = hc::influence::valuesFromFile(file, local, layer, a.params, a.threads, &st);
        if (!quiet)
            std::fprintf(stderr,
                         "hc-probe: read %llu of the grid's %llu cells around the points (%llu region%s, the largest "
                         "%llu cells; "
                         "%.1f MB of the file checked) and built their lists: no influence cache used\n",
                         (unsigned long long)st.cellsRead, (unsigned long long)file.cellCount(),
                         (unsigned long long)st.regions, st.regions == 1 ? "" : "s",
                         (unsigned long long)st.largestRegion, double(file.bytesChecked()) / 1e6);
        return values;
    }
    if (!grid_) {
        grid_ = hc::readGrid(a.gridPath, nullptr, step);
        std::string note;
        lists_ = hc::influence::loadOrBuildCache(*grid_, a.params, a.cachePath, a.threads, false, note);
        std::fprintf(stderr, "hc-probe: %s\n", note.c_str());
    } else if (grid_->step != step) {
        hc::readGridStep(a.gridPath, *grid_, step);  // the lists stay: they depend on the structure only
    }
    const hc::Grid& grid = *grid_;
    const auto layer = hc::influence::Layer::byName(grid, a.layerName);
    const hc::influence::SurfaceEvaluator eval(grid, *lists_);
    std::vector<std::array<double, 2>> local(pts.size());
    for (size_t i = 0; i < pts.size(); ++i) grid.worldToLocal(pts[i][0], pts[i][1], local[i][0], local[i][1]);
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
        Prober prober(a);
        if (!a.allSteps) {
            writeOutput(a.out, toCsv(pts, prober.values(pts, a.step, false)));
            return 0;
        }
        // The hydrograph: every step, the points in the order given within each step.
        const hc::Grid shape = hc::readGridInfo(a.gridPath).shape;
        const size_t steps = std::max<size_t>(1, shape.stepCount());
        std::string text = "x,y,step,time_s,value\n";
        char buf[160];
        for (size_t k = 0; k < steps; ++k) {
            const auto values = prober.values(pts, k, k > 0);
            const double t = k < shape.steps.size() ? shape.steps[k].timeS : 0.0;
            for (size_t i = 0; i < pts.size(); ++i) {
                std::snprintf(buf, sizeof buf, "%.17g,%.17g,%zu,%.17g,", pts[i][0], pts[i][1], k, t);
                text += buf;
                if (values[i]) {
                    std::snprintf(buf, sizeof buf, "%.17g", *values[i]);
                    text += buf;
                }
                text += '\n';
            }
        }
        if (steps > 1)
            std::fprintf(stderr, "hc-probe: %zu steps, %zu point%s each\n", steps, pts.size(),
                         pts.size() == 1 ? "" : "s");
        writeOutput(a.out, text);
        return 0;
    });
}
