// The .hcg format's blocks, steps and parts: a flipped byte caught by reading its block alone, the stored summary
// against a full pass, water steps read one at a time and checked when read, and a file written by parts (mpirun's
// ranks) the same bytes as one written whole. Shared with grid_file_test.cpp: grid_file_world.h.
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

// ------------------------------------------------------------------ block checksums and the stored summary

// The container as the .hcg reader sees it (grid_file_internal.h), to read sections in parts.
const hc::FileFormat kGridFormat12{
    {'\x89', 'H', 'C', 'G', 'R', 'I', 'D', '\n'}, 1, 2, "heightcast grid (.hcg)", {1, 2, 3}, 2};

// 300 k level-0 cells: CELLS spans 3 blocks of 1 MiB (2.4 MB), the elevation layer 2.
Grid threeBlockGrid() {
    Grid g;
    g.finestCellM = 0.5;
    g.rootLevel = 10;
    for (uint64_t k = 0; k < 300000; ++k) {
        const float v = static_cast<float>(k % 977) * 0.25f - 12.0f;
        g.appendCell(hc::mortonX(k), hc::mortonY(k), 0, &v);
    }
    return g;
}

// A flipped byte in one block of CELLS is caught by reading that block, with the block's offset, and by
// nothing that reads only other blocks; readGridInfo (no cells read) does not see it, verification does.
TEST_F(GridFile, AFlippedByteIsCaughtByReadingItsBlockOnly) {
    hc::writeGrid(threeBlockGrid(), path("t.hcg"));
    std::vector<char> b = readBytes(path("t.hcg"));
    uint64_t cellsOffset;
    std::memcpy(&cellsOffset, b.data() + 128 + 8, 8);  // section 0 = CELLS
    const uint64_t block2 = cellsOffset + 2 * uint64_t{hc::kFileBlockBytes};
    b[block2 + 12345] ^= 0x10;
    writeBytes(path("bad.hcg"), b, b.size());

    const hc::SectionedFileReader r(path("bad.hcg"), kGridFormat12);  // open reads no data: no error yet
    EXPECT_EQ(r.blockBytes(), hc::kFileBlockBytes);
    const hc::FileSection& cells = r.sections()[0];
    ASSERT_EQ(cells.kind, 2u);
    EXPECT_NO_THROW(r.read(cells, 0, 8));
    EXPECT_NO_THROW(r.read(cells, hc::kFileBlockBytes - 4, 8));  // blocks 0 and 1
    EXPECT_EQ(r.bytesChecked(), 2 * uint64_t{hc::kFileBlockBytes}) << "exactly the two blocks touched are checked";
    const std::string want =
        path("bad.hcg") + ": at byte offset " + std::to_string(block2) + ": checksum mismatch in section 0, block 2";
    try {
        r.read(cells, 2 * uint64_t{hc::kFileBlockBytes} + 100000, 8);
        FAIL() << "a flipped byte in block 2 went unnoticed when block 2 was read";
    } catch (const hc::Error& e) {
        EXPECT_EQ(std::string(e.what()).rfind(want, 0), 0u) << e.what();
    }
    EXPECT_THROW(r.verifyAll(), hc::Error);

    const hc::GridFileInfo info = hc::readGridInfo(path("bad.hcg"));
    EXPECT_FALSE(info.verified);
    EXPECT_EQ(info.cellCount, 300000u);
    EXPECT_LT(info.bytesChecked, 4096u) << "readGridInfo read more than META";
    for (auto read :
         {+[](const std::string& p) { hc::readGrid(p); }, +[](const std::string& p) { hc::verifyGridFile(p); }}) {
        try {
            read(path("bad.hcg"));
            FAIL() << "full verification missed the flipped byte";
        } catch (const hc::Error& e) {
            EXPECT_EQ(std::string(e.what()).rfind(want, 0), 0u) << e.what();
        }
    }
}

// Blocks are marked checked with atomics: threads reading the same blocks at once agree, each block counted once.
TEST_F(GridFile, ConcurrentReadsCheckEachBlockOnce) {
    hc::writeGrid(threeBlockGrid(), path("t.hcg"));
    const hc::SectionedFileReader r(path("t.hcg"), kGridFormat12);
    std::vector<std::thread> threads;
    for (int t = 0; t < 4; ++t) threads.emplace_back([&] { r.verifyAll(); });
    for (auto& t : threads) t.join();
    uint64_t sections = 0;
    for (const hc::FileSection& s : r.sections()) sections += s.bytes;
    EXPECT_EQ(r.bytesChecked(), sections);
}

