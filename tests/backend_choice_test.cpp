// The backend choice hc-render and hc-view share (support/backend_choice.h): every branch of its rule, from the
// GL on hand as the probe reports it; and the probe itself in a build without the GL backend.
#include <gtest/gtest.h>

#include <string>

#include "heightcast/support/backend_choice.h"
#include "heightcast/core/error.h"

using namespace hc::cli;

namespace {
const GlOnHand kGpu{"", "NVIDIA H100 80GB HBM3/PCIe/SSE2, OpenGL 4.6.0 NVIDIA 550.54.15"};
const GlOnHand kLlvmpipe{"", "llvmpipe (LLVM 15.0.6, 256 bits), OpenGL 4.5 (Core Profile) Mesa 22.3.6"};
const GlOnHand kNone{"no headless OpenGL 4.3 context (EGL_NOT_INITIALIZED)", ""};
}  // namespace

TEST(BackendChoice, Names) {
    EXPECT_EQ(parseBackend("gl"), Backend::Gl);
    EXPECT_EQ(parseBackend("cpu"), Backend::Cpu);
    EXPECT_EQ(parseBackend("auto"), Backend::Auto);
    EXPECT_STREQ(backendName(Backend::Gl), "gl");
    EXPECT_STREQ(backendName(Backend::Auto), "auto");
    try {
        parseBackend("vulkan");
        FAIL() << "vulkan accepted";
    } catch (const hc::Error& e) {
        EXPECT_STREQ(e.what(), "--backend vulkan: use cpu, gl or auto");
    }
}

TEST(BackendChoice, CpuIsCpuWhateverTheGl) {
    for (const GlOnHand& gl : {kGpu, kLlvmpipe, kNone}) {
        const BackendDecision d = decideBackend(Backend::Cpu, gl);
        EXPECT_FALSE(d.useGl);
        EXPECT_EQ(d.note, "");
    }
}

TEST(BackendChoice, AutoTakesGlOnAGpuOnly) {
    const BackendDecision gpu = decideBackend(Backend::Auto, kGpu);
    EXPECT_TRUE(gpu.useGl);
    EXPECT_EQ(gpu.note, "");
    // Software OpenGL is about twice as slow as the CPU backend: auto renders on the CPU and says why.
    const BackendDecision soft = decideBackend(Backend::Auto, kLlvmpipe);
    EXPECT_FALSE(soft.useGl);
    EXPECT_NE(soft.note.find("software rendering (llvmpipe (LLVM 15.0.6, 256 bits))"), std::string::npos) << soft.note;
    EXPECT_NE(soft.note.find("--backend gl forces it"), std::string::npos) << soft.note;
    const BackendDecision none = decideBackend(Backend::Auto, kNone);
    EXPECT_FALSE(none.useGl);
    EXPECT_NE(none.note.find("not available (" + kNone.unavailable + ")"), std::string::npos) << none.note;
}

TEST(BackendChoice, GlIsGlOrAnError) {
    EXPECT_TRUE(decideBackend(Backend::Gl, kGpu).useGl);
    EXPECT_EQ(decideBackend(Backend::Gl, kGpu).note, "");
    const BackendDecision soft = decideBackend(Backend::Gl, kLlvmpipe);
    EXPECT_TRUE(soft.useGl);
    EXPECT_NE(soft.note.find("--backend cpu is about twice as fast"), std::string::npos) << soft.note;
    try {
        decideBackend(Backend::Gl, kNone);
        FAIL() << "--backend gl without GL accepted";
    } catch (const hc::Error& e) {
        EXPECT_EQ(std::string(e.what()), "--backend gl: " + kNone.unavailable);
    }
}

// The probe on this machine: without the GL backend it always says the backend was built out; with it, it either
// finds a context (and names its device) or says why not, never both.
TEST(BackendChoice, ProbeOfThisBuild) {
    const GlOnHand gl = probeHeadlessGl();
#if HC_WITH_GL
    EXPECT_NE(gl.unavailable.empty(), gl.device.empty()) << gl.unavailable << " / " << gl.device;
#else
    EXPECT_NE(gl.unavailable.find("built without the OpenGL backend (-DHC_WITH_GL=OFF"), std::string::npos)
        << gl.unavailable;
    EXPECT_THROW(decideBackend(Backend::Gl, gl), hc::Error);
    EXPECT_FALSE(decideBackend(Backend::Auto, gl).useGl);
#endif
}
