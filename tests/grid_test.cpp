// Morton keys, point location, range and neighbour queries: each checked against brute force on
// real grids (ingested from data/) and on a synthetic grid with a cell-size ratio of 128.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <cmath>
#include <set>
#include <span>

#include "heightcast/grid/grid.h"
#include "heightcast/ingest/build.h"
#include "heightcast/ingest/ingest.h"
#include "test_data.h"
#include "test_grids.h"

namespace {

using hc::Grid;

TEST(Morton, RoundTripsAndInterleaves) {
    std::mt19937_64 rng(1);
    for (int i = 0; i < 100000; ++i) {
        auto x = static_cast<uint32_t>(rng() & ((1u << 29) - 1)), y = static_cast<uint32_t>(rng() & ((1u << 29) - 1));
        uint64_t k = hc::mortonEncode(x, y);
        ASSERT_EQ(hc::mortonX(k), x);
        ASSERT_EQ(hc::mortonY(k), y);
        int level = static_cast<int>(rng() % 30);
        uint64_t code = hc::makeCellCode(k, level);
        ASSERT_EQ(hc::codeKey(code), k);
        ASSERT_EQ(hc::codeLevel(code), level);
    }
    // The four children of a node follow one another: SW, SE, NW, NE.
    EXPECT_EQ(hc::mortonEncode(2, 2) + 1, hc::mortonEncode(3, 2));
    EXPECT_EQ(hc::mortonEncode(2, 2) + 2, hc::mortonEncode(2, 3));
    EXPECT_EQ(hc::mortonEncode(2, 2) + 3, hc::mortonEncode(3, 3));
}

TEST(Morton, NodeOwnsAContiguousKeyRange) {
    // Every finest cell inside node (level L, corner c) has a key in [key(c), key(c) + 4^L).
    std::mt19937 rng(2);
    for (int t = 0; t < 2000; ++t) {
        int level = static_cast<int>(rng() % 10);
        uint32_t span = 1u << level;
        uint32_t cx = static_cast<uint32_t>(rng() % 1024) * span, cy = static_cast<uint32_t>(rng() % 1024) * span;
        uint64_t k0 = hc::mortonEncode(cx, cy);
        uint32_t dx = static_cast<uint32_t>(rng() % span), dy = static_cast<uint32_t>(rng() % span);
        uint64_t k = hc::mortonEncode(cx + dx, cy + dy);
        ASSERT_GE(k, k0);
        ASSERT_LT(k - k0, hc::mortonSpan(level));
    }
}

using hc::test::ingestFile;
using hc::test::ratio128Grid;

struct Case {
    const char* name;
    Grid grid;
};

std::vector<Case> realGrids() {
    std::vector<Case> out;
    out.push_back({"ratio128", ratio128Grid()});
    for (auto [file, tol] : {std::pair{"lidar1m_minnesota_utm15.tif", 0.25},
                             {"tin_valid_3857.tif", 0.25},
                             {"lux_elev.tif", 5.0},
                             {"west_bijou_gully_3m.asc", 0.5}}) {
        std::string p = hc::test::dataFile(file);
        if (!p.empty()) out.push_back({file, ingestFile(p, tol)});
    }
    return out;
}

bool containsPoint(const Grid::Square& q, double x, double y) { return x >= q.x0 && x < q.x1 && y >= q.y0 && y < q.y1; }
bool meetsBox(const Grid::Square& q, double x0, double y0, double x1, double y1) {
    return q.x0 <= x1 && q.x1 >= x0 && q.y0 <= y1 && q.y1 >= y0;
}
bool meetsDisk(const Grid::Square& q, double cx, double cy, double r) {
    double dx = std::max({q.x0 - cx, 0.0, cx - q.x1}), dy = std::max({q.y0 - cy, 0.0, cy - q.y1});
    return dx * dx + dy * dy <= r * r;
}

TEST(GridQueries, Ratio128GridHasBothExtremes) {
    Grid g = ratio128Grid();
    ASSERT_EQ(g.validate(), "");
    auto perLevel = g.cellsPerLevel();
    ASSERT_EQ(perLevel.size(), 8u);
    EXPECT_GT(perLevel[0], 1000u);
    EXPECT_GT(perLevel[7], 0u);
}

TEST(GridQueries, LocateMatchesBruteForce) {
    for (const Case& c : realGrids()) {
        SCOPED_TRACE(c.name);
        const Grid& g = c.grid;
        ASSERT_EQ(g.validate(), "");
        std::mt19937_64 rng(4);
        double side = g.domainSizeM();
        std::uniform_real_distribution<double> u(-0.05 * side, 1.05 * side);
        std::vector<std::pair<double, double>> pts;
        for (int i = 0; i < 3000; ++i) pts.emplace_back(u(rng), u(rng));
        for (size_t i = 0; i < g.cellCount(); i += std::max<size_t>(1, g.cellCount() / 500)) {
            auto q = g.cellSquare(i);  // corners and edges exactly: half-open ownership
            pts.emplace_back(q.x0, q.y0);
            pts.emplace_back(q.x1, q.y0);
            pts.emplace_back(q.x0, (q.y0 + q.y1) / 2);
        }
        for (auto [x, y] : pts) {
            std::optional<uint32_t> brute;
            for (size_t i = 0; i < g.cellCount(); ++i)
                if (containsPoint(g.cellSquare(i), x, y)) {
                    ASSERT_FALSE(brute) << "cells overlap at " << x << "," << y;
                    brute = static_cast<uint32_t>(i);
                }
            ASSERT_EQ(g.locate(x, y), brute) << "at " << x << "," << y;
        }
        EXPECT_FALSE(g.locate(NAN, 1.0));
    }
}

TEST(GridQueries, BoxAndDiskMatchBruteForce) {
    for (const Case& c : realGrids()) {
        SCOPED_TRACE(c.name);
        const Grid& g = c.grid;
        std::mt19937_64 rng(5);
        double side = g.domainSizeM();
        std::uniform_real_distribution<double> u(-0.1 * side, 1.1 * side), ext(0, 0.2 * side);
        for (int t = 0; t < 60; ++t) {
            double x0 = u(rng), y0 = u(rng), x1 = x0 + ext(rng), y1 = y0 + ext(rng);
            if (t % 3 == 0 && g.cellCount()) {  // a box whose edges coincide with cell edges
                auto q = g.cellSquare(rng() % g.cellCount());
                x0 = q.x0, y0 = q.y0, x1 = q.x1, y1 = q.y1;
            }
            std::vector<uint32_t> got;
            g.cellsInBox(x0, y0, x1, y1, got);
            std::sort(got.begin(), got.end());
            std::vector<uint32_t> want;
            for (size_t i = 0; i < g.cellCount(); ++i)
                if (meetsBox(g.cellSquare(i), x0, y0, x1, y1)) want.push_back(static_cast<uint32_t>(i));
            ASSERT_EQ(got, want) << "box " << x0 << "," << y0 << " .. " << x1 << "," << y1;

            double cx = u(rng), cy = u(rng), r = ext(rng);
            got.clear();
            g.cellsInDisk(cx, cy, r, got);
            std::sort(got.begin(), got.end());
            want.clear();
            for (size_t i = 0; i < g.cellCount(); ++i)
                if (meetsDisk(g.cellSquare(i), cx, cy, r)) want.push_back(static_cast<uint32_t>(i));
            ASSERT_EQ(got, want) << "disk " << cx << "," << cy << " r " << r;
        }
    }
}

TEST(GridQueries, NeighboursMatchBruteForce) {
    for (const Case& c : realGrids()) {
        SCOPED_TRACE(c.name);
        const Grid& g = c.grid;
        for (size_t i = 0; i < g.cellCount(); i += std::max<size_t>(1, g.cellCount() / 300)) {
            std::vector<uint32_t> got;
            g.neighbours(static_cast<uint32_t>(i), got);
            std::sort(got.begin(), got.end());
            auto qi = g.cellSquare(i);
            std::vector<uint32_t> want;
            for (size_t j = 0; j < g.cellCount(); ++j)
                if (j != i && meetsBox(g.cellSquare(j), qi.x0, qi.y0, qi.x1, qi.y1))
                    want.push_back(static_cast<uint32_t>(j));
            ASSERT_EQ(got, want) << "cell " << i;
            // Neighbours touch but never overlap.
            for (uint32_t j : got) {
                auto qj = g.cellSquare(j);
                bool overlap = qj.x0 < qi.x1 && qj.x1 > qi.x0 && qj.y0 < qi.y1 && qj.y1 > qi.y0;
                ASSERT_FALSE(overlap);
            }
        }
    }
}

TEST(GridValidate, CatchesBrokenInvariants) {
    // Each broken invariant is named, with the cell it breaks at: a message that blamed the wrong cell or the wrong
    // rule would send a user (or a reader's caller) to the wrong place.
    using ::testing::HasSubstr;
    Grid g = ratio128Grid();
    ASSERT_EQ(g.validate(), "");
    Grid unsorted = g;
    std::swap(unsorted.codes[10], unsorted.codes[11]);
    EXPECT_THAT(unsorted.validate(), HasSubstr("cell 11 overlaps or precedes cell 10"));
    Grid misaligned = g;
    size_t big = 0;
    while (hc::codeLevel(misaligned.codes[big]) == 0) ++big;
    misaligned.codes[big] =
        hc::makeCellCode(hc::codeKey(misaligned.codes[big]) + 1, hc::codeLevel(misaligned.codes[big]));
    EXPECT_THAT(misaligned.validate(), HasSubstr("cell " + std::to_string(big) + " is not aligned to its level"));
    Grid nonFinite = g;
    nonFinite.values[0][5] = NAN;
    EXPECT_THAT(nonFinite.validate(), HasSubstr("cell 5 has a non-finite elevation value"));
    Grid shortLayer = g;
    shortLayer.values[0].pop_back();
    EXPECT_THAT(shortLayer.validate(), HasSubstr("layer elevation has " + std::to_string(g.codes.size() - 1) +
                                                 " values for " + std::to_string(g.codes.size()) + " cells"));
}

TEST(CellStreamCheck, BatchesSayWhatCellByCellSays) {
    // A writer checks its cells a batch at a time (nextBatch's tight loop); the first bad cell must be found in any
    // batch, worded as next() words it, with the state left before it, and a good stream passes in any split.
    Grid g = ratio128Grid();
    Grid unsorted = g, nonFinite = g, misaligned = g;
    std::swap(unsorted.codes[700], unsorted.codes[701]);
    nonFinite.values[0][333] = INFINITY;
    size_t big = 0;
    while (hc::codeLevel(misaligned.codes[big]) == 0) ++big;
    misaligned.codes[big] = hc::makeCellCode(hc::codeKey(misaligned.codes[big]) + 1, hc::codeLevel(g.codes[big]));
    for (const Grid* grid : {&g, &unsorted, &nonFinite, &misaligned}) {
        const Grid shape = *grid;
        std::string oneByOne;
        hc::CellStreamCheck single(shape);
        for (size_t i = 0; i < grid->codes.size() && oneByOne.empty(); ++i)
            oneByOne = single.next(grid->codes[i], &grid->values[0][i]);
        for (size_t batch : {size_t{1}, size_t{7}, size_t{256}, grid->codes.size()}) {
            hc::CellStreamCheck check(shape);
            std::string problem;
            for (size_t at = 0; at < grid->codes.size() && problem.empty(); at += batch) {
                const size_t n = std::min(batch, grid->codes.size() - at);
                problem = check.nextBatch(std::span(grid->codes).subspan(at, n),
                                          {std::span<const float>(grid->values[0]).subspan(at, n)});
            }
            EXPECT_EQ(problem, oneByOne) << "batches of " << batch;
            if (!oneByOne.empty()) {
                EXPECT_EQ(check.count(), single.count()) << "batches of " << batch;
            }
        }
    }
}

TEST(GridHashes, StructureIgnoresValuesContentDoesNot) {
    Grid a = ratio128Grid();
    Grid b = a;
    b.values[0][3] += 1.0f;
    EXPECT_EQ(a.structureHash(), b.structureHash());
    EXPECT_NE(a.contentHash(), b.contentHash());
    Grid c = a;
    c.codes.pop_back();
    c.values[0].pop_back();
    EXPECT_NE(a.structureHash(), c.structureHash());
}

}  // namespace