// A file of an older minor (one CRC per section) is checked whole at the first touch of a section.
TEST_F(GridFile, OldMinorSectionsAreCheckedWholeAtFirstTouch) {
    std::vector<char> b = readBytes(std::string(HC_GOLDEN_DIR) + "/tiny_v1_1.hcg");
    uint64_t layerOffset;
    std::memcpy(&layerOffset, b.data() + 128 + 32 + 8, 8);  // section 1 = LAYER 0
    b[layerOffset + 20] ^= 0x01;                            // the sixth value, not the first
    writeBytes(path("old.hcg"), b, b.size());
    const hc::SectionedFileReader r(path("old.hcg"), kGridFormat12);
    EXPECT_EQ(r.blockBytes(), 0u);
    EXPECT_NO_THROW(r.data(r.sections()[0]));
    EXPECT_EQ(r.bytesChecked(), r.sections()[0].bytes);
    try {
        r.read(r.sections()[1], 0, 4);
        FAIL() << "reading the first value of a damaged 1.1 section did not check the whole section";
    } catch (const hc::Error& e) {
        EXPECT_NE(std::string(e.what()).find("at byte offset " + std::to_string(layerOffset) +
                                             ": checksum mismatch in section 1"),
                  std::string::npos)
            << e.what();
    }
}

// readGridInfo's summary is what a full pass over the cells gives, without reading them.
TEST_F(GridFile, SummaryEqualsAFullPass) {
    for (const Grid& g : {tinyGrid(), threeBlockGrid()}) {
        hc::writeGrid(g, path("t.hcg"));
        const hc::GridFileInfo info = hc::readGridInfo(path("t.hcg"));
        EXPECT_FALSE(info.verified);
        EXPECT_EQ(info.fileMinor, hc::kGridFileMinor);
        EXPECT_EQ(info.cellCount, g.cellCount());
        EXPECT_EQ(info.summary.cellsPerLevel, g.cellsPerLevel());
        double x0, y0, x1, y1;
        g.boundsLocal(x0, y0, x1, y1);
        EXPECT_EQ(static_cast<double>(info.summary.boundsFinest[0]) * g.finestCellM, x0);
        EXPECT_EQ(static_cast<double>(info.summary.boundsFinest[1]) * g.finestCellM, y0);
        EXPECT_EQ(static_cast<double>(info.summary.boundsFinest[2]) * g.finestCellM, x1);
        EXPECT_EQ(static_cast<double>(info.summary.boundsFinest[3]) * g.finestCellM, y1);
        ASSERT_EQ(info.summary.layerMin.size(), g.layers.size());
        for (size_t l = 0; l < g.layers.size(); ++l) {
            EXPECT_EQ(info.summary.layerMin[l], *std::min_element(g.values[l].begin(), g.values[l].end()));
            EXPECT_EQ(info.summary.layerMax[l], *std::max_element(g.values[l].begin(), g.values[l].end()));
        }
        EXPECT_EQ(info.structureHash, g.structureHash());
        EXPECT_EQ(info.contentHash, g.contentHash());
        EXPECT_EQ(info.shape.crsName, g.crsName);
        EXPECT_EQ(info.shape.stats.validPixels, g.stats.validPixels);
        const hc::GridFileInfo full = hc::verifyGridFile(path("t.hcg"));
        EXPECT_TRUE(full.verified);
        EXPECT_EQ(full.summary.cellsPerLevel, info.summary.cellsPerLevel);
        uint64_t sectionBytes = 0;
        const hc::SectionedFileReader reader(path("t.hcg"), kGridFormat12);
        for (const hc::FileSection& sec : reader.sections()) sectionBytes += sec.bytes;
        EXPECT_EQ(full.bytesChecked, sectionBytes) << "verification checks every section byte";
    }
}

