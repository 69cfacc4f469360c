// hc-influence: grid -> influencing-cell lists (.hci cache) and the surface pyramid (.hcp).
#include <algorithm>
#include <cstdio>
#include <memory>
#include <optional>

#include <fmt/format.h>

#include "heightcast/support/cli.h"
#include "heightcast/support/on_ranks.h"
#include "heightcast/core/ranks.h"
#include "heightcast/core/error.h"
#include "heightcast/core/progress.h"
#include "heightcast/core/timer.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/influence/influence.h"
#include "heightcast/influence/on_ranks.h"
#include "heightcast/influence/pyramid.h"

namespace {

struct InfluenceArgs {
    std::string gridPath, out, pyramidOut;
    std::string listsWhy;  // why the default built the lists or not ("" when --lists or --no-lists said)
    hc::influence::KernelParams params;
    unsigned threads = 0;
    bool quiet = false;
    bool lists = true, pyramid = true;
    int step = -1;                          // --step: the one water step whose pyramid to build; -1: every step
    size_t stepCount = 0;                   // the grid's water steps
    std::vector<std::string> pyramidPaths;  // per step built (one entry when the grid has at most one step)
};

// The options, validated before any work; false after --help.
bool parseOptions(int argc, char** argv, InfluenceArgs& a) {
    bool noLists = false, noPyramid = false, lists = false;
    hc::cli::Parser p(
        "hc-influence", "GRID.hcg [-o OUT.hci] [-p OUT.hcp] [--sigma S] [--truncation R] [--no-lists | --no-pyramid]",
        "Builds the influence list of every cell (the cells whose truncated Gaussian reaches into it)\n"
        "and writes them as a cache that hc-probe, hc-export and the renderer reuse. A cache depends\n"
        "only on the grid's tree, sigma and R: new water values on the same tree keep it valid.\n"
        "Then samples the exact smooth surface into the surface pyramid (docs/design.md section 4): dyadic\n"
        "lattices (spacing finest cell * 2^t) in 16 x 16 tiles kept where cells are as fine as the\n"
        "spacing, each tile with its measured error against the next coarser level. The lists take\n"
        "about 220 bytes per cell; the pyramid about 4-20 per channel and needs no lists. By default the\n"
        "lists are built for grids of up to 4.5 M cells (1 GB of lists) and left out above, where the\n"
        "pyramid serves every tool and the grid is read a node (at most 4 M cells and their halo) at a\n"
        "time, never whole: any grid that fits the disk. Under `mpirun -np N` the ranks share the nodes\n"
        "of the grid, each reading its nodes and their halo, and write the same bytes as one process,\n"
        "each its lists and tiles into the files rank 1 opens: they must lie on a file system every rank\n"
        "sees (docs/mpi.md).");
    p.positional("GRID.hcg", "grid file (hc-ingest)", a.gridPath);
    p.option("-o", "OUT.hci", "cache file (default: the grid's path with .hci)", a.out);
    p.option("--sigma", "S", "Gaussian width in cell sizes (default 1.0, the report's)", a.params.sigma);
    p.option("--truncation", "R", "kernel cut-off in sigmas; a cell reaches R * sigma cell sizes (default 3.5)",
             a.params.truncation);
    p.option("-p", "OUT.hcp",
             "surface pyramid file (default: the grid's path with .hcp; with several water steps one per step,\n"
             "      GRID.step0007.hcp for step 7; -p then needs --step)",
             a.pyramidOut);
    p.option("--step", "K",
             "build the pyramid of water step K only, 0-based (default: every step; the lists serve all steps);\n"
             "      the first step's pyramid is whole, a later step's holds its water only, where it is drawn: the "
             "renderers\n"
             "      take the terrain from the first step's",
             a.step);
    p.option("--threads", "N", "worker threads (default 0 = all cores; under mpirun: per rank)", a.threads);
    p.flag("--lists", "build the lists whatever the grid's size (default: up to 4.5 M cells)", lists);
    p.flag("--no-lists", "build the surface pyramid only (no .hci)", noLists);
    p.flag("--no-pyramid", "build the influence lists only (no .hcp)", noPyramid);
    p.flag("--quiet", "no progress output", a.quiet);
    if (!p.parse(argc, argv)) return false;
    if (std::string why = a.params.validate(); !why.empty()) throw hc::Error("--sigma/--truncation: " + why);
    if (noLists && noPyramid) throw hc::Error("--no-lists and --no-pyramid together leave nothing to build");
    if (noLists && lists) throw hc::Error("--lists and --no-lists contradict each other");
    a.pyramid = !noPyramid;
    if (a.out.empty()) a.out = hc::influence::defaultCachePath(a.gridPath);
    const hc::GridFileInfo info = hc::readGridInfo(a.gridPath);
    a.stepCount = info.shape.stepCount();
    a.lists = !noLists;
    if (!lists && !noLists && !noPyramid) {  // the default: lists where they fit and help
        a.lists = info.cellCount <= hc::influence::kListsDefaultMaxCells;
        a.listsWhy = fmt::format("{} (about {:.1f} MB for {} cells; default up to {:.1f} M cells{})",
                                 a.lists ? "built" : "not built",
                                 hc::influence::kListBytesPerCell * double(info.cellCount) / 1e6, info.cellCount,
                                 double(hc::influence::kListsDefaultMaxCells) / 1e6,
                                 a.lists ? "; --no-lists skips them" : "; --lists builds them");
    }
    if (a.step < -1 || (a.step >= 0 && size_t(a.step) >= std::max<size_t>(1, a.stepCount)))
        throw hc::Error("--step " + std::to_string(a.step) + ": " + a.gridPath + " has " + std::to_string(a.stepCount) +
                        " water steps");
    if (!a.pyramidOut.empty() && a.stepCount > 1 && a.step < 0)
        throw hc::Error("-p names one pyramid file but " + a.gridPath + " has " + std::to_string(a.stepCount) +
                        " water steps: add --step K, or leave -p out for one file per step");
    if (!a.pyramidOut.empty()) {
        a.pyramidPaths = {a.pyramidOut};
    } else {
        for (size_t k = 0; k < std::max<size_t>(1, a.stepCount); ++k)
            if (a.step < 0 || size_t(a.step) == k)
                a.pyramidPaths.push_back(hc::influence::defaultPyramidPath(a.gridPath, k, a.stepCount));
    }
    if (a.lists) {
        hc::cli::checkWritable(a.out, "influence cache");
        hc::cli::checkNotSame(a.out, a.gridPath, "influence cache");
    }
    if (a.pyramid)
        for (const std::string& path : a.pyramidPaths) {
            hc::cli::checkWritable(path, "surface pyramid");
            hc::cli::checkNotSame(path, a.gridPath, "surface pyramid");
            if (a.lists) hc::cli::checkNotSame(path, a.out, "surface pyramid");
        }
    return true;
}

void printListsSummary(const InfluenceArgs& a, uint64_t cells, uint64_t entries,
                       const hc::influence::InfluenceLists::Stats& s, double buildS, double writeS) {
    std::printf("  lists        -> %s\n", a.out.c_str());
    std::printf("    entries    %llu (per cell: mean %.1f, p99 %llu, max %llu)\n", (unsigned long long)entries,
                s.meanLength, (unsigned long long)s.p99Length, (unsigned long long)s.maxLength);
    std::printf("    bytes      %.1f MB (%.1f per cell)\n", double(s.bytes) / 1e6,
                double(s.bytes) / double(std::max<uint64_t>(1, cells)));
    std::printf("    time       %.3f s build (%.2f M cells/s) + %.3f s write\n", buildS, double(cells) / buildS / 1e6,
                writeS);
}

// What the summary says of a pyramid: its levels' tiles and largest first-channel parent error, and its totals. Under
// mpirun each rank has its part; combined() adds them up on every rank.
struct PyramidSummary {
    int channels = 1;
    double finestCellM = 1;
    std::vector<uint64_t> tiles;
    std::vector<float> worstM;
    uint64_t samples = 0, bytes = 0;

