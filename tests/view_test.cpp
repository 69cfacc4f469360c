// hc-view's window-free pieces (support/view_support.h): bookmarks JSON round trip and validation, camera
// motions, the bitmap font.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "heightcast/core/error.h"
#include "heightcast/support/view_support.h"
#include "temp_dir.h"

using namespace hc::view;

namespace {

// The suite's fixture, named as the suite: in its tests `Bookmarks` is this class, hc::view::Bookmarks the slots.
class Bookmarks : public hc::test::TempDirTest {
protected:
    Bookmarks() : TempDirTest("hc_view_") {}
};

std::string errorOf(const std::string& json) {
    try {
        bookmarksFromJson(json);
    } catch (const hc::Error& e) {
        return e.what();
    }
    return "";
}

// In this namespace (not at global scope, where hc::view::Bookmarks is seen too) `Bookmarks` names the fixture.
TEST_F(Bookmarks, PathBesideTheGrid) {
    EXPECT_EQ(bookmarksPath("out/hef.hcg"), "out/hef.bookmarks.json");
    EXPECT_EQ(bookmarksPath("grid"), "grid.bookmarks.json");
}

TEST_F(Bookmarks, RoundTripIsExact) {
    hc::view::Bookmarks b;
    b[1] = Bookmark{633759.123456789, 5184153.987654321, 3210.5, 45.25, -20.125, 60};
    b[9] = Bookmark{-1e-300, 1e300, 0.1, -179.9, -90, 179};  // extremes that %.6g would lose
    b[4] = Bookmark{0.1 + 0.2, 1.0 / 3.0, 2.0 / 3.0, 0, 90, 1e-3};
    const hc::view::Bookmarks back = bookmarksFromJson(bookmarksToJson(b));
    for (int s = 0; s <= 9; ++s) {
        ASSERT_EQ(back[s].has_value(), b[s].has_value()) << "slot " << s;
        if (!b[s]) continue;
        EXPECT_EQ(back[s]->x, b[s]->x);
        EXPECT_EQ(back[s]->y, b[s]->y);
        EXPECT_EQ(back[s]->z, b[s]->z);
        EXPECT_EQ(back[s]->yawDeg, b[s]->yawDeg);
        EXPECT_EQ(back[s]->pitchDeg, b[s]->pitchDeg);
        EXPECT_EQ(back[s]->fovYDeg, b[s]->fovYDeg);
    }
    // No bookmarks: still a valid file.
    for (const auto& s : bookmarksFromJson(bookmarksToJson(hc::view::Bookmarks{}))) EXPECT_FALSE(s.has_value());
}

TEST_F(Bookmarks, FileRoundTripAndMissingFile) {
    const std::string dir = dir_.string();
    const std::string path = dir + "/g.bookmarks.json";
    std::filesystem::remove(path);
    for (const auto& s : readBookmarks(path)) EXPECT_FALSE(s.has_value());  // no file: no bookmarks, no error
    hc::view::Bookmarks b;
    b[3] = Bookmark{1, 2, 3, 4, 5, 6};
    writeBookmarks(path, b);
    const hc::view::Bookmarks back = readBookmarks(path);
    ASSERT_TRUE(back[3].has_value());
    EXPECT_EQ(back[3]->fovYDeg, 6);
    for (const auto& e : std::filesystem::directory_iterator(dir))  // the atomic write left no temporary
        EXPECT_EQ(e.path().filename().string().find(".tmp."), std::string::npos) << e.path();
}

TEST_F(Bookmarks, BrokenFilesAreRefusedSayingWhy) {
    const std::string head = R"({"format": "heightcast-bookmarks", "version": 1, "bookmarks": [)";
    const std::string ok = R"({"slot": 2, "x": 1, "y": 2, "z": 3, "yaw": 4, "pitch": -5, "fov": 50})";
    EXPECT_EQ(errorOf(head + ok + "]}"), "");
    EXPECT_NE(errorOf(""), "");
    EXPECT_NE(errorOf(head + ok).find("at byte"), std::string::npos);  // truncated
    EXPECT_NE(errorOf(head + ok + "]} x").find("after the JSON value"), std::string::npos);
    EXPECT_NE(errorOf("[]").find("not a JSON object"), std::string::npos);
    EXPECT_NE(errorOf(R"({"format": "other", "version": 1, "bookmarks": []})").find("format"), std::string::npos);
    EXPECT_NE(errorOf(R"({"format": "heightcast-bookmarks", "version": 2, "bookmarks": []})").find("version"),
              std::string::npos);
    EXPECT_NE(errorOf(R"({"format": "heightcast-bookmarks", "version": 1})").find("\"bookmarks\""), std::string::npos);
    EXPECT_NE(errorOf(head + R"({"slot": 0, "x": 1, "y": 2, "z": 3, "yaw": 4, "pitch": -5, "fov": 50}]})")
                  .find("outside 1..9"),
              std::string::npos);
    EXPECT_NE(errorOf(head + ok + "," + ok + "]}").find("given twice"), std::string::npos);
    EXPECT_NE(
        errorOf(head + R"({"slot": 2, "x": 1, "y": 2, "yaw": 4, "pitch": -5, "fov": 50}]})").find("\"z\" is missing"),
        std::string::npos);
    EXPECT_NE(
        errorOf(head + R"({"slot": 2, "x": "1", "y": 2, "z": 3, "yaw": 4, "pitch": -5, "fov": 50}]})").find("\"x\""),
        std::string::npos);
    EXPECT_NE(
        errorOf(head + R"({"slot": 2, "x": 1e999, "y": 2, "z": 3, "yaw": 4, "pitch": -5, "fov": 50}]})").find("finite"),
        std::string::npos);
    EXPECT_NE(errorOf(head + R"({"slot": 2, "x": 1, "y": 2, "z": 3, "yaw": 4, "pitch": -5, "fov": 180}]})").find("fov"),
              std::string::npos);
    EXPECT_NE(
        errorOf(head + R"({"slot": 2, "x": 1, "y": 2, "z": 3, "yaw": 4, "pitch": -95, "fov": 50}]})").find("pitch"),
        std::string::npos);
    // Every truncation of a valid file is refused (none crashes or reads past the end).
    const std::string full = bookmarksToJson(bookmarksFromJson(head + ok + "]}"));
    const size_t whole = full.find_last_of('}') + 1;  // what follows is whitespace
    for (size_t n = 0; n < whole; ++n) EXPECT_NE(errorOf(full.substr(0, n)), "") << "truncated at byte " << n;
}

}  // namespace

