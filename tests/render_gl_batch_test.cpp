// The GL backend's batch output (issue 44): the picture read back alone (GlRenderer::ReadBack::PictureOnly) is the
// picture of the whole read-back, and one renderer handed another scene (GlRenderer::setScene, a sequence's water
// steps) draws what a renderer made for that scene draws. Headless as render_gl_test.cpp (HC_GL_TESTS=skip where no
// OpenGL 4.3 is expected).
#include "render_gl_world.h"

namespace {

using namespace hc::render;
using namespace hc::test::gl;

// The picture alone: the same bytes as the picture of every layer read back, and no other layer filled.
TEST_F(RenderGl, PictureOnlyIsTheWholeReadBacksPicture) {
    World& w = hef();
    HC_REQUIRE_GL(w);
    for (const Camera& cam : {overviewCamera(*w.scene, 241, 157), lowOblique(*w.scene, 160, 90)}) {
        Timings all, picture;
        w.gl->forgetCascades();
        const Frame f = w.gl->render(cam, smallOptions(), all);
        w.gl->forgetCascades();
        const Frame p = w.gl->render(cam, smallOptions(), picture, GlRenderer::ReadBack::PictureOnly);
        ASSERT_EQ(p.width, f.width);
        ASSERT_EQ(p.height, f.height);
        EXPECT_TRUE(p.rgb == f.rgb) << "the picture differs from the whole read-back's";
        EXPECT_TRUE(p.distanceM.empty() && p.posZ.empty() && p.wall.empty() && p.waterDepthM.empty());
        EXPECT_EQ(picture.hits, all.hits);  // the counters still come back
        EXPECT_GT(picture.readbackMs, 0.0);
    }
}

// One renderer, its scene switched between two grids in memory (their cells uploaded again) and back: each frame the
// bytes a renderer made for that scene draws, with nothing kept from the other (cascades, cells).
TEST_F(RenderGl, SetSceneDrawsAsARendererMadeForIt) {
    World& a = hef();
    World& b = lidar();
    HC_REQUIRE_GL(a);
    HC_REQUIRE_GL(b);
    const std::unique_ptr<GlRenderer> gl = GlRenderer::headless(*a.scene);
    for (World* w : {&b, &a, &b}) {
        gl->setScene(*w->scene);
        const Camera cam = overviewCamera(*w->scene, 160, 100);
        Timings t1, t2;
        w->gl->forgetCascades();
        const Frame want = w->gl->render(cam, smallOptions(), t1);
        const Frame got = gl->render(cam, smallOptions(), t2);
        EXPECT_TRUE(got.rgb == want.rgb);
        EXPECT_TRUE(got.distanceM == want.distanceM);
        EXPECT_EQ(t2.hits, t1.hits);
    }
}

// A scene of the other kind (out of core, for a renderer made for one in memory) is refused, saying which.
TEST_F(RenderGl, SetSceneRefusesTheOtherKind) {
    World& w = hef();
    HC_REQUIRE_GL(w);
    const std::filesystem::path path = dir_ / "g.hcg";
    hc::writeGrid(w.grid, path.string());
    const hc::GridRegionReader file(path.string());
    const Scene outOfCore(file, {});
    const std::unique_ptr<GlRenderer> gl = GlRenderer::headless(*w.scene);
    try {
        gl->setScene(outOfCore);
        FAIL() << "an out-of-core scene was taken by a renderer made for one in memory";
    } catch (const hc::Error& e) {
        EXPECT_NE(std::string(e.what()).find("made for a scene in memory and cannot take one read out of core"),
                  std::string::npos)
            << e.what();
    }
}

}  // namespace
