// The surface pyramid (influence/pyramid.h) against the exact evaluator (surface.h, with whole-grid influence
// lists: an independent path): every stored sample of every level, on real rasters with a cell-size ratio of
// 128, holes and water; which tiles are stored; the recorded parent errors; the .hcp file.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <optional>
#include <random>
#include <set>
#include <cstring>
#include <bit>
#include <array>
#include <algorithm>

#include "heightcast/core/error.h"
#include "heightcast/influence/influence.h"
#include "heightcast/influence/pyramid.h"
#include "heightcast/influence/surface.h"
#include "heightcast/ingest/build.h"
#include "temp_dir.h"
#include "test_data.h"
#include "test_grids.h"

namespace {

namespace fs = std::filesystem;
using hc::Grid;
using hc::influence::KernelParams;
using hc::influence::Layer;
using hc::influence::PyramidChannel;
using hc::influence::SurfacePyramid;

// A sample is the exact surface (double) rounded to float once: within half a float ulp of the value, plus
// the double evaluations' own differences (other summation order, 1e-12 relative). One float ulp is 2^-23 |v|.
double sampleTolerance(double v) { return std::ldexp(std::abs(v), -23) + 1e-9; }

// Calls f(level, i, j, value) for every stored sample of channel c.
template <typename F>
void forEachSample(const SurfacePyramid& p, PyramidChannel c, F&& f) {
    for (const SurfacePyramid::Level& L : p.levels) {
        const size_t side = size_t(L.tileSide), plane = side * side;
        for (size_t tile = 0; tile < L.tileCount(); ++tile) {
            const uint64_t i0 = hc::mortonX(L.keys[tile]) >> L.level, j0 = hc::mortonY(L.keys[tile]) >> L.level;
            const float* s = &L.samples[(tile * size_t(p.channels) + size_t(c)) * plane];
            for (size_t j = 0; j < side; ++j)
                for (size_t i = 0; i < side; ++i) f(L.level, i0 + i, j0 + j, s[j * side + i]);
        }
    }
}

void expectSamplesExact(const Grid& g, const SurfacePyramid& p) {
    const auto lists = hc::influence::buildInfluenceLists(g, p.params);
    const hc::influence::SurfaceEvaluator exact(g, lists);
    const Layer elevation = Layer::byName(g, "elevation");
    uint64_t checked = 0, undefined = 0;
    forEachSample(p, PyramidChannel::Elevation, [&](int t, uint64_t i, uint64_t j, float v) {
        const double x = double(i) * p.spacingM(t), y = double(j) * p.spacingM(t);
        const auto want = exact.value(x, y, elevation);
        if (!want) {
            EXPECT_TRUE(std::isnan(v)) << "level " << t << " sample " << i << "," << j << " outside every cell holds "
                                       << v;
            ++undefined;
            return;
        }
        ASSERT_NEAR(double(v), *want, sampleTolerance(*want)) << "level " << t << " sample " << i << "," << j;
        ++checked;
    });
    EXPECT_EQ(checked + undefined, p.sampleCount() / uint64_t(p.channels));
    EXPECT_GT(checked, g.cellCount()) << "fewer defined samples than cells";
}

TEST(SurfacePyramid, EverySampleEqualsTheExactSurfaceAtCellRatio128WithAHole) {
    const Grid g = hc::test::ratio128Grid();
    const SurfacePyramid p = hc::influence::buildSurfacePyramid(g, KernelParams{});
    ASSERT_EQ(p.channels, 1);
    ASSERT_EQ(p.topLevel(), std::max(0, g.rootLevel - hc::influence::kPyramidTileLog2));
    expectSamplesExact(g, p);
}

// Which tiles are stored (pyramid.h's rule), checked from what a reader needs rather than from the rule's code:
// - every lattice point of level t that lies within the kernel reach box of a cell of level <= t (|x - cx| and
//   |y - cy| both <= R sigma c: where that cell's detail shows) and over some cell has a stored sample, so a
//   cascade copies it instead of summing kernels there;
// - every stored tile below the top is met by such a box, and holds a defined sample (no all-NaN tile);
// - at the top, exactly the tiles holding a cell; and every stored tile's parent is stored.
TEST(SurfacePyramid, TilesAreStoredWhereAFineEnoughCellsKernelReaches) {
    const Grid g = hc::test::ratio128Grid();
    const KernelParams params{};
    const SurfacePyramid p = hc::influence::buildSurfacePyramid(g, params);
    uint64_t finestTiles = 0, reachedPoints = 0, beyondOwnTile = 0;
    for (const SurfacePyramid::Level& L : p.levels) {
        const int t = L.level, nodeLevel = t + std::countr_zero(unsigned(L.tileSide));
        const double h = p.spacingM(t), tileM = h * L.tileSide;
        const uint64_t perSide = uint64_t{1} << (g.rootLevel - t);  // lattice points a side inside the domain
        if (t == p.topLevel()) {
            std::set<uint64_t> want;
            for (uint64_t code : g.codes) want.insert(hc::codeKey(code) & ~(hc::mortonSpan(nodeLevel) - 1));
            EXPECT_EQ(std::set<uint64_t>(L.keys.begin(), L.keys.end()), want) << "top level " << t;
            continue;
        }
        std::vector<std::array<double, 3>> fine;  // centre x, y and reach of every cell of level <= t
        for (size_t c = 0; c < g.cellCount(); ++c) {
            if (g.level(c) > t) continue;
            double cx = 0, cy = 0;
            g.cellCenterLocal(c, cx, cy);
            fine.push_back({cx, cy, params.radiusM(g.cellSizeM(c))});
        }
        // Completeness: every lattice point in a reach box, over a cell.
        for (const auto& [cx, cy, r] : fine) {
            const uint64_t i0 = uint64_t(std::max(0.0, std::ceil((cx - r) / h))),
                           i1 = std::min(perSide - 1, uint64_t(std::floor((cx + r) / h)));
            const uint64_t j0 = uint64_t(std::max(0.0, std::ceil((cy - r) / h))),
                           j1 = std::min(perSide - 1, uint64_t(std::floor((cy + r) / h)));
            for (uint64_t j = j0; j <= j1; ++j)
                for (uint64_t i = i0; i <= i1; ++i) {
                    if (!g.locate(double(i) * h, double(j) * h)) continue;
                    ++reachedPoints;
                    const bool ownTile = uint64_t(cx / tileM) == i / uint64_t(L.tileSide) &&
                                         uint64_t(cy / tileM) == j / uint64_t(L.tileSide);
                    beyondOwnTile += !ownTile;
                    ASSERT_TRUE(p.sample(t, i, j, PyramidChannel::Elevation).has_value())
                        << "level " << t << ": sample " << i << "," << j << " lies within reach of a fine cell at "
                        << cx << "," << cy << " but is not stored";
                }
        }
        // Minimality: every stored tile is met by a reach box and has a defined sample.
        const size_t plane = size_t(L.tileSide) * size_t(L.tileSide);
        for (size_t tile = 0; tile < L.tileCount(); ++tile) {
            const double x0 = double(hc::mortonX(L.keys[tile])) * g.finestCellM,
                         y0 = double(hc::mortonY(L.keys[tile])) * g.finestCellM;
            const bool reached = std::any_of(fine.begin(), fine.end(), [&](const auto& f) {
                return f[0] + f[2] >= x0 && f[0] - f[2] < x0 + tileM && f[1] + f[2] >= y0 && f[1] - f[2] < y0 + tileM;
            });
            EXPECT_TRUE(reached) << "level " << t << ": tile at " << x0 << "," << y0
                                 << " is stored, but no cell of level <= " << t << " reaches it";
            const float* s = &L.samples[tile * size_t(p.channels) * plane];
            EXPECT_TRUE(std::any_of(s, s + plane, [](float v) { return !std::isnan(v); }))
                << "level " << t << ": tile at " << x0 << "," << y0 << " is all NaN";
            EXPECT_GE(p.tileAt(t + 1, hc::mortonX(L.keys[tile]) >> (t + 1), hc::mortonY(L.keys[tile]) >> (t + 1)), 0)
                << "level " << t << ": a parent missing";
        }
        if (t == 0) finestTiles = L.tileCount();
    }
    // The check must have met points beyond their cell's own tile (the reach crossing a tile edge), else it would not
    // tell this rule from "the node holds a fine cell".
    EXPECT_GT(beyondOwnTile, 0u);
    EXPECT_GT(reachedPoints, beyondOwnTile);
    // The grid's 0.75 m cells fill a 16 x 256 px strip: a few dozen level-0 tiles with their reach, not the whole 640 x
    // 512 raster's 1280.
    EXPECT_GT(finestTiles, 0u);
    EXPECT_LT(finestTiles, 100u);
}

// SurfacePyramid::Cursor (which remembers the tiles of two tile rows in a table by column and row parity) reads what
// sample() (a binary search per read) does, at every level. The grid is a strip 2304 px wide whose rough band keeps
// finest cells along its whole width: 256 tile columns at level 0, so tiles 128 columns apart share a table slot.
// Rows are walked whole and met again after the table moved on, reads alternate between rows of tiles, and columns
// are walked too. A stale or aliased entry would return another tile's sample or miss a stored one.
TEST(SurfacePyramid, CursorReadsWhatSampleReadsWalkingRowsAndColumns) {
    std::mt19937 rng(5);
    const hc::ingest::Raster r = hc::test::makeRaster(2304, 64, 1, 1000, 5000, [&](size_t col, size_t row) {
        return row >= 16 && row < 32 ? 50.0f + float(rng() % 1000) * 0.01f : 40.0f + 0.002f * float(col);
    });
    hc::ingest::BuildOptions b;
    b.toleranceM = 0.5;
    const Grid g = hc::ingest::buildGrid(r, nullptr, b);
    const SurfacePyramid p = hc::influence::buildSurfacePyramid(g, KernelParams{});
    ASSERT_GT(p.levels[0].tileCount(), 128u) << "the table's slots must be shared for this test to mean anything";
    uint64_t stored = 0, reads = 0;
    for (int t = 0; t <= p.topLevel(); ++t) {
        const uint64_t side = uint64_t{1} << (g.rootLevel - t),
                       rows = std::min<uint64_t>(side, 160);  // the data and above
        SurfacePyramid::Cursor byRow(p, t), byColumn(p, t);
        auto check = [&](SurfacePyramid::Cursor& c, uint64_t i, uint64_t j) {
            const float* got = c.find(i, j);
            const std::optional<float> want = p.sample(t, i, j, PyramidChannel::Elevation);
            ++reads;
            ASSERT_EQ(got != nullptr, want.has_value()) << "level " << t << " sample " << i << "," << j;
            if (!got) return;
            ++stored;
            ASSERT_EQ(std::bit_cast<uint32_t>(*got), std::bit_cast<uint32_t>(*want))
                << "level " << t << " sample " << i << "," << j;
        };
        // Every 3rd row whole, each read followed by one 2 tile rows further (another row parity, then the same);
        // every 3rd column whole.
        for (uint64_t j = 0; j < rows; j += 3)
            for (uint64_t i = 0; i < side; ++i) check(byRow, i, j), check(byRow, i, (j + 32) % rows);
        for (uint64_t i = 0; i < side; i += 3)
            for (uint64_t j = 0; j < rows; ++j) check(byColumn, i, j);
        if (::testing::Test::HasFatalFailure()) return;
    }
    EXPECT_GT(stored, p.sampleCount() / 4) << "three passes over a third of the rows or columns each";
    EXPECT_GT(reads, 2 * stored) << "the walk should also cross tiles that are not stored";
}

// parentErrorM is the largest |sample - bilinear of the parent's samples| over the tile: recomputed here from
// sample() (not the builder's loop), it is never exceeded and is reached.
TEST(SurfacePyramid, ParentErrorIsTheLargestInterpolationErrorOfTheTile) {
    const Grid g = hc::test::ratio128Grid();
    const SurfacePyramid p = hc::influence::buildSurfacePyramid(g, KernelParams{});
    uint64_t tilesWithError = 0;
    for (int t = 0; t < p.topLevel(); ++t) {
        const SurfacePyramid::Level& L = p.levels[size_t(t)];
        for (size_t tile = 0; tile < L.tileCount(); ++tile) {
            const uint64_t i0 = hc::mortonX(L.keys[tile]) >> t, j0 = hc::mortonY(L.keys[tile]) >> t;
            double worst = 0;
            for (uint64_t j = j0; j < j0 + uint64_t(L.tileSide); ++j)
                for (uint64_t i = i0; i < i0 + uint64_t(L.tileSide); ++i) {
                    const float v = *p.sample(t, i, j, PyramidChannel::Elevation);
                    double sum = 0;
                    bool ok = !std::isnan(v);
                    for (uint64_t dj : {j / 2, (j + 1) / 2})
                        for (uint64_t di : {i / 2, (i + 1) / 2}) {
                            const auto s = p.sample(t + 1, di, dj, PyramidChannel::Elevation);
                            ok = ok && s && !std::isnan(*s);
                            if (ok) sum += *s;
                        }
                    if (ok) worst = std::max(worst, std::abs(double(v) - 0.25 * sum));
                }
            EXPECT_NEAR(L.parentErrorM[tile], worst, 1e-6 * std::max(1.0, worst)) << "level " << t << " tile " << tile;
            tilesWithError += worst > 0.01;
        }
    }
    EXPECT_GT(tilesWithError, 0u) << "the rough strip must show somewhere";
}

// Water (docs/design.md section 6) on the real LiDAR tile with a sloping river: wherever the exact evaluator draws
// water the level channel equals its water surface and the pyramid's rule draws it too; wherever it does not,
// the pyramid's rule does not either (samples whose wet share or level sits within float rounding of the rule's
// thresholds are counted and excluded: float cannot decide them).
TEST(SurfacePyramid, WaterChannelsFollowTheExactWaterRule) {
    HC_REQUIRE_DATA(lidar, "lidar1m_minnesota_utm15.tif");
    Grid g = hc::test::ingestFile(lidar, 0.25, 397.0);
    const int depth = g.findLayer("water_depth");
    double x0, y0, x1, y1;
    g.boundsLocal(x0, y0, x1, y1);
    for (size_t i = 0; i < g.cellCount(); ++i) {
        double cx, cy;
        g.cellCenterLocal(i, cx, cy);
        const double level = 395.0 + 4.0 * (cx - x0) / (x1 - x0);
        g.values[size_t(depth)][i] = static_cast<float>(std::max(0.0, level - double(g.values[0][i])));
    }
    const SurfacePyramid p = hc::influence::buildSurfacePyramid(g, KernelParams{});
    ASSERT_EQ(p.channels, 3);
    expectSamplesExact(g, p);
    const auto lists = hc::influence::buildInfluenceLists(g, p.params);
    const hc::influence::SurfaceEvaluator exact(g, lists);
    const Layer surface = Layer::byName(g, "water_surface");
    uint64_t wet = 0, dry = 0, undecidable = 0;
    forEachSample(p, PyramidChannel::Elevation, [&](int t, uint64_t i, uint64_t j, float z) {
        if (std::isnan(z)) return;
        const float level = *p.sample(t, i, j, PyramidChannel::WaterLevel),
                    share = *p.sample(t, i, j, PyramidChannel::WetShare);
        ASSERT_TRUE(share >= 0 && share <= 1) << share;
        const double x = double(i) * p.spacingM(t), y = double(j) * p.spacingM(t);
        const auto want = exact.value(x, y, surface);
        if (std::abs(double(share) - hc::influence::kWetShareMin) < 1e-6 ||
            (!std::isnan(level) && std::abs(double(level) - double(z)) < 2 * sampleTolerance(z))) {
            ++undecidable;
            return;
        }
        const bool drawn = !std::isnan(level) && share >= hc::influence::kWetShareMin && level > z;
        ASSERT_EQ(drawn, want.has_value()) << "level " << t << " sample " << i << "," << j;
        if (want) {
            ASSERT_NEAR(double(level), *want, sampleTolerance(*want));
            ++wet;
        } else {
            ++dry;
        }
    });
    EXPECT_GT(wet, 1000u);
    EXPECT_GT(dry, 1000u);
    EXPECT_LT(undecidable, (wet + dry) / 1000) << "more samples on the thresholds than float rounding explains";
}

// A later step's water pyramid built over the tiles its wet cells reach is the whole pyramid's water pyramid, bit for
// bit (keys, samples, parent errors), on real LiDAR with a sloping river and on a flood that reaches one corner only;
// and it samples fewer tiles.
TEST(SurfacePyramid, WaterPyramidBuiltWhereWaterReachesEqualsTheWholeOnesWater) {
    HC_REQUIRE_DATA(lidar, "lidar1m_minnesota_utm15.tif");
    Grid g = hc::test::ingestFile(lidar, 0.25, 397.0);
    const int depth = g.findLayer("water_depth");
    double x0, y0, x1, y1;
    g.boundsLocal(x0, y0, x1, y1);
    for (const bool corner : {false, true}) {  // a river sloping along x; then water in the south-west corner only
        SCOPED_TRACE(corner ? "corner" : "river");
        for (size_t i = 0; i < g.cellCount(); ++i) {
            double cx, cy;
            g.cellCenterLocal(i, cx, cy);
            const double level =
                corner ? (cx - x0 < 40 && cy - y0 < 40 ? 415.0 : 0.0) : 395.0 + 4.0 * (cx - x0) / (x1 - x0);
            g.values[size_t(depth)][i] = static_cast<float>(std::max(0.0, level - double(g.values[0][i])));
        }
        const SurfacePyramid whole = hc::influence::buildSurfacePyramid(g, KernelParams{});
        const SurfacePyramid want = hc::influence::waterPyramidOf(whole),
                             got = hc::influence::buildWaterPyramid(g, KernelParams{});
        ASSERT_EQ(got.channels, 2);
        ASSERT_EQ(got.levels.size(), want.levels.size());
        uint64_t tiles = 0, wholeTiles = 0;
        for (size_t t = 0; t < want.levels.size(); ++t) {
            const auto& a = want.levels[t];
            const auto& b = got.levels[t];
            ASSERT_TRUE(std::equal(a.keys.begin(), a.keys.end(), b.keys.begin(), b.keys.end())) << "level " << t;
            ASSERT_EQ(a.samples.size(), b.samples.size());
            ASSERT_EQ(a.parentErrorM.size(), b.parentErrorM.size());
            if (a.keys.empty()) continue;  // a level without water (its spans' data() may be null: no memcmp)
            EXPECT_EQ(0, std::memcmp(a.samples.data(), b.samples.data(), a.samples.size_bytes())) << "level " << t;
            EXPECT_EQ(0, std::memcmp(a.parentErrorM.data(), b.parentErrorM.data(), a.parentErrorM.size_bytes()))
                << "level " << t;
            tiles += b.tileCount(), wholeTiles += whole.levels[t].tileCount();
        }
        EXPECT_GT(tiles, 0u);
        if (corner) {
            EXPECT_LT(tiles * 4, wholeTiles) << "water in one corner: a small part of the tiles";
        }
    }
    Grid dry = hc::test::ingestFile(lidar, 0.25);
    EXPECT_THROW(hc::influence::buildWaterPyramid(dry, KernelParams{}), hc::Error);
}

class PyramidFile : public hc::test::TempDirTest {
protected:
    PyramidFile() : TempDirTest("hc_pyramid_") {}
};

TEST_F(PyramidFile, RoundTripsAndRefusesForeignGridsAndDamage) {
    Grid g = hc::test::ratio128Grid();
    const SurfacePyramid built = hc::influence::buildSurfacePyramid(g, KernelParams{});
    hc::influence::writeSurfacePyramid(built, path("g.hcp"));
    const SurfacePyramid read = hc::influence::readSurfacePyramid(path("g.hcp"), g, KernelParams{});
    ASSERT_EQ(read.levels.size(), built.levels.size());
    for (size_t t = 0; t < built.levels.size(); ++t) {
        EXPECT_TRUE(std::equal(read.levels[t].keys.begin(), read.levels[t].keys.end(), built.levels[t].keys.begin(),
                               built.levels[t].keys.end()));
        EXPECT_EQ(0, std::memcmp(read.levels[t].samples.data(), built.levels[t].samples.data(),
                                 built.levels[t].samples.size_bytes()));
        EXPECT_TRUE(std::equal(read.levels[t].parentErrorM.begin(), read.levels[t].parentErrorM.end(),
                               built.levels[t].parentErrorM.begin()));
    }
    // Another sigma, other values on the same tree: refused, saying so.
    KernelParams wide;
    wide.sigma = 1.5;
    EXPECT_THROW(hc::influence::readSurfacePyramid(path("g.hcp"), g, wide), hc::Error);
    g.values[0][0] += 1.0f;
    try {
        hc::influence::readSurfacePyramid(path("g.hcp"), g, KernelParams{});
        ADD_FAILURE() << "a pyramid of other values was read";
    } catch (const hc::Error& e) {
        EXPECT_NE(std::string(e.what()).find("stale or foreign"), std::string::npos) << e.what();
    }
    g.values[0][0] -= 1.0f;
    // A flipped byte in the samples and a truncation: refused, naming the file.
    std::ifstream in(path("g.hcp"), std::ios::binary);
    std::vector<char> bytes((std::istreambuf_iterator<char>(in)), {});
    for (size_t at : {size_t(40), bytes.size() / 2, bytes.size() - 1}) {
        std::vector<char> bad = bytes;
        bad[at] = char(bad[at] ^ 0x04);
        std::ofstream(path("bad.hcp"), std::ios::binary).write(bad.data(), std::streamsize(bad.size()));
        try {
            hc::influence::readSurfacePyramid(path("bad.hcp"), g, KernelParams{});
            ADD_FAILURE() << "byte " << at << " flipped was read";
        } catch (const hc::Error& e) {
            EXPECT_NE(std::string(e.what()).find("bad.hcp"), std::string::npos) << e.what();
        }
    }
    std::ofstream(path("cut.hcp"), std::ios::binary).write(bytes.data(), std::streamsize(bytes.size() - 64));
    EXPECT_THROW(hc::influence::readSurfacePyramid(path("cut.hcp"), g, KernelParams{}), hc::Error);
}

}  // namespace
