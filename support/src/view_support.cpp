#include "heightcast/support/view_support.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <span>
#include <sstream>

#include <nlohmann/json.hpp>

#include "heightcast/core/atomic_file.h"
#include "heightcast/core/error.h"

namespace hc::view {

// ------------------------------------------------------------------------------------------- bookmarks

std::string bookmarksPath(const std::string& gridPath) {
    std::filesystem::path p(gridPath);
    if (p.extension() == ".hcg") p.replace_extension();
    return p.string() + ".bookmarks.json";
}

namespace {

using Json = nlohmann::ordered_json;  // keys in the order written

// The deepest nesting a bookmarks file has is 2 (document, list, bookmark); anything past 8 is not one.
constexpr int kMaxDepth = 8;

// nlohmann's message without its "[json.exception.parse_error.101] " prefix.
std::string withoutPrefix(const char* what) {
    const std::string s = what;
    const size_t end = s.find("] ");
    return s.rfind("[json.exception.", 0) == 0 && end != std::string::npos ? s.substr(end + 2) : s;
}

// "at byte B: what went wrong (line L, column C)" from nlohmann's "parse error at line L, column C: what went wrong".
std::string syntaxError(const Json::parse_error& e) {
    std::string detail = withoutPrefix(e.what()), where;
    constexpr std::string_view kLead = "parse error at ";
    if (const size_t colon = detail.find(": "); detail.rfind(kLead, 0) == 0 && colon != std::string::npos) {
        where = " (" + detail.substr(kLead.size(), colon - kLead.size()) + ")";
        detail = detail.substr(colon + 2);
    }
    // A complete value followed by more text: said as plainly as the rest.
    if (detail.ends_with("; expected end of input")) detail = "unexpected text after the JSON value";
    return "at byte " + std::to_string(e.byte) + ": " + detail + where;
}

// Strict parsing: no comments, nesting past kMaxDepth refused, syntax errors with their byte offset (hc::Error).
Json parseDocument(std::string_view text) {
    const Json::parser_callback_t depthCheck = [](int depth, Json::parse_event_t, Json&) {
        if (depth > kMaxDepth) throw Error("nested too deeply (more than " + std::to_string(kMaxDepth) + " levels)");
        return true;
    };
    try {
        return Json::parse(text, depthCheck);
    } catch (const Json::parse_error& e) {
        throw Error(syntaxError(e));
    } catch (const Json::out_of_range& e) {  // a number beyond double's range, such as 1e999
        throw Error("a number is not finite (" + withoutPrefix(e.what()) + ")");
    }
}

const Json* member(const Json& o, const char* key) {
    const auto it = o.find(key);
    return it == o.end() ? nullptr : &*it;
}

}  // namespace

std::string bookmarksToJson(const Bookmarks& b) {
    Json doc;
    doc["format"] = "heightcast-bookmarks";
    doc["version"] = 1;
    doc["bookmarks"] = Json::array();
    for (int slot = 1; slot <= 9; ++slot) {
        if (!b[slot]) continue;
        const Bookmark& m = *b[slot];
        // nlohmann writes doubles with the shortest digits that read back to the same value: an exact round trip.
        doc["bookmarks"].push_back({{"slot", slot},
                                    {"x", m.x},
                                    {"y", m.y},
                                    {"z", m.z},
                                    {"yaw", m.yawDeg},
                                    {"pitch", m.pitchDeg},
                                    {"fov", m.fovYDeg}});
    }
    return doc.dump(2) + "\n";
}

Bookmarks bookmarksFromJson(std::string_view text) {
    const Json doc = parseDocument(text);
    if (!doc.is_object()) throw Error("the top level is not a JSON object");
    const Json* format = member(doc, "format");
    if (!format || !format->is_string() || format->get<std::string>() != "heightcast-bookmarks")
        throw Error("\"format\" is not \"heightcast-bookmarks\"");
    const Json* version = member(doc, "version");
    if (!version || !version->is_number() || version->get<double>() != 1) throw Error("\"version\" is not 1");
    const Json* list = member(doc, "bookmarks");
    if (!list || !list->is_array()) throw Error("\"bookmarks\" is missing or not an array");
    Bookmarks out;
    for (size_t i = 0; i < list->size(); ++i) {
        const Json& e = (*list)[i];
        const std::string where = "bookmark " + std::to_string(i + 1);
        if (!e.is_object()) throw Error(where + ": not an object");
        auto num = [&](const char* key) {
            const Json* v = member(e, key);
            if (!v || !v->is_number() || !std::isfinite(v->get<double>()))
                throw Error(where + ": \"" + key + "\" is missing or not a finite number");
            return v->get<double>();
        };
        const double slot = num("slot");
        if (slot != std::floor(slot) || slot < 1 || slot > 9)
            throw Error(where + ": slot " + std::to_string(slot) + " is outside 1..9");
        const int s = int(slot);
        if (out[s]) throw Error(where + ": slot " + std::to_string(s) + " given twice");
        Bookmark b{num("x"), num("y"), num("z"), num("yaw"), num("pitch"), num("fov")};
        if (!(b.fovYDeg > 0 && b.fovYDeg <= 179)) throw Error(where + ": fov is outside (0, 179] degrees");
        if (b.pitchDeg < -90 || b.pitchDeg > 90) throw Error(where + ": pitch is outside [-90, 90] degrees");
        out[s] = b;
    }
    return out;
}

Bookmarks readBookmarks(const std::string& path) {
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) return {};
    std::ifstream in(path, std::ios::binary);
    if (!in) throw Error(path + ": cannot open for reading");
    std::ostringstream ss;
    ss << in.rdbuf();
    try {
        return bookmarksFromJson(ss.str());
    } catch (const Error& e) {
        throw Error(path + ": " + e.what());
    }
}