// A summary that lies (behind valid checksums) passes readGridInfo when it fits the header, and is caught by
// every full read; one that does not fit the header is refused by readGridInfo too.
TEST_F(GridFile, ALyingSummaryIsCaughtByVerification) {
    hc::writeGrid(tinyGrid(), path("t.hcg"));
    const std::vector<char> good = readBytes(path("t.hcg"));
    // META's value strings are length-prefixed (u32 3, then "3 3").
    auto value = [](const char* v) { return std::string("\x03\0\0\0", 4) + v; };
    auto edit = [&](const std::string& from, const std::string& to) {
        std::vector<char> b = good;
        const auto at = std::search(b.begin(), b.end(), from.begin(), from.end());
        EXPECT_NE(at, b.end()) << from;
        std::copy(to.begin(), to.end(), at);  // same length: the layout stays
        fixAllChecksums(b);
        writeBytes(path("lie.hcg"), b, b.size());
    };
    ASSERT_EQ(tinyGrid().cellsPerLevel(), (std::vector<uint64_t>{3, 3}));
    edit(value("3 3"), value("2 4"));  // the same total, other levels
    EXPECT_EQ(hc::readGridInfo(path("lie.hcg")).summary.cellsPerLevel, (std::vector<uint64_t>{2, 4}));
    try {
        hc::verifyGridFile(path("lie.hcg"));
        FAIL() << "a lying summary passed verification";
    } catch (const hc::Error& e) {
        EXPECT_NE(std::string(e.what()).find("META summary"), std::string::npos) << e.what();
    }
    EXPECT_THROW(hc::readGrid(path("lie.hcg")), hc::Error);
    edit(value("3 3"), value("3 4"));  // 7 cells for the header's 6
    try {
        hc::readGridInfo(path("lie.hcg"));
        FAIL() << "a summary of 7 cells in a 6-cell file was accepted";
    } catch (const hc::Error& e) {
        EXPECT_NE(std::string(e.what()).find("META summary.cells_per_level does not fit the header's 6 cells"),
                  std::string::npos)
            << e.what();
    }
}

}  // namespace

// ---- water steps (format 1.3, docs/design.md section 6) ----

// tinyGrid's water as three steps: dry, the tiny grid's own water, and every cell wet. Velocity is a step layer.
struct Scenario {
    Grid shape;  // tinyGrid with a velocity layer; its step layers hold step 0
    std::vector<hc::WaterStepData> steps;
};
Scenario tinyScenario() {
    Scenario s;
    s.shape = tinyGrid();
    s.shape.layers.push_back({"velocity", "m/s"});
    s.shape.values.push_back(std::vector<float>(s.shape.cellCount(), 0.0f));
    hc::WaterStepData dry;
    dry.timeS = 0;
    dry.values.resize(2);
    hc::WaterStepData mid = hc::sparseStep(s.shape);
    mid.timeS = 1800;
    mid.values[1] = std::vector<float>(mid.wet.size(), 0.5f);
    hc::WaterStepData full;
    full.timeS = 5400.5;
    full.values.resize(2);
    for (uint32_t i = 0; i < s.shape.cellCount(); ++i) {
        full.wet.push_back(i);
        full.values[0].push_back(1.0f + float(i));
        full.values[1].push_back(-0.25f * float(i));  // a step layer may be negative
    }
    s.steps = {dry, mid, full};
    return s;
}

void writeScenario(const Scenario& s, const std::string& path) {
    hc::GridFileWriter w(path, s.shape, s.shape.cellCount(), s.steps.size());
    w.append(s.shape.codes, {std::span<const float>(s.shape.values[0])});
    for (const auto& step : s.steps) w.appendStep(step);
    w.commit(s.shape.stats);
}

// The scenario's grid with step k selected, built in memory (the reference for every read).
Grid scenarioAt(const Scenario& s, size_t k) {
    Grid g = s.shape;
    hc::selectStep(g, s.steps[k], k);
    return g;
}

