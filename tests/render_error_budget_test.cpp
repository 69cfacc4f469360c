// The speed/accuracy knob (issue 43): RenderOptions::maxErrorM / maxErrorPx, the bound a frame reports
// (Timings::errorBoundM) and the error measured at its hits (verifyFrameError), on real DEMs with their surface
// pyramids: the bundled alpine SRTM flooded at 2600 m (water too) and a 1 m LiDAR tile of adaptive cells.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "heightcast/influence/pyramid.h"
#include "heightcast/render/cascades.h"
#include "heightcast/render/detail/frame.h"
#include "heightcast/render/renderer.h"
#include "render_world.h"

namespace hc::test {
namespace {

using render::Camera;
using render::ErrorCheck;
using render::RenderOptions;
using render::Scene;
using render::Timings;

// A hit's height is stored in float32 (Frame::posZ): its rounding at 4000 m is 0.24 mm; the issue allows 5 mm.
constexpr double kFloatPositionM = 5e-3;
// Hits checked a frame: enough for a largest error that is rarely beaten (the 99th percentile has 40 beyond it).
constexpr size_t kChecked = 4000;

struct Rendered {
    Timings timings;
    ErrorCheck check;
    uint64_t visibleTexels = 0;
};

Rendered renderChecked(const Scene& scene, const RenderOptions& o) {
    const Camera cam = render::overviewCamera(scene, 320, 200);
    Rendered r;
    const render::Frame f = render::renderFrame(scene, cam, o, r.timings);
    r.check = render::verifyFrameError(scene, cam, f, kChecked);
    for (const render::CascadeStats& c : r.timings.cascades) r.visibleTexels += c.visibleTexels;
    return r;
}

class ErrorBudget : public ::testing::TestWithParam<std::string> {
protected:
    World& world() { return GetParam() == "hef" ? hef() : lidar(); }
};

// Per level, the rendered error grows with the spacing (each level adds its parent errors), and every level of a
// pyramid has one.
TEST_P(ErrorBudget, LevelErrorsGrowWithTheSpacing) {
    World& w = world();
    const influence::SurfacePyramid pyramid = influence::buildSurfacePyramid(w.grid, w.lists.params());
    const Scene scene(w.grid, w.lists, &pyramid);
    const std::vector<double>& e = scene.levelErrorM();
    ASSERT_EQ(e.size(), pyramid.levels.size());
    for (size_t t = 0; t < e.size(); ++t) {
        EXPECT_GT(e[t], 0.0) << t;
        if (t > 0) {
            EXPECT_GE(e[t], e[t - 1]) << t;
        }
    }
    EXPECT_GT(e.back(), 10 * e.front());  // the top level carries far more than the finest
}

// Every frame's measured error lies under its bound: by default, under budgets from 1 cm to 10 m and under a budget in
// pixels; where every cascade met its budget the bound is within it; and a looser budget costs fewer texels.
TEST_P(ErrorBudget, VerifiedErrorLiesUnderTheBoundAndTheBudget) {
    World& w = world();
    const influence::SurfacePyramid pyramid = influence::buildSurfacePyramid(w.grid, w.lists.params());
    const Scene scene(w.grid, w.lists, &pyramid);
    RenderOptions o;
    o.legend = false;
    o.texelsPerSide = 256;
    uint64_t lastTexels = UINT64_MAX;
    for (const double budget : {0.0, 0.01, 0.1, 1.0, 10.0}) {
        o.maxErrorM = budget;
        const Rendered r = renderChecked(scene, o);
        SCOPED_TRACE("budget " + std::to_string(budget) + " m");
        ASSERT_TRUE(std::isfinite(r.timings.errorBoundM));
        ASSERT_GT(r.check.hits, kChecked / 2);
        EXPECT_LE(r.check.maxM, r.timings.errorBoundM + kFloatPositionM)
            << "median " << r.check.medianM << ", p99 " << r.check.p99M;
        bool met = true;
        for (const render::CascadeStats& c : r.timings.cascades) {
            EXPECT_EQ(c.budgetM, budget);
            met = met && (budget == 0 || c.errorBoundM <= c.budgetM);
        }
        if (budget > 0 && met) {
            EXPECT_LE(r.timings.errorBoundM, budget);
        }
        std::printf("%s, budget %g m: bound %.3g m, verified largest %.3g m, median %.3g m; %llu texels\n",
                    GetParam().c_str(), budget, r.timings.errorBoundM, r.check.maxM, r.check.medianM,
                    (unsigned long long)r.visibleTexels);
        if (budget > 0) {
            EXPECT_LE(r.visibleTexels, lastTexels);
            lastTexels = r.visibleTexels;
        }
    }
    o.maxErrorM = 0, o.maxErrorPx = 1;
    const Rendered px = renderChecked(scene, o);
    EXPECT_LE(px.check.maxM, px.timings.errorBoundM + kFloatPositionM);
    EXPECT_LE(px.check.maxPx, px.timings.errorBoundPx + 0.01);
    for (const render::CascadeStats& c : px.timings.cascades)
        if (c.errorBoundM <= c.budgetM) {
            EXPECT_LE(c.errorBoundPx, 1.0 + 1e-9);
        }
}

// The errors per region: over the whole domain exactly the whole pyramid's (bilinearErrorByLevelM), over any part of it
// no more at any level, and over some parts less (the regions differ: a view of one part is not charged with the
// roughest tile elsewhere).
TEST_P(ErrorBudget, RegionalErrorsAreTheWholeOnesOverTheDomainAndLessOverParts) {
    World& w = world();
    const influence::SurfacePyramid pyramid = influence::buildSurfacePyramid(w.grid, w.lists.params());
    const double domain = w.grid.domainSizeM();
    const influence::RegionalLevelErrors regional(pyramid, influence::PyramidChannel::Elevation);
    EXPECT_EQ(regional.byLevelM(0, 0, domain, domain),
              influence::bilinearErrorByLevelM(pyramid, influence::PyramidChannel::Elevation));
    const Scene scene(w.grid, w.lists, &pyramid);
    const std::vector<double>& whole = scene.levelErrorM();
    ASSERT_EQ(scene.levelErrorM(0, 0, domain, domain), whole);
    int less = 0;
    for (int j = 0; j < 4; ++j)
        for (int i = 0; i < 4; ++i) {
            const double q = domain / 4;
            const std::vector<double> part = scene.levelErrorM(i * q, j * q, (i + 1) * q, (j + 1) * q);
            ASSERT_EQ(part.size(), whole.size());
            for (size_t t = 0; t < whole.size(); ++t) {
                EXPECT_LE(part[t], whole[t]) << "level " << t << ", part " << i << ", " << j;
                less += part[t] < whole[t];
            }
        }
    EXPECT_GT(less, 0) << "every part of the domain carries the whole domain's error at every level";
}

// Cascades charged with their own ground's error: from cameras over parts of the domain, under budgets, every frame's
// measured error still lies under its bound, and the cascades near the camera (over a part of the domain) get a bound
// of their own, below the whole domain's at their spacing somewhere.
TEST_P(ErrorBudget, RegionalBoundHoldsFromCamerasOverPartsOfTheDomain) {
    World& w = world();
    const influence::SurfacePyramid pyramid = influence::buildSurfacePyramid(w.grid, w.lists.params());
    const Scene scene(w.grid, w.lists, &pyramid);
    std::mt19937_64 rng(43);
    int lower = 0, frames = 0, cascades = 0;
    double smallest = 1;  // the least ratio of a cascade's error at its spacing to the whole domain's
    for (int k = 0; k < 12; ++k) {
        Camera cam = randomCamera(w, rng);
        cam.width = 160, cam.height = 100;
        for (const double budget : {0.0, 0.1, 2.0}) {
            RenderOptions o;
            o.legend = false;
            o.texelsPerSide = 256;
            o.maxErrorM = budget;
            Timings t;
            const render::Frame f = render::renderFrame(scene, cam, o, t);
            if (!std::isfinite(t.errorBoundM)) continue;
            const ErrorCheck check = render::verifyFrameError(scene, cam, f, kChecked);
            if (check.hits == 0) continue;
            ++frames;
            EXPECT_LE(check.maxM, t.errorBoundM + kFloatPositionM)
                << "camera " << k << ", budget " << budget << " m: median " << check.medianM;
            const render::CascadeFit fit =
                render::detail::fitFrame(scene, cam, render::detail::setUpFrame(scene, cam), o, t);
            for (const render::Cascade& c : fit.cascades) {
                if (c.empty()) continue;
                const int level = int(std::ceil(std::log2(c.texelM / w.grid.finestCellM) - 1e-9));
                const double own = render::levelErrorM(c.levelErrorM, level),
                             whole = render::levelErrorM(scene.levelErrorM(), level);
                EXPECT_LE(own, whole);
                lower += own < whole, ++cascades;
                smallest = std::min(smallest, own / whole);
            }
        }
    }
    std::printf(
        "%s: %d frames checked; %d of %d cascades carry less than the whole domain's error at their spacing "
        "(down to %.3g of it)\n",
        GetParam().c_str(), frames, lower, cascades, smallest);
    EXPECT_GT(frames, 18);
    EXPECT_GT(lower, 0) << "no cascade's ground carried less than the whole domain's error";
}

INSTANTIATE_TEST_SUITE_P(RealDems, ErrorBudget, ::testing::Values("hef", "lidar"));

// Without a pyramid no bound is claimed: NaN in Timings, null in the JSON, and the table says why.
TEST(ErrorBound, NoneWithoutAPyramid) {
    World& w = hef();
    const Rendered r = renderChecked(*w.scene, RenderOptions{});
    EXPECT_TRUE(std::isnan(r.timings.errorBoundM));
    EXPECT_NE(r.timings.toJson().find("\"error_bound_m\": null"), std::string::npos);
    EXPECT_NE(r.timings.toTable().find("none without the grid's surface pyramid"), std::string::npos);
    EXPECT_GT(r.check.hits, 0u);  // the check needs no pyramid
}

}  // namespace
}  // namespace hc::test