TEST(CameraMotion, OrbitKeepsTheDistanceAndLooksAtThePivot) {
    hc::render::Camera c;
    c.xWorld = 1000, c.yWorld = 2000, c.zWorld = 500, c.yawDeg = 30, c.pitchDeg = -25;
    const std::array<double, 3> pivot{1200, 2300, 100};
    const double r0 = std::hypot(pivot[0] - c.xWorld, pivot[1] - c.yWorld, pivot[2] - c.zWorld);
    for (double dy : {0.0, 40.0, -170.0})
        for (double dp : {0.0, 10.0, -30.0}) {
            hc::render::Camera o = c;
            orbit(o, pivot, dy, dp);
            const double r = std::hypot(pivot[0] - o.xWorld, pivot[1] - o.yWorld, pivot[2] - o.zWorld);
            EXPECT_NEAR(r, r0, 1e-6 * r0);
            const auto b = hc::render::basisOf(o);
            for (int k = 0; k < 3; ++k)
                EXPECT_NEAR(b.forward[k], (pivot[k] - std::array{o.xWorld, o.yWorld, o.zWorld}[k]) / r, 1e-9);
            EXPECT_GE(o.pitchDeg, -89);
            EXPECT_LE(o.pitchDeg, 89);
        }
}

TEST(CameraMotion, FlyAndLook) {
    hc::render::Camera c;
    c.yawDeg = 90, c.pitchDeg = 0;  // looking east
    fly(c, 10, 0, 0);
    EXPECT_NEAR(c.xWorld, 10, 1e-9);
    EXPECT_NEAR(c.yWorld, 0, 1e-9);
    fly(c, 0, 5, 2);  // right of east is south
    EXPECT_NEAR(c.yWorld, -5, 1e-9);
    EXPECT_NEAR(c.zWorld, 2, 1e-9);
    look(c, 280, -200);
    EXPECT_NEAR(c.yawDeg, 10, 1e-9);  // 370 wraps to 10
    EXPECT_EQ(c.pitchDeg, -89);
}

TEST(Font, TextLandsInItsCells) {
    Overlay o;
    o.resize(64, 20);
    const int end = drawText(o, 2, 3, "Hi!", 0xFF0000FF, 2);
    EXPECT_EQ(end, 2 + 3 * kGlyphW * 2);
    size_t lit = 0;
    for (int y = 0; y < o.height; ++y)
        for (int x = 0; x < o.width; ++x)
            if (o.rgba[(size_t(y) * 64 + x) * 4 + 3]) {
                ++lit;
                EXPECT_GE(x, 2);
                EXPECT_LT(x, end);
                EXPECT_GE(y, 3);
                EXPECT_LT(y, 3 + 7 * 2);
                EXPECT_EQ(o.rgba[(size_t(y) * 64 + x) * 4], 0xFF);
            }
    EXPECT_GT(lit, 20u);
    // Every printable character has a glyph (only the space is empty), and others draw as '?'.
    for (char c = 33; c < 127; ++c) {
        int bits = 0;
        for (int r = 0; r < 7; ++r) bits |= glyph(c)[r];
        EXPECT_NE(bits, 0) << c;
    }
    EXPECT_EQ(glyph('\x01'), glyph('?'));
}
