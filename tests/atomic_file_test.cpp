// hc::AtomicFileWriter and hc::AtomicPath after a kill -9 (issue 11: "kill -9 during every write never leaves a
// partial file under the real name"). A killed writer's temporary stays on disk (nothing runs at SIGKILL); these
// tests pin what makes that harmless: the temporary is named TARGET.tmp.XXXXXX (never the target's extension at
// the end), the next write of the same target removes it, and a live writer's temporary (flocked) is kept.
// tests/cli/kill_during_write.sh kills the real tools.
#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <cstddef>
#include <filesystem>
#include <fstream>
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

}  // namespace
