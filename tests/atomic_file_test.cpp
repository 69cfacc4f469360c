// hc::AtomicFileWriter and hc::AtomicPath after a kill -9 (issue 11: "kill -9 during every write never leaves a
// partial file under the real name"). A killed writer's temporary stays on disk (nothing runs at SIGKILL); these
// tests pin what makes that harmless: the temporary is named TARGET.tmp.XXXXXX (never the target's extension at
// the end), the next write of the same target removes it, and a live writer's temporary (flocked) is kept.
// tests/cli/kill_during_write.sh kills the real tools.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cstddef>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <span>
#include <string>
#include <vector>

#include "heightcast/core/atomic_file.h"
#include "temp_dir.h"

namespace fs = std::filesystem;

namespace {

class AtomicFile : public hc::test::TempDirTest {
protected:
    AtomicFile() : TempDirTest("hc_atomic_file_") {}
};

std::vector<std::string> names(const fs::path& dir) {
    std::vector<std::string> out;
    for (const auto& e : fs::directory_iterator(dir)) out.push_back(e.path().filename().string());
    std::sort(out.begin(), out.end());
    return out;
}

// TARGET.tmp.XXXXXX with six letters or digits. (No std::regex: GCC 12 warns inside it under ASan at -O1.)
bool isTemporaryOf(const std::string& name, const std::string& target) {
    const std::string prefix = target + ".tmp.";
    if (name.size() != prefix.size() + 6 || name.compare(0, prefix.size(), prefix) != 0) return false;
    return std::all_of(name.begin() + static_cast<std::ptrdiff_t>(prefix.size()), name.end(),
                       [](char c) { return std::isalnum(static_cast<unsigned char>(c)) != 0; });
}

void writeText(const fs::path& p, const std::string& text) { std::ofstream(p) << text; }

TEST_F(AtomicFile, TemporaryNamesNeverEndInTheTargetsExtension) {
    const fs::path& d = dir_;
    hc::AtomicPath p((d / "out.png").string());
    EXPECT_TRUE(isTemporaryOf(fs::path(p.temp()).filename().string(), "out.png")) << p.temp();
    hc::AtomicFileWriter w((d / "out.png").string());
    for (const std::string& n : names(d)) EXPECT_TRUE(isTemporaryOf(n, "out.png")) << n;
    EXPECT_EQ(names(d).size(), 2u);
}

TEST_F(AtomicFile, NextWriteRemovesAKilledWritersTemporary) {
    const fs::path& d = dir_;
    // What a writer killed by SIGKILL leaves: a temporary nobody holds a lock on.
    writeText(d / "g.hcg.tmp.Ab12Cd", "half a grid");
    // Not ours to touch: other targets' temporaries, names that only look alike, the user's files.
    writeText(d / "h.hcg.tmp.Ab12Cd", "another target's");
    writeText(d / "g.hcg.tmp.Ab12Cd.bak", "the user's");
    writeText(d / "g.hcg.tmp.short", "the user's");
    {
        hc::AtomicFileWriter w((d / "g.hcg").string());
        const std::string bytes = "whole";
        w.write(std::as_bytes(std::span(bytes.data(), bytes.size())));
        w.commit();
    }
    EXPECT_EQ(names(d),
              (std::vector<std::string>{"g.hcg", "g.hcg.tmp.Ab12Cd.bak", "g.hcg.tmp.short", "h.hcg.tmp.Ab12Cd"}));

    writeText(d / "e.tif.tmp.Zz9Yy8", "half a GeoTIFF");
    { hc::AtomicPath p((d / "e.tif").string()); }  // destroyed without commit: its own temporary goes too
    EXPECT_FALSE(fs::exists(d / "e.tif.tmp.Zz9Yy8"));
    EXPECT_FALSE(fs::exists(d / "e.tif"));
}

TEST_F(AtomicFile, ALiveWritersTemporaryIsKept) {
    const fs::path& d = dir_;
    hc::AtomicFileWriter first((d / "g.hci").string());  // still writing: it holds its temporary's lock
    hc::AtomicPath second((d / "g.hci").string());       // a concurrent writer of the same target
    EXPECT_EQ(names(d).size(), 2u);
    const std::string bytes = "first";
    first.write(std::as_bytes(std::span(bytes.data(), bytes.size())));
    EXPECT_NO_THROW(first.commit());
    std::ifstream in(d / "g.hci");
    std::string got;
    in >> got;
    EXPECT_EQ(got, "first");
}

// writeRun: runs staged in 4 MiB buffers and written past the page cache (O_DIRECT) where the file system takes it,
// their unaligned heads and tails through the cache. Two runs interleaved, starting at unaligned offsets, in pieces of
// odd sizes that straddle the buffers, one run broken off and restarted, a plain writeAt between them: the file read
// back is every byte where it was put. In this fixture's directory (a disk's file system: the direct path) and in
// /dev/shm (tmpfs refuses O_DIRECT: the fallback through the cache).
void writeRunsAndReadBack(const std::string& target) {
    const size_t runA = 9 * 1024 * 1024 + 123, runB = 5 * 1024 * 1024 + 7;
    const uint64_t atA = 1000, atB = atA + runA + 5000;
    std::vector<std::byte> want(atB + runB + 3000, std::byte{0});
    for (size_t i = 0; i < want.size(); ++i) want[i] = static_cast<std::byte>((i * 2654435761u) >> 13);
    {
        hc::AtomicFileWriter w(target);
        w.writeAt(0, std::span(want).first(atA));
        size_t doneA = 0, doneB = 0, piece = 1;
        while (doneA < runA || doneB < runB) {
            piece = (piece * 7919 + 17) % 1500000 + 1;  // 1 byte .. 1.5 MB
            const size_t a = std::min(piece, runA - doneA), b = std::min(piece / 3 + 1, runB - doneB);
            w.writeRun(0, atA + doneA, std::span(want).subspan(atA + doneA, a));
            w.writeRun(1, atB + doneB, std::span(want).subspan(atB + doneB, b));
            doneA += a, doneB += b;
            if (doneA > runA / 2 && doneA - a <= runA / 2) w.flushRun(0);  // broken off mid-way: restarts unaligned
        }
        w.writeAt(atA + runA, std::span(want).subspan(atA + runA, atB - atA - runA));
        w.writeAt(atB + runB, std::span(want).subspan(atB + runB));
        w.commit();
    }
    std::ifstream in(target, std::ios::binary);
    std::vector<char> got((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    ASSERT_EQ(got.size(), want.size()) << target;
    size_t firstDiff = 0;
    while (firstDiff < got.size() && static_cast<std::byte>(got[firstDiff]) == want[firstDiff]) ++firstDiff;
    EXPECT_EQ(firstDiff, got.size()) << target << ": first wrong byte";
}

TEST_F(AtomicFile, RunsPastThePageCacheReadBackExactly) {
    writeRunsAndReadBack(path("runs.bin"));
    if (fs::is_directory("/dev/shm")) {
        const std::string shm = "/dev/shm/hc_atomic_runs_" + std::to_string(::getpid()) + ".bin";
        writeRunsAndReadBack(shm);
        fs::remove(shm);
    }
}

}  // namespace
