#include "heightcast/support/backend_choice.h"

#include "heightcast/core/error.h"
#include "heightcast/render/gl/gl_renderer.h"

namespace hc::cli {

Backend parseBackend(const std::string& name) {
    if (name == "cpu") return Backend::Cpu;
    if (name == "gl") return Backend::Gl;
    if (name == "auto") return Backend::Auto;
    throw Error("--backend " + name + ": use cpu, gl or auto");
}

const char* backendName(Backend b) {
    switch (b) {
        case Backend::Cpu:
            return "cpu";
        case Backend::Gl:
            return "gl";
        case Backend::Auto:
            return "auto";
    }
    return "?";
}

GlOnHand probeHeadlessGl() {
    GlOnHand gl;
    gl.unavailable = render::headlessGlUnavailable(&gl.device);
    return gl;
}

BackendDecision decideBackend(Backend requested, const GlOnHand& gl) {
    BackendDecision d;
    if (requested == Backend::Cpu) return d;
    if (requested == Backend::Gl && !gl.unavailable.empty()) throw Error("--backend gl: " + gl.unavailable);
    const std::string renderer = gl.device.substr(0, gl.device.find(", OpenGL"));
    const bool software = gl.unavailable.empty() && render::isSoftwareRenderer(gl.device);
    if (requested == Backend::Gl) {
        d.useGl = true;
        // docs/testing.md: without a GPU the CPU backend is the fast one.
        if (software)
            d.note = "OpenGL here is software rendering (" + renderer + "); --backend cpu is about twice as fast";
    } else if (!gl.unavailable.empty()) {
        d.note = "the GL backend is not available (" + gl.unavailable + "): rendering on the CPU";
    } else if (software) {
        d.note = "OpenGL here is software rendering (" + renderer +
                 "): rendering on the CPU, which is faster (--backend gl forces it)";
    } else {
        d.useGl = true;
    }
    return d;
}

}  // namespace hc::cli