TEST_F(GridFile, WaterStepsRoundTripStepByStep) {
    const Scenario s = tinyScenario();
    writeScenario(s, path("flood.hcg"));
    const hc::GridFileInfo info = hc::readGridInfo(path("flood.hcg"));
    ASSERT_EQ(info.shape.steps.size(), 3u);
    EXPECT_EQ(info.shape.layers.size(), 3u);
    EXPECT_EQ(info.shape.firstStepLayer(), 1u) << "water_depth and velocity are the step layers";
    const double times[3] = {0, 1800, 5400.5};
    const uint64_t wet[3] = {0, 4, 6};
    for (size_t k = 0; k < 3; ++k) {
        SCOPED_TRACE("step " + std::to_string(k));
        EXPECT_EQ(info.shape.steps[k].timeS, times[k]);
        EXPECT_EQ(info.shape.steps[k].wetCells, wet[k]);
        const Grid want = scenarioAt(s, k);
        const Grid got = hc::readGrid(path("flood.hcg"), nullptr, k);
        expectEqualGrids(want, got);
        EXPECT_EQ(got.step, k);
        EXPECT_EQ(got.contentHash(), info.shape.steps[k].contentHash) << "the stored hash is the step's grid's hash";
        // The summary of a step is that of the grid with it selected (dry cells read 0).
        const hc::GridFileInfo at = hc::readGridInfo(path("flood.hcg"), k);
        EXPECT_EQ(at.contentHash, want.contentHash());
        const hc::GridFileInfo verified = hc::verifyGridFile(path("flood.hcg"), k);
        EXPECT_EQ(verified.summary.layerMin, at.summary.layerMin);
        EXPECT_EQ(verified.summary.layerMax, at.summary.layerMax);
        // A region read carries the step's values too.
        const hc::GridRegionReader reader(path("flood.hcg"), k);
        const Grid region = reader.region({0, 0, reader.shape().domainSizeM(), reader.shape().domainSizeM()});
        ASSERT_EQ(region.codes, want.codes);
        for (size_t l = 0; l < want.layers.size(); ++l)
            EXPECT_EQ(region.values[l], want.values[l]) << want.layers[l].name;
    }
    // Steps differ, so do their hashes; the lists' key (the structure) does not.
    EXPECT_NE(info.shape.steps[1].contentHash, info.shape.steps[2].contentHash);
    EXPECT_EQ(scenarioAt(s, 0).structureHash(), scenarioAt(s, 2).structureHash());
    EXPECT_THROW(hc::readGrid(path("flood.hcg"), nullptr, 3), hc::Error);
    EXPECT_THROW(hc::GridRegionReader(path("flood.hcg"), 3), hc::Error);
}

TEST_F(GridFile, SwitchingStepsReadsThatStepOnly) {
    const Scenario s = tinyScenario();
    writeScenario(s, path("flood.hcg"));
    Grid g = hc::readGrid(path("flood.hcg"), nullptr, 0);
    for (size_t k : {2u, 1u, 0u, 2u}) {
        hc::readGridStep(path("flood.hcg"), g, k);
        expectEqualGrids(scenarioAt(s, k), g);
        EXPECT_EQ(g.step, k);
    }
    // A grid of another tree is refused, and left as it was.
    Grid other = tinyGrid();
    other.layers.push_back({"velocity", "m/s"});
    other.values.push_back(std::vector<float>(other.cellCount(), 0.0f));
    other.codes.pop_back();
    for (auto& v : other.values) v.pop_back();
    const Grid before = other;
    EXPECT_THROW(hc::readGridStep(path("flood.hcg"), other, 1), hc::Error);
    expectEqualGrids(before, other);
}

// Digests known from an earlier pass (staticDigestsOf) switch steps to the same grids without hashing the cells again;
// digests of another grid are refused like that grid, and the grid is left as it was.
TEST_F(GridFile, SwitchingStepsWithKnownDigests) {
    const Scenario s = tinyScenario();
    writeScenario(s, path("flood.hcg"));
    Grid g = hc::readGrid(path("flood.hcg"), nullptr, 0);
    const hc::StaticDigests known = hc::staticDigestsOf(g);
    EXPECT_EQ(known.structureHash, g.structureHash());
    for (size_t k : {2u, 1u, 0u, 2u}) {
        hc::readGridStep(path("flood.hcg"), g, k, &known);
        expectEqualGrids(scenarioAt(s, k), g);
        EXPECT_EQ(g.contentHash(), g.steps[k].contentHash)
            << "the table's hash is the grid's: what a Scene may be given";
    }
    hc::StaticDigests wrong = known;
    ++wrong.structureHash;
    const Grid before = g;
    EXPECT_THROW(hc::readGridStep(path("flood.hcg"), g, 1, &wrong), hc::Error);
    wrong = known;
    wrong.layers.at(0).second ^= 1;  // the elevation's digest of other values
    EXPECT_THROW(hc::readGridStep(path("flood.hcg"), g, 1, &wrong), hc::Error);
    expectEqualGrids(before, g);
}

