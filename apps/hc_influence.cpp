// hc-influence: grid -> influencing-cell lists (.hci cache).
#include <cstdio>

#include "cli.h"
#include "heightcast/core/error.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/core/progress.h"
#include "heightcast/core/timer.h"
#include "heightcast/influence/influence.h"

int main(int argc, char** argv) {
    return hc::cli::run("hc-influence", [&] {
        std::string gridPath, out;
        hc::influence::KernelParams params;
        unsigned threads = 0;
        bool quiet = false;
        hc::cli::Parser p("hc-influence", "GRID.hcg [-o OUT.hci] [--sigma S] [--truncation R]",
                          "Builds the influence list of every cell (the cells whose truncated Gaussian reaches into it)\n"
                          "and writes them as a cache that hc-probe, hc-export and the renderer reuse. A cache depends\n"
                          "only on the grid's tree, sigma and R: new water values on the same tree keep it valid.");
        p.positional("GRID.hcg", "grid file (hc-ingest)", gridPath);
        p.option("-o", "OUT.hci", "cache file (default: the grid's path with .hci)", out);
        p.option("--sigma", "S", "Gaussian width in cell sizes (default 1.0, the report's)", params.sigma);
        p.option("--truncation", "R", "kernel cut-off in sigmas; a cell reaches R * sigma cell sizes (default 3.5)", params.truncation);
        p.option("--threads", "N", "worker threads (default 0 = all cores)", threads);
        p.flag("--quiet", "no progress output", quiet);
        if (!p.parse(argc, argv)) return 0;
        if (std::string why = params.validate(); !why.empty()) throw hc::Error("--sigma/--truncation: " + why);
        if (out.empty()) out = hc::influence::defaultCachePath(gridPath);
        hc::cli::checkWritable(out, "influence cache");
        hc::cli::checkNotSame(out, gridPath, "influence cache");

        hc::Grid grid = hc::readGrid(gridPath);
        hc::Stopwatch clock;
        hc::influence::InfluenceLists lists = hc::influence::buildInfluenceLists(grid, params, threads, !quiet);
        const double buildS = clock.lap();
        hc::influence::writeInfluenceCache(lists, out);
        const double writeS = clock.seconds();

        auto s = lists.stats();
        std::printf("hc-influence: %s -> %s\n", gridPath.c_str(), out.c_str());
        std::printf("  kernel       truncated Gaussian, sigma %g, R %g (reach %g cell sizes)\n", params.sigma, params.truncation,
                    params.truncation * params.sigma);
        std::printf("  cells        %zu\n", lists.cellCount());
        std::printf("  entries      %llu (per cell: mean %.1f, p99 %llu, max %llu)\n", (unsigned long long)lists.entryCount(),
                    s.meanLength, (unsigned long long)s.p99Length, (unsigned long long)s.maxLength);
        std::printf("  bytes        %.1f MB\n", double(s.bytes) / 1e6);
        std::printf("  time         %.3f s build (%.2f M cells/s) + %.3f s write\n", buildS,
                    double(lists.cellCount()) / buildS / 1e6, writeS);
        std::printf("  memory       peak %.1f MB resident\n", double(hc::peakRssBytes()) / 1e6);
        return 0;
    });
}
