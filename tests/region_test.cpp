// Out of core (docs/design.md section 4): a grid file read a region at a time (GridRegionReader), the exact surface
// from the cells around its points (influence/region.h) and frames rendered without the whole grid or its lists
// (render::Scene over a file), each against the in-memory path on real rasters.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <set>

#include "heightcast/core/error.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/influence/on_ranks.h"
#include "heightcast/influence/pyramid.h"
#include "heightcast/influence/region.h"
#include "heightcast/render/renderer.h"
#include "temp_dir.h"
#include "test_data.h"
#include "test_grids.h"

namespace fs = std::filesystem;
using hc::Grid;
using hc::GridRegionReader;
namespace inf = hc::influence;

namespace {

// A grid written to a temporary .hcg, removed at the end.
struct GridOnDisk {
    Grid grid;
    fs::path path;
    GridOnDisk(Grid g, const std::string& tag) : grid(std::move(g)) {
        path = hc::test::tempPath("hc_region_", tag + ".hcg");
        hc::writeGrid(grid, path.string());
    }
    ~GridOnDisk() { fs::remove(path); }
};

// The LiDAR tile flooded at 397 m (adaptive cells 1-16 m, holes along its edges, water and dry land) and the demo
// DEM flooded at 2600 m (cells 64-254 m).
GridOnDisk& lidar() {
    static GridOnDisk g(hc::test::ingestFile(hc::test::dataFile("lidar1m_minnesota_utm15.tif"), 0.25, 397.0), "lidar");
    return g;
}
GridOnDisk& hef() {
    static GridOnDisk g(hc::test::ingestFile(hc::test::dataFile("hef_srtm.tif"), 0.5, 2600.0), "hef");
    return g;
}

std::string fileBytes(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), {}};
}

bool meets(const Grid::Square& q, const Grid::Square& box, double m) {
    return !(q.x1 < box.x0 - m || q.x0 > box.x1 + m || q.y1 < box.y0 - m || q.y0 > box.y1 + m);
}

}  // namespace

// The region is exactly the cells whose squares meet the box grown by their level's margin (brute force over every
// cell), in file order, with their values; cellsInNode and cellSquareAt agree with the in-memory grid.
TEST(GridRegionReader, RegionIsExactlyTheCellsWithinTheirMarginOfTheBox) {
    if (hc::test::dataFile("lidar1m_minnesota_utm15.tif").empty()) GTEST_SKIP() << "no LiDAR raster";
    const GridOnDisk& d = lidar();
    const Grid& g = d.grid;
    const GridRegionReader file(d.path.string());
    EXPECT_EQ(file.cellCount(), g.cellCount());
    const std::vector<double> margin = inf::kernelReachM(g, {});
    std::mt19937_64 rng(7);
    double x0, y0, x1, y1;
    g.boundsLocal(x0, y0, x1, y1);
    std::uniform_real_distribution<double> ux(x0 - 20, x1 + 20), uy(y0 - 20, y1 + 20), size(0, 40);
    size_t nonEmpty = 0;
    for (int trial = 0; trial < 60; ++trial) {
        const double bx = ux(rng), by = uy(rng);
        const Grid::Square box{bx, by, bx + (trial % 3 == 0 ? 0.0 : size(rng)),
                               by + (trial % 3 == 0 ? 0.0 : size(rng))};
        const Grid r = file.region(box, margin);
        std::vector<size_t> want;
        for (size_t i = 0; i < g.cellCount(); ++i)
            if (meets(g.cellSquare(i), box, margin[size_t(g.level(i))])) want.push_back(i);
        ASSERT_EQ(r.cellCount(), want.size()) << "box " << box.x0 << "," << box.y0 << " .. " << box.x1 << "," << box.y1;
        for (size_t k = 0; k < want.size(); ++k) {
            ASSERT_EQ(r.codes[k], g.codes[want[k]]);
            for (size_t l = 0; l < g.layerCount(); ++l) ASSERT_EQ(r.values[l][k], g.values[l][want[k]]);
        }
        nonEmpty += !want.empty();
        // A point query's node counts and cell squares, as the whole grid answers them.
        const double px = box.x0, py = box.y0;
        const auto k = g.locate(px, py);
        const auto sq = file.cellSquareAt(px, py);
        ASSERT_EQ(bool(k), bool(sq));
        if (k) {
            EXPECT_EQ(g.cellSquare(*k).x0, sq->x0);
            EXPECT_EQ(g.cellSquare(*k).y1, sq->y1);
        }
        if (const auto key = g.finestKeyAt(px, py))
            for (int level : {0, 2, 5, 9}) {
                const uint64_t node = *key & ~(hc::mortonSpan(level) - 1);
                uint64_t brute = 0;
                for (size_t i = 0; i < g.cellCount(); ++i) {
                    const uint64_t ck = hc::codeKey(g.codes[i]), span = hc::mortonSpan(g.level(i));
                    brute += ck < node + hc::mortonSpan(level) && node < ck + span;  // the cell and the node overlap
                }
                EXPECT_EQ(file.cellsInNode(node, level), brute) << "node of level " << level;
            }
    }
    EXPECT_GT(nonEmpty, 30u);
    // One point reads a few blocks of the file, not all of it.
    EXPECT_LT(file.bytesChecked(), fs::file_size(d.path));
}

