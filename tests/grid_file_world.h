// tests/grid_file_world.h: what the .hcg format's tests share (grid_file_test.cpp, grid_file_blocks_test.cpp): a tiny
// grid with every field set, reading and writing a file's bytes, the fixture, the comparison of two grids, and the
// checksums rewritten after an edit to reach the checks behind them.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <span>
#include <string>
#include <vector>

#include "heightcast/core/checksum.h"
#include "heightcast/core/sectioned_file.h"
#include "heightcast/grid/grid_file.h"
#include "temp_dir.h"

namespace hc::test::gridfile {

using hc::Grid;

// A small grid with two layers, two levels and a hole; every field set to a non-default value.
inline Grid tinyGrid() {
    Grid g;
    g.originWorldX = 652000.25;
    g.originWorldY = 5189000.5;  // a UTM northing: must survive as a double
    g.finestCellM = 2.5;
    g.rootLevel = 2;
    g.minLevel = 0;
    g.maxLevel = 1;
    g.crsWkt = "PROJCRS[\"test\"]";
    g.crsName = "test (TEST:1)";
    g.layers.push_back({"water_depth", "m"});
    g.values.emplace_back();
    g.stats.sourcePath = "tiny.tif";
    g.stats.sourceCrsName = "test";
    g.stats.sourceWidth = 4;
    g.stats.sourceHeight = 4;
    g.stats.validPixels = 13;
    g.stats.toleranceM = 0.25;
    g.stats.maxDevM = 0.125;
    g.stats.rmsDevM = 0.0625;
    const float v0[2] = {100.5f, 0.0f}, v1[2] = {101.0f, 0.25f}, v2[2] = {-11000.0f, 3.0f}, v3[2] = {8900.0f, 0.0f};
    g.appendCell(0, 0, 1, v0);  // SW quadrant: one level-1 cell
    g.appendCell(2, 0, 0, v1);  // SE quadrant: three level-0 cells and a hole at (3, 1)
    g.appendCell(3, 0, 0, v2);
    g.appendCell(2, 1, 0, v3);
    g.appendCell(0, 2, 1, v1);  // NW
    g.appendCell(2, 2, 1, v2);  // NE
    return g;
}

using hc::test::readBytes;
using hc::test::writeBytes;

class GridFile : public hc::test::TempDirTest {
protected:
    GridFile() : TempDirTest("hc_grid_file_") {}
};

inline void expectEqualGrids(const Grid& a, const Grid& b) {
    EXPECT_EQ(a.originWorldX, b.originWorldX);
    EXPECT_EQ(a.originWorldY, b.originWorldY);
    EXPECT_EQ(a.finestCellM, b.finestCellM);
    EXPECT_EQ(a.rootLevel, b.rootLevel);
    EXPECT_EQ(a.minLevel, b.minLevel);
    EXPECT_EQ(a.maxLevel, b.maxLevel);
    EXPECT_EQ(a.crsWkt, b.crsWkt);
    EXPECT_EQ(a.crsName, b.crsName);
    ASSERT_EQ(a.layers.size(), b.layers.size());
    for (size_t l = 0; l < a.layers.size(); ++l) {
        EXPECT_EQ(a.layers[l].name, b.layers[l].name);
        EXPECT_EQ(a.layers[l].units, b.layers[l].units);
        EXPECT_EQ(0, std::memcmp(a.values[l].data(), b.values[l].data(), a.values[l].size() * 4));  // bit-exact
    }
    EXPECT_EQ(a.codes, b.codes);
    EXPECT_EQ(a.stats.sourcePath, b.stats.sourcePath);
    EXPECT_EQ(a.stats.validPixels, b.stats.validPixels);
    EXPECT_EQ(a.stats.toleranceM, b.stats.toleranceM);
    EXPECT_EQ(a.stats.maxDevM, b.stats.maxDevM);
    EXPECT_EQ(a.stats.rmsDevM, b.stats.rmsDevM);
}

// Rewrites the header checksum after an edit, to reach the checks behind it.
inline void fixHeaderCrc(std::vector<char>& b) {
    uint32_t crc = hc::crc32(std::as_bytes(std::span(b.data(), 124)));
    std::memcpy(b.data() + 124, &crc, 4);
}

// Rewrites every checksum a 1.2 file derives from its bytes (block CRCs, section CRCs, table and header CRCs)
// after an edit, to reach the content checks behind them. Container layout: sectioned_file.h.
inline void fixAllChecksums(std::vector<char>& b) {
    auto load32 = [&](size_t at) {
        uint32_t v;
        std::memcpy(&v, b.data() + at, 4);
        return v;
    };
    auto load64 = [&](size_t at) {
        uint64_t v;
        std::memcpy(&v, b.data() + at, 8);
        return v;
    };
    auto crcOf = [&](uint64_t at, uint64_t n) { return hc::crc32(std::as_bytes(std::span(b.data() + at, n))); };
    const uint32_t count = load32(60);
    const size_t last = 128 + 32 * size_t{count - 1};
    ASSERT_EQ(load32(last), hc::kFileBlockChecksumsKind);
    const uint64_t blocks = load64(last + 8), blockBytes = load32(static_cast<size_t>(blocks));
    uint64_t at = blocks + 8;
    for (uint32_t s = 0; s + 1 < count; ++s) {
        const uint64_t offset = load64(128 + 32 * s + 8), bytes = load64(128 + 32 * s + 16);
        for (uint64_t from = 0; from < bytes; from += blockBytes, at += 4) {
            const uint32_t crc = crcOf(offset + from, std::min(blockBytes, bytes - from));
            std::memcpy(b.data() + at, &crc, 4);
        }
    }
    for (uint32_t s = 0; s < count; ++s) {
        const uint32_t crc = crcOf(load64(128 + 32 * s + 8), load64(128 + 32 * s + 16));
        std::memcpy(b.data() + 128 + 32 * s + 24, &crc, 4);
    }
    const uint32_t table = crcOf(128, 32 * count);
    std::memcpy(b.data() + 120, &table, 4);
    fixHeaderCrc(b);
}

}  // namespace hc::test::gridfile
