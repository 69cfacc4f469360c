// The GL backend's batch output (issue 44): the picture read back alone (GlRenderer::ReadBack::PictureOnly) is the
// picture of the whole read-back, pictures in flight are the pictures read at once, and one renderer handed another
// scene (GlRenderer::setScene, a sequence's water steps) draws what a renderer made for that scene draws. Headless as
// render_gl_test.cpp (HC_GL_TESTS=skip where no OpenGL 4.3 is expected).
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

// Pictures in flight (submitPicture / collectPicture): collected in the order submitted, each the same bytes as the
// picture read back at once, whatever the size (the ring's buffers grow), with its own timings; a full ring and an
// empty one refuse; a scene handed over between a submit and its collect leaves the submitted picture as it was.
TEST_F(RenderGl, PicturesInFlightAreThePicturesReadAtOnce) {
    World& a = hef();
    World& b = lidar();
    HC_REQUIRE_GL(a);
    HC_REQUIRE_GL(b);
    const std::vector<Camera> cams{overviewCamera(*a.scene, 241, 157), lowOblique(*a.scene, 160, 90),
                                   overviewCamera(*a.scene, 320, 200), lowOblique(*a.scene, 97, 61),
                                   overviewCamera(*a.scene, 64, 48)};
    std::vector<Frame> want;
    std::vector<uint64_t> hits;
    for (const Camera& cam : cams) {
        Timings t;
        a.gl->forgetCascades();
        want.push_back(a.gl->render(cam, smallOptions(), t, GlRenderer::ReadBack::PictureOnly));
        hits.push_back(t.hits);
    }
    const std::unique_ptr<GlRenderer> gl = GlRenderer::headless(*a.scene);
    EXPECT_THROW(gl->collectPicture(), hc::Error);
    size_t next = 0;
    auto collect = [&] {
        const GlRenderer::Picture p = gl->collectPicture();
        ASSERT_LT(next, want.size());
        EXPECT_EQ(p.frame.width, want[next].width);
        EXPECT_EQ(p.frame.height, want[next].height);
        EXPECT_TRUE(p.frame.rgb == want[next].rgb) << "picture " << next << " differs from the one read at once";
        EXPECT_EQ(p.timings.hits, hits[next]);
        EXPECT_GT(p.timings.readbackMs, 0.0);
        ++next;
    };
    for (const Camera& cam : cams) {
        if (gl->picturesInFlight() == GlRenderer::kPicturesInFlight) {
            EXPECT_THROW(gl->submitPicture(cam, smallOptions()), hc::Error);
            collect();
        }
        gl->forgetCascades();
        gl->submitPicture(cam, smallOptions());
    }
    while (gl->picturesInFlight() > 0) collect();
    EXPECT_EQ(next, cams.size());
    // Another scene between a submit and its collect, and a picture read at once meanwhile.
    next = 0;
    gl->forgetCascades();
    gl->submitPicture(cams[0], smallOptions());
    gl->setScene(*b.scene);
    const Camera other = overviewCamera(*b.scene, 160, 100);
    Timings t1, t2;
    b.gl->forgetCascades();
    const Frame wantB = b.gl->render(other, smallOptions(), t1, GlRenderer::ReadBack::PictureOnly);
    const Frame gotB = gl->render(other, smallOptions(), t2, GlRenderer::ReadBack::PictureOnly);
    EXPECT_TRUE(gotB.rgb == wantB.rgb);
    collect();
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
