// apps/view/hud.cpp: the HUD, the help and screenshots (see hud.h).
#include "view/hud.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <utility>
#include <vector>

#include <fmt/format.h>

#include "heightcast/render/image_io.h"

namespace hc::view {
namespace {

// Every key and mouse control (input.cpp), shown with H.
const char* const kHelp =
    "hc-view controls\n"
    "\n"
    "W A S D / arrows   fly forward, left, back, right\n"
    "Q E                down, up\n"
    "Shift (held)       4x faster\n"
    "right drag         look around\n"
    "left drag          orbit around the point under the centre\n"
    "scroll             move forward / back (zoom)\n"
    "F                  water on/off\n"
    "C                  cell outlines on/off\n"
    "K                  cascade colouring on/off\n"
    "P                  screenshot (PNG beside the grid)\n"
    "1-9                go to bookmark\n"
    "Shift+1-9          save bookmark\n"
    "R                  back to the first view\n"
    "[ ]                previous / next water step\n"
    "Space              play / pause the water steps\n"
    "- +                playback slower / faster\n"
    "B N                error budget in pixels: tighter / looser\n"
    "M                  error budget off\n"
    "U                  HUD on/off\n"
    "H                  this help\n"
    "Esc                quit";

}  // namespace

void Hud::flash(const std::string& text) {
    flash_ = text;
    sinceFlash_.restart();
}

bool Hud::compose(const HudStatus& s, int fw, int fh) {
    const int scale = fw >= 1200 ? 2 : 1;
    const int lineH = kGlyphH * scale, pad = 4 * scale;
    const uint32_t kText = 0xF0F0F0FF, kDim = 0xB8C4D0FF, kWarn = 0xFFC850FF, kBox = 0x000000A0;
    const Toggles& t = s.toggles;
    std::vector<std::pair<std::string, uint32_t>> lines;
    if (t.hud) {
        lines.push_back(
            {fmt::format("hc-view  {}   backend {} ({})", s.gridPath, s.backendName, s.backendDevice), kText});
        if (!s.backendNote.empty()) lines.push_back({s.backendNote, kWarn});
        if (s.backendDevice != s.contextInfo) lines.push_back({"display: " + s.contextInfo, kDim});
        const render::Timings& ms = s.timings;
        lines.push_back({fmt::format("{:.1f} fps   frame {}x{}{}   total {:.1f} ms", s.framesPerSecond, s.frameWidth,
                                     s.frameHeight, s.frameFull ? "" : " (moving: reduced)", ms.totalMs),
                         kText});
        lines.push_back(
            {fmt::format("fitting {:.1f}  approximation {:.1f}  mipmaps {:.1f}  ray casting {:.1f}  shading {:.1f} ms",
                         ms.fittingMs, ms.approximationMs, ms.mipmapMs, ms.raycastMs, ms.shadingMs),
             kText});
        lines.push_back({(std::isfinite(ms.errorBoundM)
                              ? fmt::format("within {:.3g} m, {:.2g} px of the exact surface{}", ms.errorBoundM,
                                            ms.errorBoundPx, ms.boundFromTexels ? " (from the texels: no pyramid)" : "")
                              : std::string("accuracy: no bound claimed")) +
                             (ms.shoreBoundM > 0 ? fmt::format(", shore {:.3g} m", ms.shoreBoundM) : std::string()) +
                             (ms.maxErrorPx > 0 ? fmt::format("   budget {:g} px (B N, M off)", ms.maxErrorPx)
                                                : std::string("   no budget (B N set one)")),
                         kText});
        const render::Camera& c = s.camera;
        lines.push_back({fmt::format("camera {:.1f}, {:.1f}, {:.1f} m  yaw {:.1f}  pitch {:.1f}  fov {:.1f} deg",
                                     c.xWorld, c.yWorld, c.zWorld, c.yawDeg, c.pitchDeg, c.fovYDeg),
                         kText});
        lines.push_back({(s.heightAboveGroundM
                              ? fmt::format("height above ground {:.1f} m", *s.heightAboveGroundM)
                              : fmt::format("outside the grid, {:.1f} m above its highest point", s.aboveHighestM)) +
                             fmt::format("   speed {:.0f} m/s", s.speedMps),
                         kText});
        if (!s.stepLine.empty()) lines.push_back({s.stepLine, kText});
        lines.push_back({fmt::format("water {} (F)  cells {} (C)  cascades {} (K)  H help", t.water ? "on" : "off",
                                     t.cells ? "on" : "off", t.cascadeTint ? "on" : "off"),
                         kDim});
        if (!flash_.empty() && sinceFlash_.seconds() < 4) lines.push_back({flash_, kWarn});
    }
    std::string key = fmt::format("{}x{} {}|", fw, fh, t.help ? 1 : 0);
    for (const auto& l : lines) key += l.first + "\n";
    if (key == key_) return false;
    key_ = key;
    if (overlay_.width != fw || overlay_.height != fh)
        overlay_.resize(fw, fh);
    else
        overlay_.clear();
    int widest = 0;
    for (const auto& l : lines) widest = std::max(widest, int(l.first.size()));
    if (!lines.empty()) {
        overlay_.fillRect(0, 0, widest * kGlyphW * scale + 2 * pad, int(lines.size()) * lineH + 2 * pad, kBox);
        int y = pad;
        for (const auto& [text, colour] : lines) drawText(overlay_, pad, y, text, colour, scale), y += lineH;
    }
    if (t.help) {
        int rows = 1, cols = 0, col = 0;
        for (const char* p = kHelp; *p; ++p)
            if (*p == '\n')
                ++rows, col = 0;
            else
                cols = std::max(cols, ++col);
        const int w = cols * kGlyphW * scale + 4 * pad, h = rows * lineH + 4 * pad;
        const int x = (fw - w) / 2, y = (fh - h) / 2;
        overlay_.fillRect(x, y, w, h, 0x000000C8);
        drawText(overlay_, x + 2 * pad, y + 2 * pad, kHelp, kText, scale);
    }
    return true;
}

std::string nextScreenshotPath(const std::string& gridPath) {
    std::string base = gridPath;
    if (base.size() > 4 && base.compare(base.size() - 4, 4, ".hcg") == 0) base.resize(base.size() - 4);
    for (int i = 1;; ++i) {
        std::string p = fmt::format("{}.view{:03d}.png", base, i);
        if (std::FILE* f = std::fopen(p.c_str(), "rb"))
            std::fclose(f);
        else
            return p;
    }
}

void saveScreenshot(const Window& window, const std::string& path) { render::writePng(window.readBackBuffer(), path); }

}  // namespace hc::view