    explicit PyramidSummary(const hc::influence::SurfacePyramid& p)
        : channels(p.channels), finestCellM(p.finestCellM), samples(p.sampleCount()), bytes(p.bytes()) {
        for (const auto& L : p.levels) {
            float worst = 0;
            for (size_t i = 0; i < L.parentErrorM.size(); i += size_t(p.channels))
                worst = std::max(worst, L.parentErrorM[i]);
            tiles.push_back(L.tileCount());
            worstM.push_back(worst);
        }
    }
    PyramidSummary(const hc::influence::PyramidFileSummary& f, double finestM)
        : channels(f.channels),
          finestCellM(finestM),
          tiles(f.tiles),
          worstM(f.worstM),
          samples(f.samples),
          bytes(f.bytes) {}
    double spacingM(size_t t) const { return finestCellM * double(uint64_t{1} << t); }
};

void printPyramidSummary(const std::string& path, const hc::Grid& grid, uint64_t cells, const PyramidSummary& p,
                         double buildS, double writeS) {
    if (grid.steps.size() > 1)
        std::printf("  step %zu       at %.9g s, %llu wet cells\n", grid.step, grid.stepTimeS(),
                    (unsigned long long)grid.steps[grid.step].wetCells);
    const size_t top = p.tiles.size() - 1;
    std::printf("  pyramid      -> %s\n", path.c_str());
    std::printf(
        "    levels     0..%zu (spacing %g .. %g m), %d channel%s\n", top, p.spacingM(0), p.spacingM(top), p.channels,
        p.channels == 1   ? " (elevation)"
        : p.channels == 2 ? "s (water level, wet share; the terrain is step 0's), in the tiles where water is drawn"
                          : "s (elevation, water level, wet share)");
    std::printf("    samples    %llu (%.2f per cell per channel)\n", (unsigned long long)p.samples,
                double(p.samples) / double(p.channels) / double(std::max<uint64_t>(1, cells)));
    std::printf("    bytes      %.1f MB (%.1f per cell)\n", double(p.bytes) / 1e6,
                double(p.bytes) / double(std::max<uint64_t>(1, cells)));
    std::printf("    level  spacing m    tiles   max error vs next level m\n");
    for (size_t t = 0; t <= top; ++t)
        std::printf("    %5zu %10g %8llu   %.4g\n", t, p.spacingM(t), (unsigned long long)p.tiles[t],
                    double(p.worstM[t]));
    std::printf("    time       %.3f s build (%.2f M samples/s) + %.3f s write\n", buildS,
                double(p.samples) / buildS / 1e6, writeS);
}

void printHeader(const InfluenceArgs& a, uint64_t cells) {
    std::printf("hc-influence: %s\n", a.gridPath.c_str());
    std::printf("  kernel       truncated Gaussian, sigma %g, R %g (reach %g cell sizes)\n", a.params.sigma,
                a.params.truncation, a.params.truncation * a.params.sigma);
    std::printf("  cells        %llu\n", (unsigned long long)cells);
    if (!a.listsWhy.empty()) std::printf("  lists        %s\n", a.listsWhy.c_str());
}

// One process building lists: the grid read whole, every list and tile built here.
void runAlone(const InfluenceArgs& a) {
    namespace inf = hc::influence;
    hc::Grid grid = hc::readGrid(a.gridPath, nullptr, a.step < 0 ? 0 : size_t(a.step));
    printHeader(a, grid.cellCount());
    hc::Stopwatch clock;
    if (a.lists) {
        const inf::InfluenceLists lists = inf::buildInfluenceLists(grid, a.params, a.threads, !a.quiet);
        const double buildS = clock.lap();
        inf::writeInfluenceCache(lists, a.out);
        printListsSummary(a, lists.cellCount(), lists.entryCount(), lists.stats(), buildS, clock.lap());
    }
    std::optional<hc::StaticDigests> digests;
    for (size_t i = 0; a.pyramid && i < a.pyramidPaths.size(); ++i) {
        // One pyramid per water step; the grid switches steps reading only the next step's section.
        if (a.step < 0 && i > 0) {
            if (!digests) digests = hc::staticDigestsOf(grid);  // hashed once, not per step
            hc::readGridStep(a.gridPath, grid, i, &*digests);
        }
        clock.lap();
        // A scenario's later steps keep their water only: the first step's pyramid holds the terrain for all.
        const inf::SurfacePyramid pyramid = grid.steps.size() > 1 && grid.step > 0
                                                ? inf::buildWaterPyramid(grid, a.params, a.threads, !a.quiet)
                                                : inf::buildSurfacePyramid(grid, a.params, a.threads, !a.quiet);
        const double buildS = clock.lap();
        inf::writeSurfacePyramid(pyramid, a.pyramidPaths[i]);
        printPyramidSummary(a.pyramidPaths[i], grid, grid.cellCount(), PyramidSummary(pyramid), buildS, clock.lap());
    }
}

// The ranks of mpirun (on_ranks.h), or one process without lists: no rank reads the grid whole; each builds its nodes
// from regions of the file and writes its lists and pyramid tiles at their place in the files rank 0 opens. Every
// collective step runs in ranks::together, so a failure anywhere stops every rank there.
void runByNodes(const InfluenceArgs& a) {
    namespace inf = hc::influence;
    namespace ranks = hc::ranks;
    const bool root = ranks::rank() == 0, progress = !a.quiet && root;
    const hc::Stopwatch all;
    std::unique_ptr<hc::GridRegionReader> file;
    ranks::together(
        [&] { file = std::make_unique<hc::GridRegionReader>(a.gridPath, a.step < 0 ? 0 : size_t(a.step)); });
    printHeader(a, file->cellCount());
    const inf::RankPartition part = inf::partitionOf(*file, ranks::count());
    uint64_t myNodes = 0, myCells = 0;
    for (size_t j = 0; j < part.keys.size(); ++j)
        if (part.rank[j] == ranks::rank()) ++myNodes, myCells += part.cells[j];
    if (ranks::distributed())
        std::printf(
            "  ranks        %d (mpirun): %zu nodes of %g m holding cells, shared out in Morton order by cell count; "
            "each rank reads\n"
            "               its nodes' cells and their halo, and writes its lists and tiles into the files rank 1 "
            "opens\n",
            ranks::count(), part.keys.size(), file->shape().levelSizeM(part.level));
    else
        std::printf(
            "  nodes        %zu of %g m holding cells, read one at a time with their halo (the grid is never read "
            "whole)\n",
            part.keys.size(), file->shape().levelSizeM(part.level));
    hc::Stopwatch clock;
    inf::RankShare listShare, pyramidShare;
    if (a.lists) {
        inf::InfluenceListsPart lists;
        ranks::together(
            [&] { lists = inf::buildInfluenceListsOnRanks(*file, a.params, a.threads, progress, &listShare); });
        const double buildS = clock.lap();
        const inf::InfluenceLists::Stats stats = inf::writeInfluenceCacheOnRanks(lists, a.out);
        if (root) printListsSummary(a, lists.totalCells, lists.totalEntries, stats, buildS, clock.lap());
    }
    for (size_t i = 0; a.pyramid && i < a.pyramidPaths.size(); ++i) {
        if (a.step < 0 && i > 0) ranks::together([&] { file = std::make_unique<hc::GridRegionReader>(a.gridPath, i); });
        const hc::Grid& shape = file->shape();
        const bool waterOnly = shape.steps.size() > 1 && shape.step > 0;
        inf::RankShare stepShare;
        const inf::PyramidFileSummary whole =
            inf::writePyramidOnRanks(*file, a.params, a.threads, progress, waterOnly, a.pyramidPaths[i], &stepShare);
        pyramidShare.tiles += stepShare.tiles, pyramidShare.seconds += stepShare.seconds;
        pyramidShare.cellsRead = std::max(pyramidShare.cellsRead, stepShare.cellsRead);
        if (root)
            printPyramidSummary(a.pyramidPaths[i], shape, file->cellCount(), PyramidSummary(whole, shape.finestCellM),
                                whole.buildSeconds, whole.writeSeconds);
    }
    std::string line = fmt::format("{} nodes, {} cells", myNodes, myCells);
    if (a.lists)
        line +=
            fmt::format("; lists in {:.3f} s ({} cells read with their halo)", listShare.seconds, listShare.cellsRead);
    if (a.pyramid)
        line += fmt::format("; {} pyramid tiles in {:.3f} s (at most {} cells read for a step)", pyramidShare.tiles,
                            pyramidShare.seconds, pyramidShare.cellsRead);
    line += fmt::format("; {:.3f} s in all, peak {:.1f} MB resident", all.seconds(), double(hc::peakRssBytes()) / 1e6);
    if (ranks::distributed()) ranks::log("hc-influence", line);
}

}  // namespace

int main(int argc, char** argv) {
    return hc::cli::runOnRanks("hc-influence", argc, argv, [&] {
        InfluenceArgs a;
        bool go = true;
        hc::ranks::together([&] { go = parseOptions(argc, argv, a); });
        if (!go) return 0;
        // Without lists nothing needs the grid whole: one process builds the pyramid as one rank would, a node of the
        // grid at a time, each node's tiles written out before the next (writePyramidOnRanks), so that its memory
        // follows a node, neither the grid nor the pyramid (in the same time and to the same bytes:
        // docs/benchmarks.md).
        if (hc::ranks::distributed() || !a.lists)
            runByNodes(a);
        else
            runAlone(a);
        std::printf("  memory       peak %.1f MB resident\n", double(hc::peakRssBytes()) / 1e6);
        return 0;
    });
}