// The surface at points from the file, a region per group of points, equals the whole grid's with its lists bit for
// bit (the cells left out weigh exactly 0 and the rest keep their order), for the terrain and both water layers; one
// point at a time too, where each region holds a few dozen cells.
TEST(Region, ValuesFromTheFileAreTheWholeGridsBitForBit) {
    if (hc::test::dataFile("lidar1m_minnesota_utm15.tif").empty()) GTEST_SKIP() << "no LiDAR raster";
    const GridOnDisk& d = lidar();
    const Grid& g = d.grid;
    const inf::InfluenceLists lists = inf::buildInfluenceLists(g, {});
    const inf::SurfaceEvaluator whole(g, lists);
    const GridRegionReader file(d.path.string());
    double x0, y0, x1, y1;
    g.boundsLocal(x0, y0, x1, y1);
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<double> ux(x0 - 5, x1 + 5), uy(y0 - 5, y1 + 5);
    std::vector<std::array<double, 2>> pts(3000);
    for (auto& p : pts) p = {ux(rng), uy(rng)};
    size_t defined = 0, wet = 0;
    for (const char* name : {"elevation", "water_surface", "water_depth"}) {
        const inf::Layer layer = inf::Layer::byName(g, name);
        const auto want = whole.values(pts, layer);
        inf::RegionReadStats st;
        const auto got = inf::valuesFromFile(file, pts, layer, {}, 0, &st);
        ASSERT_EQ(got.size(), want.size());
        for (size_t i = 0; i < pts.size(); ++i) {
            ASSERT_EQ(bool(got[i]), bool(want[i])) << name << " at " << pts[i][0] << "," << pts[i][1];
            if (want[i]) {
                ASSERT_EQ(*got[i], *want[i]) << name << " at " << pts[i][0] << "," << pts[i][1];
            }
        }
        for (const auto& v : want) defined += bool(v), wet += std::string(name) == "water_depth" && v && *v > 0;
        EXPECT_GE(st.regions, 1u);
    }
    EXPECT_GT(defined, 6000u);
    EXPECT_GT(wet, 100u);
    // One point at a time: regions of the kernel margin only.
    const inf::Layer level = inf::Layer::byName(g, "water_surface");
    for (size_t i = 0; i < 200; ++i) {
        inf::RegionReadStats st;
        const auto one = inf::valuesFromFile(file, std::span(&pts[i], 1), level, {}, 1, &st);
        const auto ref = whole.value(pts[i][0], pts[i][1], level);
        ASSERT_EQ(bool(one[0]), bool(ref));
        if (ref) {
            ASSERT_EQ(*one[0], *ref);
        }
        EXPECT_LT(st.largestRegion, g.cellCount() / 20);
    }
}

