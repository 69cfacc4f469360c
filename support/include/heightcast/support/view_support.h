// heightcast/support/view_support.h: hc-view's pieces that need no window (and so are unit-tested): camera bookmarks
// as JSON, camera motions (fly, look, orbit), and text drawn with a built-in 5x7 bitmap font into an
// RGBA overlay.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "heightcast/render/camera.h"

namespace hc::view {

// ------------------------------------------------------------------------------------------- bookmarks
// A saved view: position in the grid's CRS [m], yaw, pitch and vertical field of view [degrees].
struct Bookmark {
    double x = 0, y = 0, z = 0, yawDeg = 0, pitchDeg = 0, fovYDeg = 50;
};
// Slots 1..9 (index 0 unused).
using Bookmarks = std::array<std::optional<Bookmark>, 10>;

// GRID.hcg -> GRID.bookmarks.json (beside the grid); any other name gets .bookmarks.json appended.
std::string bookmarksPath(const std::string& gridPath);
// {"format": "heightcast-bookmarks", "version": 1, "bookmarks": [{"slot": 1, "x": ..., "y": ..., "z": ...,
//  "yaw": ..., "pitch": ..., "fov": ...}, ...]}, indented by 2; doubles in the fewest digits that read back exactly.
std::string bookmarksToJson(const Bookmarks& b);
// Strict (read with nlohmann-json, no comments): throws hc::Error saying what is wrong (syntax with the byte
// offset, nesting deeper than 8, a missing or non-finite field, a slot outside 1..9 or given twice, fov outside
// (0, 179], pitch outside [-90, 90]). Of a key given twice in one object, the last counts.
Bookmarks bookmarksFromJson(std::string_view text);
// A missing file gives no bookmarks; a broken one throws hc::Error naming the file.
Bookmarks readBookmarks(const std::string& path);
// Atomically (hc::AtomicFileWriter). Throws hc::Error.
void writeBookmarks(const std::string& path, const Bookmarks& b);

Bookmark toBookmark(const render::Camera& c);
void applyBookmark(const Bookmark& b, render::Camera& c);  // keeps c's size

// -------------------------------------------------------------------------------------- camera motion
// Moves along the camera's forward / right axes and the world's up axis [m].
void fly(render::Camera& c, double forwardM, double rightM, double upM);
// Turns the camera: yaw to the right and pitch up [degrees]; pitch stays within [-89, 89].
void look(render::Camera& c, double dYawDeg, double dPitchDeg);
// Orbits around `pivot` (world [m]): the camera keeps its distance to the pivot, turns by dYaw and
// dPitch and ends looking at it (pitch within [-89, 89]).
void orbit(render::Camera& c, const std::array<double, 3>& pivot, double dYawDeg, double dPitchDeg);

// ------------------------------------------------------------------------------------------------ text
// An RGBA8 image, row 0 at the top, straight (not premultiplied) alpha.
struct Overlay {
    int width = 0, height = 0;
    std::vector<uint8_t> rgba;
    void resize(int w, int h);
    void clear();
    void fillRect(int x, int y, int w, int h, uint32_t rgba8);  // 0xRRGGBBAA, clipped
};
// Glyph cell: 5x7 pixels plus one column and two rows of spacing (where descenders reach), times `scale`.
constexpr int kGlyphW = 6, kGlyphH = 9;
// Draws printable ASCII (others as '?'); returns the x after the text. Newlines start a new line.
int drawText(Overlay& o, int x, int y, std::string_view text, uint32_t rgba8, int scale);
// The 7 rows (5 low bits, bit 4 = leftmost pixel) of a printable ASCII character; '?' for others.
const uint8_t* glyph(char c);
// Whether the glyph is drawn two rows lower (g p q y: their 7 rows are body and descender).
bool descends(char c);

}  // namespace hc::view