void writeBookmarks(const std::string& path, const Bookmarks& b) {
    AtomicFileWriter w(path);
    const std::string j = bookmarksToJson(b);
    w.write(std::as_bytes(std::span(j)));
    w.commit();
}

Bookmark toBookmark(const render::Camera& c) { return {c.xWorld, c.yWorld, c.zWorld, c.yawDeg, c.pitchDeg, c.fovYDeg}; }

void applyBookmark(const Bookmark& b, render::Camera& c) {
    c.xWorld = b.x, c.yWorld = b.y, c.zWorld = b.z;
    c.yawDeg = b.yawDeg, c.pitchDeg = b.pitchDeg, c.fovYDeg = b.fovYDeg;
}

// -------------------------------------------------------------------------------------- camera motion

void fly(render::Camera& c, double forwardM, double rightM, double upM) {
    const render::CameraBasis b = render::basisOf(c);
    c.xWorld += b.forward[0] * forwardM + b.right[0] * rightM;
    c.yWorld += b.forward[1] * forwardM + b.right[1] * rightM;
    c.zWorld += b.forward[2] * forwardM + b.right[2] * rightM + upM;
}

void look(render::Camera& c, double dYawDeg, double dPitchDeg) {
    c.yawDeg = std::remainder(c.yawDeg + dYawDeg, 360.0);
    c.pitchDeg = std::clamp(c.pitchDeg + dPitchDeg, -89.0, 89.0);
}

void orbit(render::Camera& c, const std::array<double, 3>& pivot, double dYawDeg, double dPitchDeg) {
    const double dx = pivot[0] - c.xWorld, dy = pivot[1] - c.yWorld, dz = pivot[2] - c.zWorld;
    const double r = std::sqrt(dx * dx + dy * dy + dz * dz);
    if (!(r > 0)) return;
    const double kDeg = M_PI / 180;
    // The direction to the pivot as yaw/pitch, then turned.
    const double yaw = std::atan2(dx, dy) / kDeg + dYawDeg;
    const double pitch = std::clamp(std::asin(std::clamp(dz / r, -1.0, 1.0)) / kDeg + dPitchDeg, -89.0, 89.0);
    const double fx = std::sin(yaw * kDeg) * std::cos(pitch * kDeg), fy = std::cos(yaw * kDeg) * std::cos(pitch * kDeg),
                 fz = std::sin(pitch * kDeg);
    c.xWorld = pivot[0] - r * fx, c.yWorld = pivot[1] - r * fy, c.zWorld = pivot[2] - r * fz;
    c.yawDeg = std::remainder(yaw, 360.0);
    c.pitchDeg = pitch;
    c.rollDeg = 0;
}