// Rendering step k reads step k: a damaged section of another step goes unnoticed by readGrid(k) (it is never read)
// and is caught by every read of that step and by a full verification.
TEST_F(GridFile, StepsAreReadLazilyAndCheckedWhenRead) {
    const Scenario s = tinyScenario();
    writeScenario(s, path("flood.hcg"));
    std::vector<char> bytes = readBytes(path("flood.hcg"));
    // Find step 2's section in the table (kind 5, index 2) and flip a byte of its depths.
    uint32_t count;
    std::memcpy(&count, bytes.data() + 60, 4);
    uint64_t offset = 0;
    for (uint32_t e = 0; e < count; ++e) {
        uint32_t kind, index;
        std::memcpy(&kind, bytes.data() + 128 + 32 * e, 4);
        std::memcpy(&index, bytes.data() + 132 + 32 * e, 4);
        if (kind == 5 && index == 2) std::memcpy(&offset, bytes.data() + 136 + 32 * e, 8);
    }
    ASSERT_NE(offset, 0u);
    bytes[offset + 4 * 6 + 1] ^= 0x40;  // a depth of step 2's first wet cell
    writeBytes(path("bad.hcg"), bytes, bytes.size());
    expectEqualGrids(scenarioAt(s, 1), hc::readGrid(path("bad.hcg"), nullptr, 1));
    const std::string where = "at byte offset " + std::to_string(offset);
    for (auto read : std::vector<std::function<void()>>{[&] { hc::readGrid(path("bad.hcg"), nullptr, 2); },
                                                        [&] { hc::verifyGridFile(path("bad.hcg"), 0); },
                                                        [&] {
                                                            Grid g = hc::readGrid(path("bad.hcg"));
                                                            hc::readGridStep(path("bad.hcg"), g, 2);
                                                        },
                                                        [&] {
                                                            const hc::GridRegionReader r(path("bad.hcg"), 2);
                                                            r.region({0, 0, 10, 10});
                                                        }}) {
        try {
            read();
            ADD_FAILURE() << "a damaged step was read";
        } catch (const hc::Error& e) {
            EXPECT_NE(std::string(e.what()).find(where), std::string::npos) << e.what();
        }
    }
    // The same damage behind rewritten checksums (a writer's bug, not the disk's): the content checks catch it.
    fixAllChecksums(bytes);
    writeBytes(path("bad2.hcg"), bytes, bytes.size());
    EXPECT_THROW(hc::readGrid(path("bad2.hcg"), nullptr, 2), hc::Error);
    EXPECT_THROW(hc::verifyGridFile(path("bad2.hcg"), 0), hc::Error);
}

// Writing by parts (under mpirun each rank writes its own run of cells into rank 0's file, docs/design.md section 7),
// run here in one process: rank 0's writer appends cells [0, a), two parts write [a, b) and [b, n) straight into its
// temporary (the second before the first, as ranks race), checking and summarising them as they go, then hash them in
// turn, read back from the file, from the state the run before left. The file must be the very bytes writeGrid()
// writes: cuts inside checksum blocks, a second static layer, 300 k cells over three 1 MiB blocks of CELLS.
namespace {

Grid twoLayerThreeBlockGrid() {
    Grid g = threeBlockGrid();
    g.layers.push_back({"roughness", "m"});
    g.values.emplace_back();
    for (size_t i = 0; i < g.cellCount(); ++i) g.values[1].push_back(static_cast<float>(i % 13) * 0.01f);
    return g;
}

std::vector<std::span<const float>> valuesOf(const Grid& g, size_t i, size_t n) {
    std::vector<std::span<const float>> out;
    for (const auto& v : g.values) out.emplace_back(std::span<const float>(v).subspan(i, n));
    return out;
}

}  // namespace

