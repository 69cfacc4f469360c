// The .hci influence cache: round trip and golden bytes, an older version still read, every truncation and flipped
// byte refused, stale and foreign caches refused and rebuilt, and the fuzzer's findings (counts behind valid
// checksums, lists past the entry count).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>

#include "heightcast/core/checksum.h"
#include "heightcast/core/error.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/influence/influence.h"
#include "hostile_files.h"
#include "temp_dir.h"
#include "test_grids.h"

namespace {

namespace fs = std::filesystem;
using hc::Grid;
using hc::influence::InfluenceLists;
using hc::influence::KernelParams;
using hc::test::ratio128Grid;

class CacheFile : public hc::test::TempDirTest {
protected:
    CacheFile() : TempDirTest("hc_cache_") {}
};

using hc::test::readBytes;
using hc::test::writeBytes;

// Six cells of two sizes (the grid of grid_file_test's golden file).
Grid tinyGrid() {
    Grid g;
    g.finestCellM = 2.5;
    g.rootLevel = 2;
    g.maxLevel = 1;
    const float v = 1;
    g.appendCell(0, 0, 1, &v);
    g.appendCell(2, 0, 0, &v);
    g.appendCell(3, 0, 0, &v);
    g.appendCell(2, 1, 0, &v);
    g.appendCell(0, 2, 1, &v);
    g.appendCell(2, 2, 1, &v);
    return g;
}

TEST_F(CacheFile, RoundTripAndGoldenBytes) {
    Grid g = tinyGrid();
    InfluenceLists lists = hc::influence::buildInfluenceLists(g, KernelParams{});
    hc::influence::writeInfluenceCache(lists, path("t.hci"));
    InfluenceLists back = hc::influence::readInfluenceCache(path("t.hci"), g, KernelParams{});
    ASSERT_EQ(back.cellCount(), lists.cellCount());
    EXPECT_TRUE(std::equal(back.offsets().begin(), back.offsets().end(), lists.offsets().begin()));
    EXPECT_TRUE(std::equal(back.indices().begin(), back.indices().end(), lists.indices().begin()));
    const std::string golden = std::string(HC_GOLDEN_DIR) + "/tiny_v1_1.hci";
    if (std::getenv("HC_UPDATE_GOLDEN")) writeBytes(golden, readBytes(path("t.hci")), readBytes(path("t.hci")).size());
    EXPECT_EQ(readBytes(path("t.hci")), readBytes(golden)) << "format 1.1 changed: update deliberately";
}

// Format 1.0 (one CRC per section, no block checksums) still reads, with the same lists; and a flipped byte in
// it is still caught (the whole section is checked at its first touch).
TEST_F(CacheFile, Version10CacheStillReads) {
    Grid g = tinyGrid();
    const InfluenceLists lists = hc::influence::buildInfluenceLists(g, KernelParams{});
    const std::string v10 = std::string(HC_GOLDEN_DIR) + "/tiny_v1_0.hci";
    const InfluenceLists old = hc::influence::readInfluenceCache(v10, g, KernelParams{});
    EXPECT_TRUE(std::equal(old.offsets().begin(), old.offsets().end(), lists.offsets().begin(), lists.offsets().end()));
    EXPECT_TRUE(std::equal(old.indices().begin(), old.indices().end(), lists.indices().begin(), lists.indices().end()));
    std::vector<char> bad = readBytes(v10);
    bad[bad.size() - 3] ^= 0x01;  // in INDICES, the last section
    writeBytes(path("bad.hci"), bad, bad.size());
    EXPECT_THROW(hc::influence::readInfluenceCache(path("bad.hci"), g, KernelParams{}), hc::Error);
}

TEST_F(CacheFile, EveryTruncationAndEveryFlippedByteIsRefused) {
    Grid g = tinyGrid();
    hc::influence::writeInfluenceCache(hc::influence::buildInfluenceLists(g, KernelParams{}), path("t.hci"));
    std::vector<char> bytes = readBytes(path("t.hci"));
    for (size_t n = 0; n < bytes.size(); ++n) {
        writeBytes(path("cut.hci"), bytes, n);
        EXPECT_THROW(hc::influence::readInfluenceCache(path("cut.hci"), g, KernelParams{}), hc::Error)
            << "cut to " << n;
    }
    for (size_t i = 0; i < bytes.size(); ++i) {
        std::vector<char> bad = bytes;
        bad[i] = static_cast<char>(bad[i] ^ 0x10);
        writeBytes(path("bad.hci"), bad, bad.size());
        EXPECT_THROW(hc::influence::readInfluenceCache(path("bad.hci"), g, KernelParams{}), hc::Error) << "byte " << i;
    }
}

TEST_F(CacheFile, StaleAndForeignCachesAreRefusedAndRebuilt) {
    Grid g = ratio128Grid();
    hc::influence::writeInfluenceCache(hc::influence::buildInfluenceLists(g, KernelParams{}), path("g.hci"));
    auto message = [&](const Grid& grid, const KernelParams& p) {
        try {
            hc::influence::readInfluenceCache(path("g.hci"), grid, p);
        } catch (const hc::Error& e) {
            return std::string(e.what());
        }
        return std::string("accepted");
    };
    // New values on the same tree (the next water time step): the cache stays valid.
    Grid wetter = g;
    for (float& v : wetter.values[0]) v += 1.0f;
    EXPECT_EQ(message(wetter, KernelParams{}), "accepted");
    // Another tree: stale.
    Grid other = tinyGrid();
    EXPECT_NE(message(other, KernelParams{}).find("stale or foreign"), std::string::npos);
    // Other parameters: says which.
    KernelParams wide;
    wide.sigma = 1.5;
    EXPECT_NE(message(g, wide).find("sigma 1.000000"), std::string::npos) << message(g, wide);
    // Tools rebuild and say so.
    std::string note;
    InfluenceLists rebuilt = hc::influence::loadOrBuildCache(g, wide, path("g.hci"), 0, false, note);
    EXPECT_NE(note.find("rebuilt"), std::string::npos) << note;
    EXPECT_EQ(rebuilt.params().sigma, 1.5);
    hc::influence::loadOrBuildCache(g, wide, path("g.hci"), 0, false, note);
    EXPECT_NE(note.find("using"), std::string::npos) << note;
    hc::influence::loadOrBuildCache(g, wide, path("none.hci"), 0, false, note);
    EXPECT_NE(note.find("no influence cache"), std::string::npos) << note;
}

// Issue 11: declared counts behind valid checksums. 2^62 entries with an empty INDICES section passed the
// old size check (2^62 * 4 wraps to 0) and hc-probe walked the lists past the end of the file; now the
// count is refused at its byte offset. Same for a cell count the file cannot hold.
TEST_F(CacheFile, HugeCountsBehindValidChecksumsAreRefused) {
    Grid g = tinyGrid();
    hc::influence::writeInfluenceCache(hc::influence::buildInfluenceLists(g, KernelParams{}), path("t.hci"));
    auto message = [&] {
        try {
            hc::influence::readInfluenceCache(path("huge.hci"), g, KernelParams{});
        } catch (const hc::Error& e) {
            return std::string(e.what());
        }
        return std::string("accepted");
    };
    for (uint64_t count : {uint64_t{1} << 62, uint64_t{1} << 63, ~uint64_t{0}, uint64_t{1} << 40}) {
        hc::hostile::cacheWithEntryCount(path("t.hci"), path("huge.hci"), count);
        const std::string m = message();
        EXPECT_EQ(
            m.rfind(path("huge.hci") + ": at byte offset 32: header declares " + std::to_string(count) + " entries", 0),
            0u)
            << count << ": " << m;
    }
    for (uint64_t count : {uint64_t{1} << 61, ~uint64_t{0}}) {
        auto c = hc::hostile::readContainer(path("t.hci"), hc::hostile::kCacheFormat);
        hc::bytes::store<uint64_t>(c.header, hc::hostile::kCacheCellCountAt, count);
        hc::hostile::writeContainer(c, path("huge.hci"), hc::hostile::kCacheFormat);
        const std::string m = message();
        EXPECT_EQ(
            m.rfind(path("huge.hci") + ": at byte offset 24: header declares " + std::to_string(count) + " cells", 0),
            0u)
            << count << ": " << m;
    }
}

// Issue 11: OFFSETS that end at the entry count but overshoot it before (0, m + 100, ...) made the old
// reader read 100 indices past the end of INDICES before it noticed the decrease.
TEST_F(CacheFile, ListsRunningPastTheEntryCountAreRefused) {
    Grid g = tinyGrid();
    hc::influence::writeInfluenceCache(hc::influence::buildInfluenceLists(g, KernelParams{}), path("t.hci"));
    hc::hostile::cacheWithListPastTheEnd(path("t.hci"), path("past.hci"), 100);
    try {
        hc::influence::readInfluenceCache(path("past.hci"), g, KernelParams{});
        FAIL() << "a list past the entry count was accepted";
    } catch (const hc::Error& e) {
        EXPECT_NE(std::string(e.what()).find("OFFSETS exceed the entry count"), std::string::npos) << e.what();
    }
}

// Issue 11, found by fuzz_hci with the fix reverted (within its first 20 executions, once files were read
// into exact-size heap blocks so that AddressSanitizer saw the overrun): OFFSETS[21] = 16712333 with 2307
// entries, a list running past the end of INDICES. The file is the input as the reader saw it (CRCs fixed
// up), for the grid it was built from (also copied beside it); it is also a seed of fuzz/corpus/hci/.
TEST_F(CacheFile, FuzzFindingListPastTheEntryCount) {
    const std::string dir = std::string(HC_GOLDEN_DIR) + "/hostile/";
    const Grid g = hc::readGrid(dir + "buscot_20x20.hcg");
    KernelParams params;
    params.sigma = 1.5;  // the parameters the file declares
    params.truncation = 2.5;
    try {
        hc::influence::readInfluenceCache(dir + "fuzz_hci_list_past_end.hci", g, params);
        FAIL() << "accepted";
    } catch (const hc::Error& e) {
        EXPECT_NE(std::string(e.what()).find(": at byte offset 360: OFFSETS exceed the entry count 2307 at cell 20"),
                  std::string::npos)
            << e.what();
    }
}

}  // namespace
