// The GL backend at parity with the CPU one where shading needs what the CPU computes from each hit (GpuFrame::overlay,
// render/gl/src/backend_overlay.cpp): colouring by a further layer (--color-by: the exact evaluator's value at the
// hit), a static layer on the terrain and a water layer on a flood, and cell outlines out of core (the cell around each
// hit read from the file). Each GL frame against the CPU's of the same scene and camera: the same hits and picture as
// every GL test holds them (render_gl_world.h), the same layer values where both colour, and a picture that the
// overlay changed. Headless as render_gl_test.cpp (HC_GL_TESTS=skip where no OpenGL 4.3 is expected).
#include <map>

#include "render_gl_world.h"

namespace {

using namespace hc::render;
using namespace hc::test::gl;

// The lidar DEM with a static layer "relief" [m]: the elevation less its mean over 200 m squares, a field with as much
// detail as the terrain, so that a wrongly placed or wrongly ranged value shows.
World& lidarWithRelief() {
    static World w = [] {
        World x;
        x.grid = hc::test::ingestFile(hc::test::dataFile("lidar1m_minnesota_utm15.tif"), 0.25);
        hc::Grid& g = x.grid;
        std::map<std::pair<long, long>, std::pair<double, size_t>> mean;
        auto square = [&](size_t i) {
            double cx = 0, cy = 0;
            g.cellCenterLocal(i, cx, cy);
            return std::pair{long(std::floor(cx / 200)), long(std::floor(cy / 200))};
        };
        for (size_t i = 0; i < g.cellCount(); ++i) {
            auto& [sum, n] = mean[square(i)];
            sum += g.values[0][i], ++n;
        }
        g.layers.push_back({"relief", "m"});
        g.values.emplace_back(g.cellCount());
        for (size_t i = 0; i < g.cellCount(); ++i) {
            const auto& [sum, n] = mean[square(i)];
            g.values.back()[i] = float(g.values[0][i] - sum / double(n));
        }
        x.init();
        return x;
    }();
    return w;
}

// The alpine DEM's bathtub flood with a step layer "speed" [m s-1] = sqrt(g d) on its wet cells (a water layer: the
// flood coloured, dry land grey), its range in the step table as hc-ingest writes it.
World& hefWithSpeed() {
    static World w = [] {
        World x;
        x.grid = hc::test::ingestFile(hc::test::dataFile("hef_srtm.tif"), 0.5, 2600);
        hc::Grid& g = x.grid;
        const std::vector<float>& depth = g.values[size_t(g.findLayer("water_depth"))];
        std::vector<float> speed(g.cellCount(), 0.0f);
        float lo = HUGE_VALF, hi = -HUGE_VALF, dLo = HUGE_VALF, dHi = -HUGE_VALF;
        for (size_t i = 0; i < g.cellCount(); ++i) {
            if (!(depth[i] > 0)) continue;
            speed[i] = std::sqrt(9.81f * depth[i]);
            lo = std::min(lo, speed[i]), hi = std::max(hi, speed[i]);
            dLo = std::min(dLo, depth[i]), dHi = std::max(dHi, depth[i]);
        }
        g.layers.push_back({"speed", "m s-1"});
        g.values.push_back(std::move(speed));
        if (g.steps.empty()) g.steps.resize(1);
        g.steps[0].layerMin = {dLo, lo}, g.steps[0].layerMax = {dHi, hi};
        x.init();
        return x;
    }();
    return w;
}

// Frame::colorLayerValue of both backends: pixels either colours, both colour, and both within `tolerance` of each
// other.
struct LayerAgreement {
    size_t either = 0, both = 0, within = 0;
};
LayerAgreement compareLayerValues(const Frame& cpu, const Frame& gl, double tolerance) {
    LayerAgreement a;
    for (size_t i = 0; i < cpu.colorLayerValue.size(); ++i) {
        const float c = cpu.colorLayerValue[i], g = gl.colorLayerValue[i];
        if (std::isnan(c) && std::isnan(g)) continue;
        ++a.either;
        if (std::isnan(c) || std::isnan(g)) continue;
        ++a.both;
        a.within += std::abs(double(c) - double(g)) <= tolerance;
    }
    return a;
}

// --color-by `layer` on both backends from `cam`. The values are the exact evaluator's at each backend's own hit, so
// they differ as the hits do: the hit positions agree within the depth tolerance (1e-5 t + 1 cm, up to 0.3 m at these
// distances) on 99.5 % of the pixels, across which these fields change by a few hundredths of their range at most (the
// relief's detail is a metre or more; the speed's a cell). 1 % of the layer's range bounds that; a layer placed or
// ranged wrongly misses it on most pixels.
void expectColouredAsOnTheCpu(World& w, const Camera& cam, const std::string& layer, const std::string& name) {
    RenderOptions o = smallOptions();
    o.colorLayer = layer;
    Timings tc, tg;
    const Frame cpu = renderFrame(*w.scene, cam, o, tc);
    w.gl->forgetCascades();
    const Frame gl = w.gl->render(cam, o, tg);
    expectSameFrames(cpu, gl, tc, tg, name);
    EXPECT_EQ(gl.colorLayer, layer) << name;
    ASSERT_EQ(gl.colorLayerValue.size(), cpu.colorLayerValue.size()) << name;
    const auto [lo, hi] = detail::layerRange(w.grid, hc::influence::Layer::byName(w.grid, layer));
    ASSERT_GT(hi, lo) << name;
    const LayerAgreement a = compareLayerValues(cpu, gl, 0.01 * (hi - lo));
    std::printf(
        "[ %s ] %zu pixels coloured by %s on either backend, %zu on both, %zu of those within 1 %% of its "
        "range\n",
        name.c_str(), a.either, layer.c_str(), a.both, a.within);
    EXPECT_GT(a.both, cpu.colorLayerValue.size() / 20) << name << ": the layer colours a part of the picture";
    EXPECT_GE(double(a.both), 0.995 * double(a.either)) << name << ": the same pixels coloured";
    EXPECT_GE(double(a.within), 0.995 * double(a.both)) << name << ": the same values";
    // The overlay reached the picture: the layer's colours are not the plain ramps'.
    Timings tp;
    const Frame plain = w.gl->render(cam, smallOptions(), tp);
    EXPECT_LT(hc::test::psnr(gl, plain), 25.0) << name << ": the picture coloured by " << layer << " is the plain one";
}

TEST_F(RenderGl, ColouredByAStaticLayerAsOnTheCpu) {
    World& w = lidarWithRelief();
    HC_REQUIRE_GL(w);
    expectColouredAsOnTheCpu(w, overviewCamera(*w.scene, 320, 200), "relief", "lidar_relief_overview");
    expectColouredAsOnTheCpu(w, lowOblique(*w.scene, 320, 200), "relief", "lidar_relief_oblique_low");
}

TEST_F(RenderGlWater, ColouredByAWaterLayerAsOnTheCpu) {
    World& w = hefWithSpeed();
    HC_REQUIRE_GL(w);
    expectColouredAsOnTheCpu(w, overviewCamera(*w.scene, 320, 200), "speed", "hef_speed_overview");
    expectColouredAsOnTheCpu(w, straightDown(*w.scene, 240, 240), "speed", "hef_speed_straight_down");
    RenderOptions o = smallOptions();
    o.colorLayer = "nosuch";
    Timings t;
    EXPECT_THROW((void)w.gl->render(overviewCamera(*w.scene, 320, 200), o, t), hc::Error);
}

// Out of core the cells are not on the GPU: the outline of the cell around each hit comes from the file, on the CPU.
// The same picture as the CPU backend's on the same scene, and one the outlines darkened; a colour layer is refused
// there on both backends.
TEST_F(RenderGl, CellOutlinesOutOfCoreAsOnTheCpu) {
    World& w = lidar();
    HC_REQUIRE_GL(w);
    const std::filesystem::path path = dir_ / "outlines.hcg";
    hc::writeGrid(w.grid, path.string());
    const hc::GridRegionReader file(path.string());
    const Scene scene(file, {});
    ASSERT_TRUE(scene.outOfCore());
    const std::unique_ptr<GlRenderer> gl = GlRenderer::headless(scene);
    RenderOptions o = smallOptions();
    o.cellOutlines = true;
    o.cascades = 4;
    const Camera cam = straightDown(scene, 240, 240);
    Timings tc, tg, tp;
    const Frame cpu = renderFrame(scene, cam, o, tc);
    const Frame g = gl->render(cam, o, tg);
    expectSameFrames(cpu, g, tc, tg, "lidar_out_of_core_cells");
    o.cellOutlines = false;
    const Frame plain = gl->render(cam, o, tp);
    size_t darker = 0;
    for (size_t i = 0; i < g.rgb.size(); i += 3) darker += g.rgb[i + 1] + 20 < plain.rgb[i + 1];
    EXPECT_GT(darker, g.rgb.size() / 3 / 50) << "the outlines darken the cells' edges";
    // A colour layer needs the exact evaluator, which needs the grid in memory: refused before any work, as on the CPU.
    RenderOptions layered = smallOptions();
    layered.colorLayer = "elevation";
    EXPECT_THROW((void)gl->render(cam, layered, tp), hc::Error);
    EXPECT_THROW((void)renderFrame(scene, cam, layered, tp), hc::Error);
}

}  // namespace