TEST_F(GridFile, WritingByPartsEqualsWholeWrite) {
    const Grid g = twoLayerThreeBlockGrid();
    ASSERT_EQ(g.validate(), "");
    hc::writeGrid(g, path("whole.hcg"));
    const size_t n = g.cellCount();
    for (auto [a, b] : {std::pair<size_t, size_t>{70001, 200003}, {0, 131072}, {n / 2, n}, {1, 2}}) {
        SCOPED_TRACE(std::to_string(a) + ", " + std::to_string(b));
        hc::GridFileWriter w(path("parts.hcg"), g, n, 0);
        w.append(std::span(g.codes).first(a), valuesOf(g, 0, a));
        const std::vector<std::byte> where = w.placement();
        hc::GridFilePart p1(where, g, a), p2(where, g, b);
        for (size_t i = b; i < n; i += 50000)
            p2.append(std::span(g.codes).subspan(i, std::min<size_t>(50000, n - i)),
                      valuesOf(g, i, std::min<size_t>(50000, n - i)));
        p1.append(std::span(g.codes).subspan(a, b - a), valuesOf(g, a, b - a));
        p1.resume(w.streamState());
        p1.follow();
        p2.resume(p1.state());
        p2.follow();
        w.addPart(p1.finish());
        w.addPart(p2.finish());
        w.commit(g.stats);
        EXPECT_EQ(readBytes(path("parts.hcg")), readBytes(path("whole.hcg")));
    }
    expectEqualGrids(g, hc::readGrid(path("parts.hcg")));
}

TEST_F(GridFile, WritingByPartsRefusesPartsOutOfTurnAndLeavesNothing) {
    const Grid g = twoLayerThreeBlockGrid();
    const size_t n = g.cellCount(), a = 1000, b = 150000;
    {
        hc::GridFileWriter w(path("t.hcg"), g, n, 0);
        w.append(std::span(g.codes).first(a), valuesOf(g, 0, a));
        const std::vector<std::byte> where = w.placement();
        hc::GridFilePart p1(where, g, a), p2(where, g, b);
        p1.append(std::span(g.codes).subspan(a, b - a), valuesOf(g, a, b - a));
        p2.append(std::span(g.codes).subspan(b, n - b), valuesOf(g, b, n - b));
        // A part must go on from the state of exactly the cells before it.
        EXPECT_THROW(p2.resume(w.streamState()), hc::Error);
        // A part finished, or passing its state on, before its cells were hashed is refused.
        EXPECT_THROW(p1.finish(), hc::Error);
        p1.resume(w.streamState());
        EXPECT_THROW(p1.state(), hc::Error);
        // Cells out of order within a part are refused as they are appended.
        hc::GridFilePart p3(where, g, b);
        const uint64_t backwards[2] = {g.codes[b + 1], g.codes[b]};
        const float zeros[2] = {0, 0};
        EXPECT_THROW(p3.append(backwards, {std::span<const float>(zeros), std::span<const float>(zeros)}), hc::Error);
        // A part whose first cell overlaps the last cell before it (the writer's cell a - 1 again) is refused at the
        // seam.
        hc::GridFilePart seam(where, g, a);
        seam.append(std::span(g.codes).subspan(a - 1, 2), valuesOf(g, a - 1, 2));
        EXPECT_THROW(seam.resume(w.streamState()), hc::Error);
    }
    EXPECT_TRUE(fs::is_empty(dir_)) << "an abandoned write by parts left a file or temporary behind";
    {
        hc::GridFileWriter w(path("t.hcg"), g, n, 0);
        w.append(std::span(g.codes).first(a), valuesOf(g, 0, a));
        const std::vector<std::byte> where = w.placement();
        hc::GridFilePart p1(where, g, a), p2(where, g, b);
        p1.append(std::span(g.codes).subspan(a, b - a), valuesOf(g, a, b - a));
        p2.append(std::span(g.codes).subspan(b, n - b), valuesOf(g, b, n - b));
        p1.resume(w.streamState());
        p1.follow();
        p2.resume(p1.state());
        p2.follow();
        const std::vector<std::byte> r1 = p1.finish(), r2 = p2.finish();
        EXPECT_THROW(w.addPart(r2), hc::Error);      // out of turn: the writer needs cell a next
        EXPECT_THROW(w.commit(g.stats), hc::Error);  // cells missing
        // A state from another grid (one layer fewer) is refused.
        hc::GridFilePart other(where, g, a);
        EXPECT_THROW(other.resume(std::vector<std::byte>(64)), hc::Error);
    }
    EXPECT_TRUE(fs::is_empty(dir_)) << "an abandoned write by parts left a file or temporary behind";
    // A part cannot write into a temporary that is gone.
    std::vector<std::byte> stale;
    {
        hc::GridFileWriter w(path("t.hcg"), g, n, 0);
        stale = w.placement();
    }
    EXPECT_THROW(hc::GridFilePart(stale, g, 0), hc::Error);
}
