// The error bound on the GL backend against the CPU's (docs/tools/hc-render.md, "Error budget"): under a budget in
// memory, where the shaders sum every texel from the kernels, and without a pyramid, where the bound comes from the
// texels (mipmap.comp's estimate against Heightfield::errorEstimateM). Headless as render_gl_test.cpp (HC_GL_TESTS=skip
// where no OpenGL 4.3 is expected).
#include "render_gl_world.h"

namespace {

using namespace hc::render;
using namespace hc::test::gl;

// The error budget on the GL backend in memory, where every texel is summed from the kernels (off the pyramid's
// ladder): every checked hit lies under the frame's bound, the bound within the budget where the texels met it, a
// looser budget costs fewer texels, and where the budget (not the texels, N a side here against the CPU's 2N) sets the
// spacing it is the CPU's. (Before, the GL backend in memory ignored the budget: every budget gave the default's
// texels.) On the alpine SRTM (32 m cells) the budgets below 14 m need the finest level, which N texels cannot cover.
TEST_F(RenderGl, ErrorBudgetHoldsInMemory) {
    World& w = hef();
    HC_REQUIRE_GL(w);
    const hc::influence::SurfacePyramid pyramid = hc::influence::buildSurfacePyramid(w.grid, w.lists.params());
    const Scene scene(w.grid, w.lists, &pyramid);
    const std::unique_ptr<GlRenderer> gl = GlRenderer::headless(scene);
    const Camera cam = overviewCamera(scene, 160, 100);
    RenderOptions o = smallOptions();
    std::vector<uint64_t> texels;
    for (const double budget : {1.0, 30.0, 100.0}) {
        SCOPED_TRACE("budget " + std::to_string(budget) + " m");
        o.maxErrorM = budget;
        Timings t, cpu;
        gl->forgetCascades();
        const Frame f = gl->render(cam, o, t);
        const ErrorCheck check = verifyFrameError(scene, cam, f, 2000);
        ASSERT_TRUE(std::isfinite(t.errorBoundM));
        ASSERT_GT(check.hits, 1000u);
        EXPECT_LE(check.maxM, t.errorBoundM + 5e-3);  // + float32 hit positions, as render_error_budget_test
        // The shoreline too (shore.comp's texels): the exact shore within the bound of every hit on its wrong side.
        std::printf(
            "budget %g m: %llu hits on the wrong side of the shore, the exact one at most %.1f m away, bound %.1f m\n",
            budget, (unsigned long long)(check.drawnDryOverWater + check.drawnWetOverDry), check.shoreDistanceM,
            t.shoreBoundM);
        EXPECT_GT(t.shoreBoundM, 0.0);
        EXPECT_LE(check.shoreDistanceM, t.shoreBoundM * kShoreRingStep);
        (void)renderFrame(scene, cam, o, cpu);
        // Where the budget can be met the cascades are the CPU's, merged alike (fitCascades); below, GL's 8-step
        // ladder and the CPU's pyramid spacings may merge differently.
        if (budget > 14) {
            ASSERT_EQ(t.cascades.size(), cpu.cascades.size());
        }
        bool met = true;
        texels.push_back(0);
        for (size_t k = 0; k < t.cascades.size(); ++k) {
            const CascadeStats& c = t.cascades[k];
            met = met && c.errorBoundM <= c.budgetM, texels.back() += c.visibleTexels;
            if (budget > 14) {
                EXPECT_EQ(c.texelM, cpu.cascades[k].texelM) << k;
            }
        }
        if (met) {
            EXPECT_LE(t.errorBoundM, budget);
        }
    }
    EXPECT_GE(texels[0], texels[1]);
    EXPECT_GT(texels[1], texels[2]);
}

// Without a pyramid the GL backend estimates the bound from its texels as the CPU does (mipmap.comp against
// Heightfield::errorEstimateM, on the flooded alpine DEM: terrain and water surface), and the bound holds, the
// shoreline's too.
TEST_F(RenderGl, BoundWithoutAPyramidAsOnTheCpu) {
    World& w = hef();
    HC_REQUIRE_GL(w);
    const Scene& scene = *w.scene;
    for (const Camera& cam : {overviewCamera(scene, 160, 100), lowOblique(scene, 160, 100)}) {
        Timings t, cpu;
        w.gl->forgetCascades();
        const Frame f = w.gl->render(cam, smallOptions(), t);
        (void)renderFrame(scene, cam, smallOptions(), cpu);
        ASSERT_TRUE(std::isfinite(t.errorBoundM));
        EXPECT_TRUE(t.boundFromTexels);
        ASSERT_EQ(t.cascades.size(), cpu.cascades.size());
        for (size_t k = 0; k < t.cascades.size(); ++k) {
            // Texels summed in float on either side lie within kSummedTexelErrorM of the exact surface: the estimate's
            // second differences (three texels, weights 1, 2, 1, halved, two axes) within 4 of it.
            EXPECT_NEAR(t.cascades[k].texelEstimateM, cpu.cascades[k].texelEstimateM,
                        4 * hc::render::kSummedTexelErrorM)
                << k;
            EXPECT_GT(t.cascades[k].texelEstimateM, 0.0) << k;
        }
        const ErrorCheck check = verifyFrameError(scene, cam, f, 2000);
        ASSERT_GT(check.hits, 1000u);
        EXPECT_LE(check.maxM, t.errorBoundM + 5e-3);  // + float32 hit positions, as render_error_budget_test
        EXPECT_LE(check.shoreDistanceM, t.shoreBoundM * kShoreRingStep);
    }
}

// The pixel bound is charged at each cascade's nearest hit on GL as on the CPU (error_bound.cpp): shade.comp's counter
// is the read-back frame's own nearest hit of each cascade, bit for bit, and the verified error in pixels lies under
// the bound (plus the float32 rounding of a hit's height, in pixels at the frame's nearest hit).
TEST_F(RenderGl, NearestHitsAreTheFramesOwn) {
    World& w = hef();
    HC_REQUIRE_GL(w);
    const Scene& scene = *w.scene;
    for (const Camera& cam : {overviewCamera(scene, 160, 100), lowOblique(scene, 160, 100)}) {
        Timings t;
        w.gl->forgetCascades();
        const Frame f = w.gl->render(cam, smallOptions(), t);
        Timings measured = t;  // the CPU's scan of the read-back frame (detail::measureNearestHits)
        detail::measureNearestHits(f, 0, measured);
        ASSERT_FALSE(t.cascades.empty());
        double frameNearest = HUGE_VAL;
        for (size_t k = 0; k < t.cascades.size(); ++k) {
            EXPECT_EQ(t.cascades[k].nearestHitM, measured.cascades[k].nearestHitM) << k;
            frameNearest = std::min(frameNearest, measured.cascades[k].nearestHitM);
        }
        const ErrorCheck check = verifyFrameError(scene, cam, f, 2000);
        ASSERT_GT(check.hits, 1000u);
        const double pixelRad = detail::setUpFrame(scene, cam).view.pixelRad;
        EXPECT_LE(check.maxPx, t.errorBoundPx + 5e-3 / (pixelRad * frameNearest));
    }
}

}  // namespace
