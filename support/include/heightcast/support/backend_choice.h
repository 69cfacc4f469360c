// heightcast/support/backend_choice.h: which backend renders, decided the same way in hc-render and hc-view.
//
// --backend cpu | gl | auto. auto takes the GL backend only on a GPU: on a software OpenGL (Mesa's llvmpipe) the CPU
// backend is faster per frame (docs/benchmarks.md), so auto renders on the CPU there and says why. gl fails
// with the reason when no OpenGL 4.3 context can be had, also in a build without the GL backend (-DHC_WITH_GL=OFF).
#pragma once

#include <string>

namespace hc::cli {

enum class Backend { Cpu, Gl, Auto };
// "cpu" | "gl" | "auto"; throws hc::Error naming the bad value.
Backend parseBackend(const std::string& name);
const char* backendName(Backend b);

// What the OpenGL on hand offers: `unavailable` says why there is no OpenGL 4.3 context ("" when there is one),
// `device` is its renderer and version ("llvmpipe (LLVM 15.0.6, 256 bits), OpenGL 4.5 (Core Profile) Mesa 22.3.6").
struct GlOnHand {
    std::string unavailable, device;
};
// Makes a headless context (EGL) and drops it again; in a build without the GL backend, unavailable says so.
GlOnHand probeHeadlessGl();

struct BackendDecision {
    bool useGl = false;
    std::string note;  // for stderr, "" when there is nothing to say: why not GL under auto, or that GL is software
};
// The rule above. Throws hc::Error("--backend gl: <why>") when gl was asked for and `gl.unavailable` is not empty.
BackendDecision decideBackend(Backend requested, const GlOnHand& gl);

}  // namespace hc::cli