// A damaged block is found when a region reads it, named by its offset; regions elsewhere still read.
TEST(GridRegionReader, ADamagedBlockIsRefusedWhereItIsRead) {
    if (hc::test::dataFile("lidar1m_minnesota_utm15.tif").empty()) GTEST_SKIP() << "no LiDAR raster";
    const GridOnDisk& d = lidar();
    const fs::path bad = fs::path(d.path).replace_extension(".bad.hcg");
    fs::copy_file(d.path, bad, fs::copy_options::overwrite_existing);
    const Grid& g = d.grid;
    // Flip a byte of the last cell's code: CELLS starts after the header and table, 8 bytes a cell.
    std::fstream f(bad, std::ios::in | std::ios::out | std::ios::binary);
    std::vector<char> head(4096);
    f.read(head.data(), std::streamsize(head.size()));
    uint64_t cellsOffset = 0;
    for (uint32_t s = 0; s < 8; ++s) {
        uint32_t kind;
        std::memcpy(&kind, &head[128 + 32 * s], 4);
        if (kind == 2) std::memcpy(&cellsOffset, &head[128 + 32 * s + 8], 8);
    }
    ASSERT_GT(cellsOffset, 0u);
    const uint64_t at = cellsOffset + 8 * (g.cellCount() - 1) + 2;
    f.seekp(std::streamoff(at));
    f.put('\x5a');
    f.close();
    const GridRegionReader file(bad.string());  // opening reads no cell
    double x0, y0, x1, y1;
    g.boundsLocal(x0, y0, x1, y1);
    const std::vector<double> margin = inf::kernelReachM(g, {});
    try {
        (void)file.region({x0, y0, x1, y1}, margin);
        ADD_FAILURE() << "a region over the damaged block was read";
    } catch (const hc::Error& e) {
        EXPECT_NE(std::string(e.what()).find("checksum mismatch"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find(bad.filename().string()), std::string::npos) << e.what();
    }
    fs::remove(bad);
}

// A frame rendered out of core (no lists, no per-cell arrays: the texels that need the kernels read the cells
// around them) shows what the in-memory scene shows: the same hits, at the same distances within float rounding
// (a region's shorter lists put the same non-zero weights in other vector lanes), with and without the pyramid.
TEST(Region, OutOfCoreFramesEqualInMemoryOnes) {
    if (hc::test::dataFile("hef_srtm.tif").empty()) GTEST_SKIP() << "no demo DEM";
    const GridOnDisk& d = hef();
    const Grid& g = d.grid;
    const inf::InfluenceLists lists = inf::buildInfluenceLists(g, {});
    const inf::SurfacePyramid pyramid = inf::buildSurfacePyramid(g, {});
    const GridRegionReader file(d.path.string());
    for (const inf::SurfacePyramid* p : {static_cast<const inf::SurfacePyramid*>(nullptr), &pyramid}) {
        const hc::render::Scene memory(g, lists, p);
        hc::render::Scene outOfCore(file, {}, p);
        EXPECT_TRUE(outOfCore.outOfCore());
        EXPECT_EQ(outOfCore.xMin, memory.xMin);
        EXPECT_EQ(outOfCore.yMax, memory.yMax);
        EXPECT_EQ(outOfCore.elevationMin, memory.elevationMin);
        EXPECT_EQ(outOfCore.depthMax, memory.depthMax);
        EXPECT_GE(outOfCore.zMax, memory.zMax);  // the summary bounds the water's top by max elevation + max depth
        outOfCore.zMax = memory.zMax;            // the same view box, so that the same cascades are fitted
        hc::render::RenderOptions o;
        o.texelsPerSide = 256;
        for (int view = 0; view < 2; ++view) {
            hc::render::Camera c = hc::render::overviewCamera(memory, 320, 200);
            if (view == 1)
                c = hc::render::Camera::lookAt({c.xWorld + 8000, c.yWorld + 9000, 3400},
                                               {c.xWorld + 12000, c.yWorld + 13000, 2700}, 50, 320, 200);
            hc::render::Timings tm, to;
            const hc::render::Frame a = hc::render::renderFrame(memory, c, o, tm);
            const hc::render::Frame b = hc::render::renderFrame(outOfCore, c, o, to);
            uint64_t read = 0;
            for (const auto& cs : to.cascades) read += cs.cellsRead;
            if (!p) {
                EXPECT_GT(read, 0u);  // with the pyramid every texel of a view may be a copy
            }
            EXPECT_LT(read, 3 * g.cellCount());
            size_t hits = 0, differ = 0;
            for (size_t i = 0; i < a.distanceM.size(); ++i) {
                const bool ha = std::isfinite(a.distanceM[i]), hb = std::isfinite(b.distanceM[i]);
                if (ha != hb) {
                    ++differ;
                    continue;
                }
                if (!ha) continue;
                ++hits;
                // Texels agree to float rounding of the height (1e-6 relative); a hit moves by that over the ray's
                // slope.
                if (std::abs(a.distanceM[i] - b.distanceM[i]) > 1e-3 * a.distanceM[i]) ++differ;
            }
            EXPECT_GT(hits, 10000u);
            EXPECT_LE(differ, hits / 1000) << (p ? "with" : "without") << " the pyramid, view " << view;
        }
    }
}

// Out of core, the texels finer than the stored pyramid levels are interpolated where the in-memory scene
// interpolates them: the fine cells that forbid it come from the file's codes (GridRegionReader::codesInNode) instead
// of the grid's, and give the same masks. The 1 m LiDAR flood from a nearer camera: its near cascades' 1 m texels lie
// over 2-16 m cells.
TEST(Region, OutOfCoreInterpolatesThePyramidsTexelsAsInMemory) {
    if (hc::test::dataFile("lidar1m_minnesota_utm15.tif").empty()) GTEST_SKIP() << "no LiDAR raster";
    const GridOnDisk& d = lidar();
    const Grid& g = d.grid;
    const inf::InfluenceLists lists = inf::buildInfluenceLists(g, {});
    const inf::SurfacePyramid pyramid = inf::buildSurfacePyramid(g, {});
    const GridRegionReader file(d.path.string());
    const hc::render::Scene memory(g, lists, &pyramid);
    hc::render::Scene outOfCore(file, {}, &pyramid);
    outOfCore.zMax = memory.zMax;  // the same view box (above)
    hc::render::Camera c = hc::render::overviewCamera(memory, 320, 200);
    double mx, my;
    g.localToWorld(0.5 * (memory.xMin + memory.xMax), 0.5 * (memory.yMin + memory.yMax), mx, my);
    const double mz = 0.5 * (memory.zMin + memory.zMax);
    c.xWorld = mx + 0.35 * (c.xWorld - mx), c.yWorld = my + 0.35 * (c.yWorld - my),
    c.zWorld = mz + 0.35 * (c.zWorld - mz);
    hc::render::RenderOptions o;
    o.texelsPerSide = 256;
    hc::render::Timings tm, to;
    const hc::render::Frame a = hc::render::renderFrame(memory, c, o, tm);
    const hc::render::Frame b = hc::render::renderFrame(outOfCore, c, o, to);
    ASSERT_EQ(tm.cascades.size(), to.cascades.size());
    uint64_t interpolated = 0;
    for (size_t k = 0; k < tm.cascades.size(); ++k) {
        EXPECT_EQ(tm.cascades[k].pyramidInterpolated, to.cascades[k].pyramidInterpolated) << "cascade " << k;
        EXPECT_EQ(tm.cascades[k].pyramidTexels, to.cascades[k].pyramidTexels) << "cascade " << k;
        interpolated += tm.cascades[k].pyramidInterpolated;
    }
    EXPECT_GT(interpolated, 10000u);
    size_t hits = 0, differ = 0;
    for (size_t i = 0; i < a.distanceM.size(); ++i) {
        const bool ha = std::isfinite(a.distanceM[i]), hb = std::isfinite(b.distanceM[i]);
        if (ha != hb || (ha && std::abs(a.distanceM[i] - b.distanceM[i]) > 1e-3 * a.distanceM[i])) ++differ;
        hits += ha;
    }
    EXPECT_GT(hits, 10000u);
    EXPECT_LE(differ, hits / 1000);  // the summed texels' float rounding, as above
}

// The file index runs of a region name, for each of its cells, the cell of the file it is.
TEST(GridRegionReader, RunsNameEachRegionCellsIndexInTheFile) {
    if (hc::test::dataFile("lidar1m_minnesota_utm15.tif").empty()) GTEST_SKIP() << "no LiDAR raster";
    const GridOnDisk& d = lidar();
    const GridRegionReader file(d.path.string());
    double x0, y0, x1, y1;
    d.grid.boundsLocal(x0, y0, x1, y1);
    std::vector<std::pair<uint64_t, uint64_t>> runs;
    const Grid r = file.region({x0 + 100, y0 + 50, x0 + 180, y0 + 260}, inf::kernelReachM(d.grid, {}), &runs);
    ASSERT_GT(r.cellCount(), 100u);
    ASSERT_GT(runs.size(), 1u);  // a box is several Morton runs
    size_t k = 0;
    for (size_t run = 0; run < runs.size(); ++run) {
        if (run > 0) {
            EXPECT_GT(runs[run].first, runs[run - 1].second);  // ascending, apart (touching runs are joined)
        }
        for (uint64_t i = runs[run].first; i < runs[run].second; ++i, ++k) ASSERT_EQ(r.codes[k], d.grid.codes[i]);
    }
    EXPECT_EQ(k, r.cellCount());
}

// The file's pages a region touched stay resident until releasePages() drops them (hc-influence --no-lists calls it
// between nodes: its memory then follows a node, not the file walked so far); a region read afterwards reads them back
// from the page cache, the same bytes.
TEST(GridRegionReader, ReleasedPagesLeaveResidentMemoryAndReadBackTheSame) {
    if (hc::test::dataFile("lidar1m_minnesota_utm15.tif").empty()) GTEST_SKIP() << "no LiDAR raster";
    const GridOnDisk& d = lidar();
    const GridRegionReader file(d.path.string());
    auto residentFileKb = [] {  // this process's resident pages of mapped files, /proc/self/status
        std::ifstream status("/proc/self/status");
        for (std::string line; std::getline(status, line);)
            if (line.rfind("RssFile:", 0) == 0) return std::stol(line.substr(8));
        return -1L;
    };
    double x0, y0, x1, y1;
    d.grid.boundsLocal(x0, y0, x1, y1);
    const Grid::Square all{x0, y0, x1, y1};
    const Grid first = file.region(all);  // every cell: the file's cells and values all touched
    ASSERT_EQ(first.cellCount(), d.grid.cellCount());
    const long touched = residentFileKb();
    file.releasePages();
    const long released = residentFileKb();
    ASSERT_GE(touched, 0) << "no RssFile in /proc/self/status";
    // The cells (8 bytes of code and 4 of each layer's value a cell) leave resident memory, give or take a page.
    const long cellsKb = long(d.grid.cellCount() * (8 + 4 * d.grid.layerCount()) / 1024);
    EXPECT_GE(touched - released, cellsKb - 8)
        << "touched " << touched << " kB, after the release " << released << " kB";
    const Grid again = file.region(all);
    EXPECT_EQ(again.codes, first.codes);
    EXPECT_EQ(again.values, first.values);
}

// Reading a pyramid whose samples exceed the resident limit (here 0 bytes; kPyramidResidentBytes for the tools) checks
// every sample's block but leaves the samples out of resident memory (a renderer then holds the tiles it reads, not the
// file); the samples read afterwards are the ones written.
TEST(SurfacePyramidFile, ReadingChecksTheSamplesWithoutKeepingThemResident) {
    if (hc::test::dataFile("lidar1m_minnesota_utm15.tif").empty()) GTEST_SKIP() << "no LiDAR raster";
    const GridOnDisk& d = lidar();
    const inf::SurfacePyramid built = inf::buildSurfacePyramid(d.grid, {});
    const fs::path path = hc::test::tempPath("hc_region_", "resident.hcp");
    inf::writeSurfacePyramid(built, path.string());
    auto residentFileKb = [] {  // this process's resident pages of mapped files, /proc/self/status
        std::ifstream status("/proc/self/status");
        for (std::string line; std::getline(status, line);)
            if (line.rfind("RssFile:", 0) == 0) return std::stol(line.substr(8));
        return -1L;
    };
    uint64_t sampleBytes = 0;
    for (const auto& L : built.levels) sampleBytes += L.samples.size() * sizeof(float);
    ASSERT_GT(sampleBytes, uint64_t(1) << 20) << "too small a pyramid to tell";
    const long before = residentFileKb();
    ASSERT_GE(before, 0) << "no RssFile in /proc/self/status";
    const inf::SurfacePyramid read =
        inf::readSurfacePyramid(path.string(), d.grid, d.grid.structureHash(), d.grid.contentHash(), {}, 0);
    const long after = residentFileKb();
    // The keys and parent errors stay (a few per cent of the file) and a page at each section's ends; not the samples.
    EXPECT_LT(after - before, long(sampleBytes / 1024 / 4)) << "samples " << sampleBytes / 1024 << " kB";
    ASSERT_EQ(read.levels.size(), built.levels.size());
    for (size_t t = 0; t < built.levels.size(); ++t)
        ASSERT_TRUE(read.levels[t].samples.size() == built.levels[t].samples.size() &&
                    std::memcmp(read.levels[t].samples.data(), built.levels[t].samples.data(),
                                built.levels[t].samples.size_bytes()) == 0)  // bytes: holes are NaN
            << "level " << t;
    fs::remove(path);
}

// The nodes the ranks of an MPI run share out (on_ranks.h): every cell in exactly one node, no node finer than the
// coarsest cell, the ranks in Morton runs of about equal cell count (off by at most one node's cells).
TEST(Ranks, PartitionPutsEveryCellInOneNodeAndBalancesTheRanks) {
    if (hc::test::dataFile("lidar1m_minnesota_utm15.tif").empty()) GTEST_SKIP() << "no LiDAR raster";
    for (GridOnDisk* d : {&lidar(), &hef()}) {
        const Grid& g = d->grid;
        const GridRegionReader file(d->path.string());
        for (int ranks = 1; ranks <= 5; ++ranks) {
            const inf::RankPartition p = inf::partitionOf(file, ranks);
            ASSERT_GE(p.level, g.maxLevel);
            ASSERT_EQ(p.keys.size(), p.cells.size());
            ASSERT_EQ(p.keys.size(), p.rank.size());
            std::vector<uint64_t> seen(p.keys.size(), 0), perRank(size_t(ranks), 0);
            for (uint64_t code : g.codes) {
                const uint64_t key = hc::codeKey(code) & ~(hc::mortonSpan(p.level) - 1);
                const auto it = std::lower_bound(p.keys.begin(), p.keys.end(), key);
                ASSERT_TRUE(it != p.keys.end() && *it == key) << "a cell in no node";
                ++seen[size_t(it - p.keys.begin())];
            }
            uint64_t largest = 0;
            for (size_t j = 0; j < p.keys.size(); ++j) {
                EXPECT_EQ(seen[j], p.cells[j]) << "node " << j;
                if (j > 0) {
                    EXPECT_LE(p.rank[j - 1], p.rank[j]);
                }
                ASSERT_TRUE(p.rank[j] >= 0 && p.rank[j] < ranks);
                perRank[size_t(p.rank[j])] += p.cells[j];
                largest = std::max(largest, p.cells[j]);
            }
            for (int r = 0; r < ranks; ++r)
                EXPECT_LE(double(perRank[size_t(r)]), double(g.cellCount()) / ranks + double(largest))
                    << ranks << " ranks, rank " << r;
        }
    }
}

// One rank's build from regions of the file (the path every rank of mpirun takes) gives the lists and pyramids of the
// whole grid bit for bit: the terrain with water (3 channels) and a later step's water pyramid. The CLI tests
// (tests/cli/mpi.cmake) compare the files 1, 2 and 3 ranks write.
TEST(Ranks, BuildFromRegionsEqualsTheWholeGridsBitForBit) {
    if (hc::test::dataFile("lidar1m_minnesota_utm15.tif").empty()) GTEST_SKIP() << "no LiDAR raster";
    for (GridOnDisk* d : {&lidar(), &hef()}) {
        const Grid& g = d->grid;
        const GridRegionReader file(d->path.string());
        const inf::KernelParams params;
        const inf::InfluenceLists want = inf::buildInfluenceLists(g, params);
        const inf::InfluenceListsPart got = inf::buildInfluenceListsOnRanks(file, params, 2, false);
        ASSERT_EQ(got.cellCount(), want.cellCount());
        ASSERT_EQ(got.totalCells, want.cellCount());
        ASSERT_EQ(got.firstCell, 0u);
        ASSERT_EQ(got.entryCount(), want.entryCount());
        ASSERT_EQ(got.totalEntries, want.entryCount());
        EXPECT_TRUE(std::equal(want.offsets().begin(), want.offsets().end(), got.offsets.begin()));
        std::vector<uint32_t> indices;  // the nodes' entries in order
        for (const auto& e : got.entries) indices.insert(indices.end(), e.indices.get(), e.indices.get() + e.count);
        EXPECT_GT(got.entries.size(), 1u);
        EXPECT_TRUE(std::equal(want.indices().begin(), want.indices().end(), indices.begin(), indices.end()));
        EXPECT_EQ(got.structureHash, g.structureHash());
        // Written by parts (one process: rank 0's part is the whole): writeInfluenceCache's bytes and the same figures.
        const fs::path byParts = d->path.string() + ".parts.hci", whole = d->path.string() + ".whole.hci";
        const inf::InfluenceLists::Stats stats = inf::writeInfluenceCacheOnRanks(got, byParts.string());
        inf::writeInfluenceCache(want, whole.string());
        EXPECT_EQ(fileBytes(byParts), fileBytes(whole));
        EXPECT_GT(fs::file_size(whole), 1000u);
        const inf::InfluenceLists::Stats wantStats = want.stats();
        EXPECT_EQ(stats.bytes, wantStats.bytes);
        EXPECT_EQ(stats.meanLength, wantStats.meanLength);
        EXPECT_EQ(stats.p99Length, wantStats.p99Length);
        EXPECT_EQ(stats.maxLength, wantStats.maxLength);
        fs::remove(byParts), fs::remove(whole);
        for (bool waterOnly : {false, true}) {
            const inf::SurfacePyramid a =
                waterOnly ? inf::buildWaterPyramid(g, params) : inf::buildSurfacePyramid(g, params);
            // Built and written a node at a time (one process: the whole), writeSurfacePyramid's bytes, and read back
            // the same tiles, samples and errors.
            const fs::path pyramidByParts = d->path.string() + ".parts.hcp",
                           pyramidWhole = d->path.string() + ".whole.hcp";
            const inf::PyramidFileSummary sum =
                inf::writePyramidOnRanks(file, params, 2, false, waterOnly, pyramidByParts.string());
            inf::writeSurfacePyramid(a, pyramidWhole.string());
            EXPECT_EQ(fileBytes(pyramidByParts), fileBytes(pyramidWhole)) << (waterOnly ? "water pyramid" : "pyramid");
            const inf::SurfacePyramid b = inf::readSurfacePyramid(pyramidByParts.string(), file.info(), params);
            ASSERT_EQ(a.channels, b.channels);
            ASSERT_EQ(a.levels.size(), b.levels.size());
            EXPECT_EQ(a.contentHash, b.contentHash);
            EXPECT_EQ(sum.channels, a.channels);
            EXPECT_EQ(sum.samples, a.sampleCount());
            EXPECT_EQ(sum.bytes, a.bytes());
            uint64_t tiles = 0;
            for (size_t t = 0; t < a.levels.size(); ++t) {
                const auto &x = a.levels[t], &y = b.levels[t];
                ASSERT_EQ(x.tileCount(), y.tileCount()) << "level " << t;
                EXPECT_EQ(sum.tiles[t], x.tileCount()) << "level " << t;
                tiles += x.tileCount();
                if (x.keys.empty()) continue;  // empty spans' data() may be null: no memcmp
                EXPECT_TRUE(std::equal(x.keys.begin(), x.keys.end(), y.keys.begin())) << "level " << t;
                EXPECT_EQ(0, std::memcmp(x.samples.data(), y.samples.data(), x.samples.size_bytes())) << "level " << t;
                EXPECT_EQ(0, std::memcmp(x.parentErrorM.data(), y.parentErrorM.data(), x.parentErrorM.size_bytes()))
                    << "level " << t;
                float worst = 0;
                for (size_t i = 0; i < x.parentErrorM.size(); i += size_t(a.channels))
                    worst = std::max(worst, x.parentErrorM[i]);
                EXPECT_EQ(sum.worstM[t], worst) << "level " << t;
            }
            EXPECT_GT(tiles, 10u);
            fs::remove(pyramidByParts), fs::remove(pyramidWhole);
        }
    }
}
