// The .hcg format: round trip, golden bytes, every truncation, every flipped byte, versions,
// content validation behind valid checksums, and atomic writes that leave nothing on failure.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <thread>

#include "heightcast/core/checksum.h"
#include "heightcast/core/error.h"
#include "heightcast/core/sectioned_file.h"
#include "heightcast/grid/grid_file.h"
#include "hostile_files.h"
#include "grid_file_world.h"

namespace {

namespace fs = std::filesystem;
using hc::Grid;
using namespace hc::test::gridfile;

TEST_F(GridFile, RoundTripIsExact) {
    Grid g = tinyGrid();
    ASSERT_EQ(g.validate(), "");
    hc::writeGrid(g, path("t.hcg"));
    Grid r = hc::readGrid(path("t.hcg"));
    expectEqualGrids(g, r);
    EXPECT_EQ(r.contentHash(), g.contentHash());
    EXPECT_EQ(r.locate(3 * 2.5 + 0.1, 1 * 2.5 + 0.1), std::nullopt) << "the hole stays a hole";
}

TEST_F(GridFile, NamedScalarLayersRoundTrip) {
    // Static layers before water depth (manning_n) and step layers after it (velocity, stored on wet cells only)
    // keep their names, units and values.
    Grid g = tinyGrid();
    g.layers.insert(g.layers.begin() + 1, {"manning_n", "s/m^(1/3)"});
    g.values.insert(g.values.begin() + 1, {0.03f, 0.03f, 0.05f, 0.1f, 0.03f, 0.03f});
    g.layers.push_back({"velocity", "m/s"});
    g.values.push_back({0.0f, 1.5f, 2.25f, 0.0f, 0.5f, 3.0f});  // 0 on the dry cells 0 and 3
    hc::writeGrid(g, path("layers.hcg"));
    Grid r = hc::readGrid(path("layers.hcg"));
    expectEqualGrids(g, r);
    EXPECT_EQ(r.findLayer("velocity"), 3);
    EXPECT_EQ(r.firstStepLayer(), 2u);
    EXPECT_EQ(r.layers[1].units, "s/m^(1/3)");
    EXPECT_EQ(r.contentHash(), g.contentHash());
    // A step layer's value on a dry cell would be lost (steps store wet cells only): refused, and no file left.
    g.values[3][0] = 0.75f;
    try {
        hc::writeGrid(g, path("lossy.hcg"));
        FAIL() << "a velocity on a dry cell was written";
    } catch (const hc::Error& e) {
        EXPECT_NE(std::string(e.what()).find("velocity"), std::string::npos) << e.what();
    }
    EXPECT_FALSE(fs::exists(path("lossy.hcg")));
}

TEST_F(GridFile, EmptyLayerValuesAndLargeGridRoundTrip) {
    Grid g;
    g.finestCellM = 0.75;
    g.rootLevel = 10;
    g.maxLevel = 3;
    std::mt19937 rng(7);
    for (uint64_t k = 0; k < 128 * 128; ++k) {  // level-3 cells, appended in Morton order
        float v = static_cast<float>(rng() % 100000) * 0.01f;
        g.appendCell(hc::mortonX(k) * 8, hc::mortonY(k) * 8, 3, &v);
    }
    hc::writeGrid(g, path("big.hcg"));
    expectEqualGrids(g, hc::readGrid(path("big.hcg")));
}

// Golden bytes pin format 1.3: a change to the layout fails here. Regenerate deliberately with
// HC_UPDATE_GOLDEN=1 only when the format version changes (and keep the older versions' files: next tests).
TEST_F(GridFile, GoldenBytes) {
    const std::string golden = std::string(HC_GOLDEN_DIR) + "/tiny_v1_3.hcg";
    Grid g = tinyGrid();
    hc::writeGrid(g, path("t.hcg"));
    std::vector<char> bytes = readBytes(path("t.hcg"));
    if (std::getenv("HC_UPDATE_GOLDEN")) writeBytes(golden, bytes, bytes.size());
    std::vector<char> want = readBytes(golden);
    ASSERT_FALSE(want.empty()) << golden << " missing";
    ASSERT_EQ(bytes.size(), want.size());
    for (size_t i = 0; i < bytes.size(); ++i) ASSERT_EQ(bytes[i], want[i]) << "first difference at byte " << i;
    expectEqualGrids(g, hc::readGrid(golden));
    // Spot-check documented offsets (grid_file.h).
    EXPECT_EQ(0, std::memcmp(want.data(), "\x89HCGRID\n", 8));
    uint16_t major;
    double originY;
    std::memcpy(&major, want.data() + 8, 2);
    std::memcpy(&originY, want.data() + 40, 8);
    EXPECT_EQ(major, 1);
    EXPECT_EQ(originY, 5189000.5);
}

// Format 1.0 (tinyGrid written before 1.1 added the META key crs_name) still reads, every field as written
// then, and its CRS name empty: hc-info asks PROJ for one from the WKT instead.
TEST_F(GridFile, Version10FileStillReads) {
    uint16_t fileMinor = 99;
    const Grid old = hc::readGrid(std::string(HC_GOLDEN_DIR) + "/tiny_v1_0.hcg", &fileMinor);
    EXPECT_EQ(fileMinor, 0);
    EXPECT_EQ(old.crsName, "");
    Grid want = tinyGrid();
    want.crsName.clear();
    expectEqualGrids(want, old);
    EXPECT_EQ(old.contentHash(), want.contentHash());
}

// Format 1.1 (no block checksums, no summary) still reads: whole, and through readGridInfo, which then reads
// it in full and says so (verified), with the summary computed from the cells.
TEST_F(GridFile, Version11FileStillReads) {
    const std::string v11 = std::string(HC_GOLDEN_DIR) + "/tiny_v1_1.hcg";
    uint16_t fileMinor = 99;
    const Grid old = hc::readGrid(v11, &fileMinor);
    EXPECT_EQ(fileMinor, 1);
    expectEqualGrids(tinyGrid(), old);
    const hc::GridFileInfo info = hc::readGridInfo(v11);
    EXPECT_TRUE(info.verified) << "a 1.1 file has no summary: the full pass is the only source";
    EXPECT_EQ(info.fileMinor, 1);
    EXPECT_EQ(info.blockBytes, 0u);
    EXPECT_EQ(info.summary.cellsPerLevel, tinyGrid().cellsPerLevel());
    EXPECT_GE(info.bytesChecked, 6u * (8 + 4 + 4)) << "cells and both layers are read and checked";
}

// Format 1.2 stored water as a LAYER: it still reads as a grid with water and no steps (one step at time 0), with the
// same content hash (so its influence caches and pyramids stay valid), and a 1.3 rewrite holds the same values.
TEST_F(GridFile, Version12WaterLayerStillReads) {
    const std::string v12 = std::string(HC_GOLDEN_DIR) + "/tiny_v1_2.hcg";
    uint16_t fileMinor = 99;
    const Grid old = hc::readGrid(v12, &fileMinor);
    EXPECT_EQ(fileMinor, 2);
    expectEqualGrids(tinyGrid(), old);
    EXPECT_TRUE(old.steps.empty());
    EXPECT_EQ(old.stepCount(), 1u);
    EXPECT_EQ(old.contentHash(), tinyGrid().contentHash());
    EXPECT_THROW(hc::readGrid(v12, nullptr, 1), hc::Error) << "a 1.2 file has one step";
    hc::writeGrid(old, path("v13.hcg"));
    const Grid now = hc::readGrid(path("v13.hcg"));
    expectEqualGrids(old, now);
    ASSERT_EQ(now.steps.size(), 1u);
    EXPECT_EQ(now.steps[0].wetCells, 4u);
    EXPECT_EQ(now.steps[0].contentHash, old.contentHash());
}

// A 1.1 file must carry crs_name: a writer that forgot it is caught (its META rewritten without the key).
TEST_F(GridFile, Version11WithoutCrsNameIsRefused) {
    std::vector<char> v10 = readBytes(std::string(HC_GOLDEN_DIR) + "/tiny_v1_0.hcg");
    ASSERT_FALSE(v10.empty());
    uint16_t one = 1;
    std::memcpy(v10.data() + 10, &one, 2);  // a 1.0 file (no crs_name) relabelled 1.1
    fixHeaderCrc(v10);
    writeBytes(path("relabelled.hcg"), v10, v10.size());
    try {
        hc::readGrid(path("relabelled.hcg"));
        FAIL() << "a 1.1 file without crs_name was accepted";
    } catch (const hc::Error& e) {
        EXPECT_NE(std::string(e.what()).find("crs_name"), std::string::npos) << e.what();
    }
}

TEST_F(GridFile, EveryTruncationIsRefused) {
    hc::writeGrid(tinyGrid(), path("t.hcg"));
    std::vector<char> bytes = readBytes(path("t.hcg"));
    for (size_t n = 0; n < bytes.size(); ++n) {
        writeBytes(path("cut.hcg"), bytes, n);
        try {
            hc::readGrid(path("cut.hcg"));
            FAIL() << "a file cut to " << n << " bytes was accepted";
        } catch (const hc::Error& e) {
            std::string m = e.what();
            ASSERT_NE(m.find("cut.hcg"), std::string::npos) << m;
            if (n >= hc::kGridHeaderBytes) {
                ASSERT_NE(m.find("truncated"), std::string::npos) << m;
            }
        }
    }
}

TEST_F(GridFile, EveryFlippedByteIsCaught) {
    hc::writeGrid(tinyGrid(), path("t.hcg"));
    std::vector<char> bytes = readBytes(path("t.hcg"));
    for (size_t i = 0; i < bytes.size(); ++i)
        for (char mask : {char(0x01), char(0x80)}) {
            std::vector<char> bad = bytes;
            bad[i] = static_cast<char>(bad[i] ^ mask);
            writeBytes(path("bad.hcg"), bad, bad.size());
            EXPECT_THROW(hc::readGrid(path("bad.hcg")), hc::Error) << "flipping byte " << i << " went unnoticed";
        }
}

TEST_F(GridFile, VersionsNewerMajorRefusedNewerMinorRead) {
    hc::writeGrid(tinyGrid(), path("t.hcg"));
    std::vector<char> bytes = readBytes(path("t.hcg"));
    std::vector<char> major = bytes;
    uint16_t two = 2;
    std::memcpy(major.data() + 8, &two, 2);
    fixHeaderCrc(major);
    writeBytes(path("v2.hcg"), major, major.size());
    try {
        hc::readGrid(path("v2.hcg"));
        FAIL() << "a newer major version was accepted";
    } catch (const hc::Error& e) {
        EXPECT_NE(std::string(e.what()).find("newer"), std::string::npos) << e.what();
    }
    std::vector<char> minor = bytes;
    uint16_t seven = 7;
    std::memcpy(minor.data() + 10, &seven, 2);
    fixHeaderCrc(minor);
    writeBytes(path("v1_7.hcg"), minor, minor.size());
    uint16_t fileMinor = 0;
    expectEqualGrids(tinyGrid(), hc::readGrid(path("v1_7.hcg"), &fileMinor));
    EXPECT_EQ(fileMinor, 7);
}

TEST_F(GridFile, InvalidCellsBehindValidChecksumsAreRefused) {
    // Two cells swapped, with every checksum recomputed: only the content validation can catch it.
    Grid g = tinyGrid();
    hc::writeGrid(g, path("t.hcg"));
    std::vector<char> b = readBytes(path("t.hcg"));
    uint64_t cellsOffset, cellsBytes;
    std::memcpy(&cellsOffset, b.data() + 128 + 8, 8);  // section 0 = CELLS
    std::memcpy(&cellsBytes, b.data() + 128 + 16, 8);
    std::swap_ranges(b.begin() + static_cast<long>(cellsOffset), b.begin() + static_cast<long>(cellsOffset) + 8,
                     b.begin() + static_cast<long>(cellsOffset) + 8);
    ASSERT_GE(cellsBytes, 16u);
    fixAllChecksums(b);
    writeBytes(path("swapped.hcg"), b, b.size());
    try {
        hc::readGrid(path("swapped.hcg"));
        FAIL() << "unsorted cells were accepted";
    } catch (const hc::Error& e) {
        EXPECT_NE(std::string(e.what()).find("invalid grid"), std::string::npos) << e.what();
    }
}

TEST_F(GridFile, FailedWritesLeaveNothingBehind) {
    Grid bad = tinyGrid();
    bad.values[1][2] = NAN;  // invalid: refused before any byte is written
    EXPECT_THROW(hc::writeGrid(bad, path("bad.hcg")), hc::Error);
    EXPECT_THROW(hc::writeGrid(tinyGrid(), path("no/such/dir/t.hcg")), hc::Error);
    EXPECT_TRUE(fs::is_empty(dir_)) << "a failed write left a file (or a temporary) behind";
    // A failed rewrite keeps the previous good file intact.
    hc::writeGrid(tinyGrid(), path("keep.hcg"));
    EXPECT_THROW(hc::writeGrid(bad, path("keep.hcg")), hc::Error);
    expectEqualGrids(tinyGrid(), hc::readGrid(path("keep.hcg")));
}

TEST_F(GridFile, MissingAndForeignFilesGetClearErrors) {
    try {
        hc::readGrid(path("absent.hcg"));
        FAIL();
    } catch (const hc::Error& e) {
        EXPECT_NE(std::string(e.what()).find("no such file"), std::string::npos);
    }
    std::vector<char> text(500, 'a');
    writeBytes(path("text.hcg"), text, text.size());
    try {
        hc::readGrid(path("text.hcg"));
        FAIL();
    } catch (const hc::Error& e) {
        EXPECT_NE(std::string(e.what()).find("magic"), std::string::npos) << e.what();
    }
}

TEST(Checksum, FoldedCrcEqualsTheTable) {
    // The carry-less-multiply path (lengths from 256 bytes on, any alignment, any starting CRC) against slicing-by-8,
    // exactly: one wrong fold constant changes every CRC of 64 bytes or more.
    std::mt19937_64 rng(7);
    std::vector<std::byte> data(70000);
    for (auto& b : data) b = static_cast<std::byte>(rng());
    for (size_t n : {size_t{0}, size_t{255}, size_t{256}, size_t{257}, size_t{319}, size_t{320}, size_t{1000},
                     size_t{4095}, size_t{65536}, size_t{69990}})
        for (size_t at : {size_t{0}, size_t{1}, size_t{7}})
            for (uint32_t start : {0u, 0xFFFFFFFFu, 0x12345678u}) {
                const auto part = std::span(data).subspan(at, n);
                EXPECT_EQ(hc::crc32(part, start), hc::crc32Portable(part, start)) << n << " at " << at;
            }
}

TEST(Checksum, KnownValues) {
    // CRC-32 check value of "123456789" (the standard test vector): 0xCBF43926.
    const char* s = "123456789";
    EXPECT_EQ(hc::crc32(std::as_bytes(std::span(s, 9))), 0xCBF43926u);
    // Incremental CRC equals one-shot; Hash64 is split-invariant.
    std::vector<std::byte> data(1000);
    for (size_t i = 0; i < data.size(); ++i) data[i] = static_cast<std::byte>(i * 7 + 3);
    uint32_t whole = hc::crc32(data);
    EXPECT_EQ(hc::crc32(std::span(data).subspan(333), hc::crc32(std::span(data).first(333))), whole);
    // Combined from the parts' CRCs alone (the writer's section CRCs from its block CRCs), any split.
    for (size_t cut : {size_t{0}, size_t{1}, size_t{333}, size_t{999}, size_t{1000}})
        EXPECT_EQ(hc::crc32Combine(hc::crc32(std::span(data).first(cut)), hc::crc32(std::span(data).subspan(cut)),
                                   1000 - cut),
                  whole)
            << cut;
    hc::Hash64 a, b;
    a.update(data);
    b.update(std::span(data).first(5));
    b.update(std::span(data).subspan(5, 600));
    b.update(std::span(data).subspan(605));
    EXPECT_EQ(a.digest(), b.digest());
    hc::Hash64 c;
    data[999] ^= std::byte{1};
    c.update(data);
    EXPECT_NE(a.digest(), c.digest());
}

TEST_F(GridFile, StreamedWriteEqualsWholeWrite) {
    // Any batching gives the very same bytes as writeGrid().
    Grid g = tinyGrid();
    hc::writeGrid(g, path("whole.hcg"));
    for (size_t batch : {size_t{1}, size_t{2}, size_t{4}, size_t{6}}) {
        hc::GridFileWriter w(path("stream.hcg"), g, g.cellCount(), 1);
        for (size_t i = 0; i < g.cellCount(); i += batch) {
            size_t n = std::min(batch, g.cellCount() - i);
            w.append(std::span(g.codes).subspan(i, n), {std::span<const float>(g.values[0]).subspan(i, n)});
        }
        w.appendStep(hc::sparseStep(g));
        w.commit(g.stats);
        EXPECT_EQ(readBytes(path("stream.hcg")), readBytes(path("whole.hcg"))) << "batch " << batch;
    }
}

TEST_F(GridFile, StreamedWriteRefusesBadStreams) {
    Grid g = tinyGrid();
    auto values = [&](size_t i, size_t n) {
        return std::vector<std::span<const float>>{std::span<const float>(g.values[0]).subspan(i, n)};
    };
    {  // too few cells: commit refuses and nothing is left
        hc::GridFileWriter w(path("short.hcg"), g, g.cellCount(), 1);
        w.append(std::span(g.codes).first(3), values(0, 3));
        EXPECT_THROW(w.commit(g.stats), hc::Error);
    }
    {  // out of order
        hc::GridFileWriter w(path("order.hcg"), g, g.cellCount(), 1);
        w.append(std::span(g.codes).subspan(3, 1), values(3, 1));
        EXPECT_THROW(w.append(std::span(g.codes).subspan(2, 1), values(2, 1)), hc::Error);
    }
    {  // more than announced
        hc::GridFileWriter w(path("long.hcg"), g, 2, 1);
        EXPECT_THROW(w.append(std::span(g.codes).first(3), values(0, 3)), hc::Error);
    }
    {  // a water grid without steps, steps without water
        EXPECT_THROW(hc::GridFileWriter(path("nosteps.hcg"), g, g.cellCount(), 0), hc::Error);
        Grid dry = g;
        dry.layers.resize(1), dry.values.resize(1);
        EXPECT_THROW(hc::GridFileWriter(path("dry.hcg"), dry, dry.cellCount(), 1), hc::Error);
    }
    {  // a step before the cells, steps missing at commit, unsorted times, bad indices or depths
        hc::GridFileWriter w(path("steps.hcg"), g, g.cellCount(), 2);
        hc::WaterStepData s = hc::sparseStep(g);
        EXPECT_THROW(w.appendStep(s), hc::Error) << "a step before all cells";
        w.append(g.codes, values(0, g.cellCount()));
        s.timeS = 60;
        w.appendStep(s);
        hc::WaterStepData bad = s;
        EXPECT_THROW(w.appendStep(bad), hc::Error) << "the same time again";
        bad.timeS = 30;
        EXPECT_THROW(w.appendStep(bad), hc::Error) << "an earlier time";
        bad = s, bad.timeS = 120, std::swap(bad.wet[0], bad.wet[1]);
        EXPECT_THROW(w.appendStep(bad), hc::Error) << "indices out of order";
        bad = s, bad.timeS = 120, bad.wet.back() = uint32_t(g.cellCount());
        EXPECT_THROW(w.appendStep(bad), hc::Error) << "an index past the cells";
        bad = s, bad.timeS = 120, bad.values[0][0] = 0;
        EXPECT_THROW(w.appendStep(bad), hc::Error) << "a stored dry cell";
        bad = s, bad.timeS = NAN;
        EXPECT_THROW(w.appendStep(bad), hc::Error) << "a NaN time";
        EXPECT_THROW(w.commit(g.stats), hc::Error) << "one step of two";
    }
    EXPECT_TRUE(fs::is_empty(dir_)) << "a failed streamed write left a file behind";
}

// Issue 11: a declared cell count the file cannot hold, behind valid checksums, is refused with the file's
// name and the count's byte offset. 2^62 cells with empty CELLS and LAYER sections passed the old size
// checks (2^62 * 8 and 2^62 * 4 wrap to 0) and escaped as std::length_error ("vector::_M_default_append").
TEST_F(GridFile, HugeCellCountsBehindValidChecksumsAreRefused) {
    hc::writeGrid(tinyGrid(), path("t.hcg"));
    auto message = [&](uint64_t count) {
        hc::hostile::gridWithEmptySections(path("t.hcg"), path("huge.hcg"), count);
        try {
            hc::readGrid(path("huge.hcg"));
        } catch (const hc::Error& e) {
            return std::string(e.what());
        }  // any other exception fails the test
        return std::string("accepted");
    };
    for (uint64_t count : {uint64_t{1} << 62, uint64_t{1} << 61, uint64_t{1} << 63, ~uint64_t{0}, uint64_t{1} << 40}) {
        const std::string m = message(count);
        EXPECT_EQ(
            m.rfind(path("huge.hcg") + ": at byte offset 24: header declares " + std::to_string(count) + " cells", 0),
            0u)
            << count << ": " << m;
    }
    // A count the file could hold gets to the section sizes, which must then disagree with it.
    const std::string small = message(7);
    EXPECT_NE(small.find("CELLS section holds 0 bytes, expected 8 for each of 7 cells"), std::string::npos) << small;
}

// Issue 11, found by fuzz_hcg with the count checks reverted (after 134 k executions): 2^62 + 208 cells
// declared for the 208 present, so that 8x and 4x the count wrap around to the real section sizes; the
// reader then asked for 2^62 cells (std::length_error). The file is the input as the reader saw it
// (fuzz_input.h's CRC fix-up applied); it is also a seed of fuzz/corpus/hcg/, so fuzz runs replay it.
TEST_F(GridFile, FuzzFindingCellCountWrappingToTheSectionSizes) {
    const std::string file = std::string(HC_GOLDEN_DIR) + "/hostile/fuzz_hcg_cells_wrap.hcg";
    try {
        hc::readGrid(file);
        FAIL() << "accepted";
    } catch (const hc::Error& e) {
        EXPECT_EQ(
            std::string(e.what()).rfind(file + ": at byte offset 24: header declares 4611686018427388112 cells", 0), 0u)
            << e.what();
    }
}

}  // namespace