// ------------------------------------------------------------------------------------------------ text

namespace {
// A 5x7 font for ASCII 32..126, drawn for this project: 7 rows per glyph, bit 4 = leftmost pixel. The
// descenders g p q y are drawn two rows lower (descends()), into the cell's spacing rows.
constexpr uint8_t kFont[95][7] = {
    {0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00}, {0x04, 0x04, 0x04, 0x04, 0x00, 0x00, 0x04},  //   !
    {0x0A, 0x0A, 0x0A, 0x00, 0x00, 0x00, 0x00}, {0x0A, 0x0A, 0x1F, 0x0A, 0x1F, 0x0A, 0x0A},  // " #
    {0x04, 0x0F, 0x14, 0x0E, 0x05, 0x1E, 0x04}, {0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03},  // $ %
    {0x0C, 0x12, 0x14, 0x08, 0x15, 0x12, 0x0D}, {0x0C, 0x04, 0x08, 0x00, 0x00, 0x00, 0x00},  // & '
    {0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02}, {0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08},  // ( )
    {0x00, 0x04, 0x15, 0x0E, 0x15, 0x04, 0x00}, {0x00, 0x04, 0x04, 0x1F, 0x04, 0x04, 0x00},  // * +
    {0x00, 0x00, 0x00, 0x00, 0x0C, 0x04, 0x08}, {0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00},  // , -
    {0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C}, {0x00, 0x01, 0x02, 0x04, 0x08, 0x10, 0x00},  // . /
    {0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E}, {0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E},  // 0 1
    {0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F}, {0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E},  // 2 3
    {0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02}, {0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E},  // 4 5
    {0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E}, {0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08},  // 6 7
    {0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E}, {0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C},  // 8 9
    {0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x0C, 0x00}, {0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x04, 0x08},  // : ;
    {0x02, 0x04, 0x08, 0x10, 0x08, 0x04, 0x02}, {0x00, 0x00, 0x1F, 0x00, 0x1F, 0x00, 0x00},  // < =
    {0x08, 0x04, 0x02, 0x01, 0x02, 0x04, 0x08}, {0x0E, 0x11, 0x01, 0x02, 0x04, 0x00, 0x04},  // > ?
    {0x0E, 0x11, 0x01, 0x0D, 0x15, 0x15, 0x0E}, {0x0E, 0x11, 0x11, 0x11, 0x1F, 0x11, 0x11},  // @ A
    {0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E}, {0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E},  // B C
    {0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C}, {0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F},  // D E
    {0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10}, {0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F},  // F G
    {0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11}, {0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E},  // H I
    {0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C}, {0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11},  // J K
    {0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F}, {0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11},  // L M
    {0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11}, {0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E},  // N O
    {0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10}, {0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D},  // P Q
    {0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11}, {0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E},  // R S
    {0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04}, {0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E},  // T U
    {0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04}, {0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A},  // V W
    {0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11}, {0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04},  // X Y
    {0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F}, {0x0E, 0x08, 0x08, 0x08, 0x08, 0x08, 0x0E},  // Z [
    {0x00, 0x10, 0x08, 0x04, 0x02, 0x01, 0x00}, {0x0E, 0x02, 0x02, 0x02, 0x02, 0x02, 0x0E},  // \ ]
    {0x04, 0x0A, 0x11, 0x00, 0x00, 0x00, 0x00}, {0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x1F},  // ^ _
    {0x08, 0x04, 0x02, 0x00, 0x00, 0x00, 0x00}, {0x00, 0x00, 0x0E, 0x01, 0x0F, 0x11, 0x0F},  // ` a
    {0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x1E}, {0x00, 0x00, 0x0E, 0x10, 0x10, 0x11, 0x0E},  // b c
    {0x01, 0x01, 0x0D, 0x13, 0x11, 0x11, 0x0F}, {0x00, 0x00, 0x0E, 0x11, 0x1F, 0x10, 0x0E},  // d e
    {0x06, 0x09, 0x08, 0x1C, 0x08, 0x08, 0x08}, {0x0F, 0x11, 0x11, 0x11, 0x0F, 0x01, 0x0E},  // f g
    {0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x11}, {0x04, 0x00, 0x0C, 0x04, 0x04, 0x04, 0x0E},  // h i
    {0x02, 0x00, 0x06, 0x02, 0x02, 0x12, 0x0C}, {0x10, 0x10, 0x12, 0x14, 0x18, 0x14, 0x12},  // j k
    {0x0C, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E}, {0x00, 0x00, 0x1A, 0x15, 0x15, 0x11, 0x11},  // l m
    {0x00, 0x00, 0x16, 0x19, 0x11, 0x11, 0x11}, {0x00, 0x00, 0x0E, 0x11, 0x11, 0x11, 0x0E},  // n o
    {0x1E, 0x11, 0x11, 0x11, 0x1E, 0x10, 0x10}, {0x0F, 0x11, 0x11, 0x11, 0x0F, 0x01, 0x01},  // p q
    {0x00, 0x00, 0x16, 0x19, 0x10, 0x10, 0x10}, {0x00, 0x00, 0x0E, 0x10, 0x0E, 0x01, 0x1E},  // r s
    {0x08, 0x08, 0x1C, 0x08, 0x08, 0x09, 0x06}, {0x00, 0x00, 0x11, 0x11, 0x11, 0x13, 0x0D},  // t u
    {0x00, 0x00, 0x11, 0x11, 0x11, 0x0A, 0x04}, {0x00, 0x00, 0x11, 0x11, 0x15, 0x15, 0x0A},  // v w
    {0x00, 0x00, 0x11, 0x0A, 0x04, 0x0A, 0x11}, {0x11, 0x11, 0x11, 0x11, 0x0F, 0x01, 0x0E},  // x y
    {0x00, 0x00, 0x1F, 0x02, 0x04, 0x08, 0x1F}, {0x02, 0x04, 0x04, 0x08, 0x04, 0x04, 0x02},  // z {
    {0x04, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04}, {0x08, 0x04, 0x04, 0x02, 0x04, 0x04, 0x08},  // | }
    {0x00, 0x00, 0x08, 0x15, 0x02, 0x00, 0x00},                                              // ~
};
}  // namespace

