// apps/view/hud.h: what hc-view writes over the image: the HUD (grid, backend, frame rate and stage times,
// camera, height above ground, switches), a short-lived message ("flash") and the help; and screenshots of the
// window. Rasterised with view_support's bitmap font into an RGBA overlay; the viewer uploads and draws it.
#pragma once

#include <optional>
#include <string>

#include "view/window.h"
#include "heightcast/support/view_support.h"
#include "heightcast/core/timer.h"
#include "heightcast/render/camera.h"
#include "heightcast/render/renderer.h"

namespace hc::view {

// The viewer's switches (keys F, C, K, H, U).
struct Toggles {
    bool water = true, cells = false, cascadeTint = false, help = false, hud = true;
};

// What the HUD reports; filled by the viewer for each draw.
struct HudStatus {
    std::string gridPath, backendName, backendDevice;
    std::string backendNote;  // the backend choice's note, "" when none
    std::string contextInfo;  // the window's GL context, shown when it is not the backend's device
    double framesPerSecond = 0;
    int frameWidth = 0, frameHeight = 0;  // of the image on screen [pixels]
    bool frameFull = false;               // false: a reduced frame while moving
    render::Timings timings;              // of the image on screen
    render::Camera camera;
    std::optional<double> heightAboveGroundM;  // empty outside the grid: then aboveHighestM is shown
    double aboveHighestM = 0;
    double speedMps = 0;
    Toggles toggles;
    std::string stepLine;  // the water step, its time and playback; "" without steps
};

class Hud {
public:
    // Shows `text` under the HUD for 4 s.
    void flash(const std::string& text);
    // Rasterises the HUD (when toggles.hud) and the help (when toggles.help) for a framebuffer of fw x fh
    // pixels into overlay(); false when that would be the same as last time (nothing to upload).
    bool compose(const HudStatus& s, int fw, int fh);
    const Overlay& overlay() const { return overlay_; }

private:
    Overlay overlay_;
    std::string key_;  // the text overlay_ holds, to skip identical redraws
    std::string flash_;
    Stopwatch sinceFlash_;
};

// GRID.view001.png, GRID.view002.png, ... beside the grid (".hcg" dropped): the first name not taken.
std::string nextScreenshotPath(const std::string& gridPath);
// The window's contents (image and HUD, as drawn in the back buffer) as an sRGB PNG. Throws hc::Error.
void saveScreenshot(const Window& window, const std::string& path);

}  // namespace hc::view
