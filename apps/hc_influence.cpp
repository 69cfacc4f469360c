// hc-influence: grid -> influencing-cell lists (.hci cache).
#include <cstdio>

#include "cli.h"
#include "heightcast/core/error.h"
#include "heightcast/core/progress.h"
#include "heightcast/core/timer.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/influence/influence.h"

namespace {

struct InfluenceArgs {
    std::string gridPath, out;
    hc::influence::KernelParams params;
    unsigned threads = 0;
    bool quiet = false;
};

// The options, validated before any work; false after --help.
bool parseOptions(int argc, char** argv, InfluenceArgs& a) {
    hc::cli::Parser p("hc-influence", "GRID.hcg [-o OUT.hci] [--sigma S] [--truncation R]",
                      "Builds the influence list of every cell (the cells whose truncated Gaussian reaches into it)\n"
                      "and writes them as a cache that hc-probe, hc-export and the renderer reuse. A cache depends\n"
                      "only on the grid's tree, sigma and R: new water values on the same tree keep it valid.");
    p.positional("GRID.hcg", "grid file (hc-ingest)", a.gridPath);
    p.option("-o", "OUT.hci", "cache file (default: the grid's path with .hci)", a.out);
    p.option("--sigma", "S", "Gaussian width in cell sizes (default 1.0, the report's)", a.params.sigma);
    p.option("--truncation", "R", "kernel cut-off in sigmas; a cell reaches R * sigma cell sizes (default 3.5)", a.params.truncation);
    p.option("--threads", "N", "worker threads (default 0 = all cores)", a.threads);
    p.flag("--quiet", "no progress output", a.quiet);
    if (!p.parse(argc, argv)) return false;
    if (std::string why = a.params.validate(); !why.empty()) throw hc::Error("--sigma/--truncation: " + why);
    if (a.out.empty()) a.out = hc::influence::defaultCachePath(a.gridPath);
    hc::cli::checkWritable(a.out, "influence cache");
    hc::cli::checkNotSame(a.out, a.gridPath, "influence cache");
    return true;
}

void printSummary(const InfluenceArgs& a, const hc::influence::InfluenceLists& lists, double buildS, double writeS) {
    auto s = lists.stats();
    std::printf("hc-influence: %s -> %s\n", a.gridPath.c_str(), a.out.c_str());
    std::printf("  kernel       truncated Gaussian, sigma %g, R %g (reach %g cell sizes)\n", a.params.sigma, a.params.truncation,
                a.params.truncation * a.params.sigma);
    std::printf("  cells        %zu\n", lists.cellCount());
    std::printf("  entries      %llu (per cell: mean %.1f, p99 %llu, max %llu)\n", (unsigned long long)lists.entryCount(),
                s.meanLength, (unsigned long long)s.p99Length, (unsigned long long)s.maxLength);
    std::printf("  bytes        %.1f MB\n", double(s.bytes) / 1e6);
    std::printf("  time         %.3f s build (%.2f M cells/s) + %.3f s write\n", buildS, double(lists.cellCount()) / buildS / 1e6,
                writeS);
    std::printf("  memory       peak %.1f MB resident\n", double(hc::peakRssBytes()) / 1e6);
}

}  // namespace

int main(int argc, char** argv) {
    return hc::cli::run("hc-influence", [&] {
        InfluenceArgs a;
        if (!parseOptions(argc, argv, a)) return 0;
        const hc::Grid grid = hc::readGrid(a.gridPath);
        hc::Stopwatch clock;
        const hc::influence::InfluenceLists lists = hc::influence::buildInfluenceLists(grid, a.params, a.threads, !a.quiet);
        const double buildS = clock.lap();
        hc::influence::writeInfluenceCache(lists, a.out);
        const double writeS = clock.lap();
        printSummary(a, lists, buildS, writeS);
        return 0;
    });
}