bool descends(char c) { return c == 'g' || c == 'p' || c == 'q' || c == 'y'; }

const uint8_t* glyph(char c) {
    const int i = static_cast<unsigned char>(c);
    return kFont[(i >= 32 && i <= 126 ? i : '?') - 32];
}

void Overlay::resize(int w, int h) {
    width = w, height = h;
    rgba.assign(size_t(w) * size_t(h) * 4, 0);
}

void Overlay::clear() { std::fill(rgba.begin(), rgba.end(), uint8_t{0}); }

void Overlay::fillRect(int x, int y, int w, int h, uint32_t c) {
    const int x0 = std::max(x, 0), y0 = std::max(y, 0), x1 = std::min(x + w, width), y1 = std::min(y + h, height);
    for (int yy = y0; yy < y1; ++yy)
        for (int xx = x0; xx < x1; ++xx) {
            uint8_t* p = &rgba[(size_t(yy) * size_t(width) + size_t(xx)) * 4];
            p[0] = uint8_t(c >> 24), p[1] = uint8_t(c >> 16), p[2] = uint8_t(c >> 8), p[3] = uint8_t(c);
        }
}

int drawText(Overlay& o, int x, int y, std::string_view text, uint32_t rgba8, int scale) {
    const int x0 = x;
    for (char ch : text) {
        if (ch == '\n') {
            x = x0, y += kGlyphH * scale;
            continue;
        }
        const uint8_t* g = glyph(ch);
        const int dy = descends(ch) ? 2 : 0;
        for (int r = 0; r < 7; ++r)
            for (int col = 0; col < 5; ++col)
                if (g[r] & (0x10 >> col)) o.fillRect(x + col * scale, y + (r + dy) * scale, scale, scale, rgba8);
        x += kGlyphW * scale;
    }
    return x;
}

}  // namespace hc::view
