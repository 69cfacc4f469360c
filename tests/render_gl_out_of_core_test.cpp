// The GL backend out of core (a Scene over the grid file: no cells or lists in memory) and with its cascades kept on
// the GPU from frame to frame, against the CPU backend: the same pictures, texels copied and interpolated from the
// surface pyramid bit for bit (or within a float rounding where the GPU fuses), and a moving camera that uploads and
// sums only the texels it newly sees. Headless as render_gl_test.cpp (HC_GL_TESTS=skip where no OpenGL 4.3 is
// expected).
#include "render_gl_world.h"

namespace {

using namespace hc::render;
using namespace hc::test::gl;

// A world's grid written to `file` (in the test's directory: removed after the test, an assertion's early return too)
// and its surface pyramid: what an out-of-core scene reads.
struct GridOnDisk {
    std::filesystem::path path;
    hc::influence::SurfacePyramid pyramid;
    GridOnDisk(const World& w, std::filesystem::path file)
        : path(std::move(file)), pyramid(hc::influence::buildSurfacePyramid(w.grid, {})) {
        hc::writeGrid(w.grid, path.string());
    }
};

// Out of core (a Scene over the grid file: no cells or lists in memory, as for 100 M cells) the GL backend fills the
// cascades on the CPU as renderFrame() does and casts and shades on the GPU: the same picture as the CPU backend on the
// same scene, the same texels copied from the pyramid, interpolated and summed (the Gaussians counted exactly), with
// and without a pyramid; a moving camera keeps texels from its last frame (cell outlines: render_gl_parity_test.cpp).
TEST_F(RenderGl, OutOfCoreFillsTheCascadesOnTheCpuAndCastsOnTheGpu) {
    World& w = hef();
    HC_REQUIRE_GL(w);
    const GridOnDisk disk(w, dir_ / "out_of_core.hcg");
    const std::filesystem::path& path = disk.path;
    const hc::influence::SurfacePyramid& pyramid = disk.pyramid;
    {
        const hc::GridRegionReader file(path.string());
        for (const hc::influence::SurfacePyramid* p :
             {static_cast<const hc::influence::SurfacePyramid*>(nullptr), &pyramid}) {
            const std::string tag = p ? "with the pyramid" : "without a pyramid";
            const Scene scene(file, {}, p);
            ASSERT_TRUE(scene.outOfCore());
            const std::unique_ptr<GlRenderer> gl = GlRenderer::headless(scene);
            const RenderOptions o = smallOptions();
            RenderOptions coarse = o;
            coarse.texelsPerSide = 128;  // texels as large as the cells (hef's are 64-254 m): copies where a pyramid is
            Camera moving = lowOblique(scene, 320, 200);
            uint64_t copied = 0, interpolated = 0, read = 0;
            for (const auto& [cam, opt] : {std::pair{overviewCamera(scene, 320, 200), o},
                                           {lowOblique(scene, 320, 200), o},
                                           {overviewCamera(scene, 320, 200), coarse}}) {
                Timings tc, tg;
                const Frame cpu = renderFrame(scene, cam, opt, tc);
                gl->forgetCascades();  // fresh as the CPU's frame (the counts below): the coarse frame would keep
                                       // texels of the one before
                const Frame g = gl->render(cam, opt, tg);
                expectSameFrames(cpu, g, tc, tg, "hef_out_of_core " + tag);
                for (size_t k = 0; k < tc.cascades.size(); ++k) {
                    EXPECT_EQ(tc.cascades[k].visibleTexels, tg.cascades[k].visibleTexels) << tag << " cascade " << k;
                    EXPECT_EQ(tc.cascades[k].pyramidTexels, tg.cascades[k].pyramidTexels) << tag << " cascade " << k;
                    EXPECT_EQ(tc.cascades[k].pyramidInterpolated, tg.cascades[k].pyramidInterpolated)
                        << tag << " cascade " << k;
                    EXPECT_EQ(tc.cascades[k].texelM, tg.cascades[k].texelM)
                        << tag << " cascade " << k << ": the pyramid's ladder";
                    copied += tg.cascades[k].pyramidTexels, interpolated += tg.cascades[k].pyramidInterpolated,
                        read += tg.cascades[k].cellsRead;
                }
                EXPECT_GT(tg.approximationMs, 0.0);
            }
            if (p) {
                EXPECT_GT(copied, 0u) << "the GL backend's cascades copy the pyramid's samples";
                EXPECT_GT(interpolated, 0u) << "and interpolate them where texels are finer";
            } else {
                EXPECT_GT(read, 0u) << "without a pyramid the texels are summed from cells read from the file";
            }
            // The camera moves 20 m between two frames: the second keeps most texels (the first frame after the
            // overview starts afresh) and shows what a fresh CPU frame shows.
            Timings t0, t1, tc;
            (void)gl->render(moving, o, t0);
            moving.xWorld += 20;
            const Frame g = gl->render(moving, o, t1);
            const Frame cpu = renderFrame(scene, moving, o, tc);
            uint64_t kept = 0;
            for (const CascadeStats& cs : t1.cascades) kept += cs.reusedTexels;
            EXPECT_GT(kept, 0u) << tag << ": a moving camera keeps texels from its last frame";
            gl->forgetCascades();
            Timings t2;
            (void)gl->render(moving, o, t2);
            for (const CascadeStats& cs : t2.cascades)
                EXPECT_EQ(cs.reusedTexels, 0u) << tag << ": forgetCascades() starts afresh";
            const Comparison c = compare(cpu, g, "hef_out_of_core_moved " + tag);
            EXPECT_GE(double(c.agree) / double(c.pixels), 0.995) << tag;
            EXPECT_GE(c.psnr, 35.0) << tag;
        }
    }
}

// A cascade's textures from the GPU (GlRenderer::cascadeTexturesForTest) against the CPU's, texel by texel: those that
// differ, the first of them, and (counted apart, not as differing) those within a float rounding where the frame
// interpolated texels on the GPU from level 0 (interpolate.comp): its double sums there are fused multiply-adds, the
// CPU's where its compiler fuses them (GCC does for a CPU with FMA), else they may differ in their last bits and round
// to floats one ulp apart. The elevation then within one ulp, the depth (level - elevation) and the water level within
// one ulp of the larger of them each, and the water drawn on one side alone only at the depth threshold. Every other
// texel must be the same bits.
struct TexelDiff {
    size_t differ = 0, first = SIZE_MAX, rounded = 0;
};
TexelDiff diffTextures(const hc::render::detail::CascadeTextures& cpu, const GlRenderer::CascadeTexels& gpu,
                       float minDepth, bool gpuInterpolated) {
    TexelDiff d;
    const auto bits = [](float v) { return std::bit_cast<uint32_t>(v); };
    for (size_t i = 0; i < cpu.terrain.h.size(); ++i) {
        const float z = cpu.terrain.h[i], water = cpu.water.h[i], depth = cpu.depth[i];
        const float gz = gpu.terrain[i], gWater = gpu.water[i], gDepth = gpu.depth[i];
        if (bits(z) == bits(gz) && bits(water) == bits(gWater) && bits(depth) == bits(gDepth)) continue;
        const float scale = std::max({std::abs(z), std::isfinite(water) ? std::abs(water) : 0.0f, 1.0f});
        const float ulp = std::nextafter(scale, INFINITY) - scale, tol = 2 * ulp;
        const bool near = std::abs(z - gz) <= ulp && std::abs(depth - gDepth) <= tol &&
                          (bits(water) == bits(gWater) ||
                           (std::isfinite(water) && std::isfinite(gWater) && std::abs(water - gWater) <= tol) ||
                           std::abs(depth - minDepth) <= tol);
        if (near && gpuInterpolated) {
            ++d.rounded;
            continue;
        }
        if (d.differ++ == 0) d.first = i;
    }
    return d;
}

// Out of core the GL backend keeps its cascades on the GPU and uploads only the texels a frame newly sees
// (assemble.comp places them beside the texels kept from the last frame). Over a flight (20 m steps, a 2 km jump that
// keeps part of a cascade or none, steps again, a frame after one that failed half-way, a frame after forgetCascades)
// every frame's textures on the GPU are the CPU's, texel for texel and bit for bit, but for the texels interpolated on
// the GPU from level 0 (interpolate.comp), which may differ by float rounding (below): the reference evaluates each
// cascade on the CPU with the texels it keeps copied from the reference's own last frame, as renderFrame() does with a
// CascadeCache (a texel evaluated afresh may differ from a kept one in its last bit: a few of a frame's do here). A
// 20 m step uploads under a tenth of the bytes of a fresh frame. Fails when a kept texel is shifted by one, when
// assemble.comp leaves the texels outside the rows' spans unwritten (the last frame but one's stay), when a frame keeps
// texels after a failed one (whose cascades, too large for any driver's storage block, failed after the heights
// buffers were swapped: the texels of two frames before), when the kept spans are uploaded again (the bytes), or when
// interpolate.comp takes a sample or weight one off, or leaves a block's texels to the CPU's unwritten ones.
TEST_F(RenderGl, OutOfCoreKeepsTheCascadesOnTheGpuAndUploadsOnlyNewTexels) {
    namespace detail = hc::render::detail;
    World& w = hef();
    HC_REQUIRE_GL(w);
    const GridOnDisk disk(w, dir_ / "kept.hcg");
    {
        const hc::GridRegionReader file(disk.path.string());
        const Scene scene(file, {}, &disk.pyramid);
        ASSERT_TRUE(scene.outOfCore());
        ASSERT_TRUE(scene.hasWater());
        // Four flights: texels mostly finer than the pyramid's levels (interpolated from level 0 on the GPU where its
        // tiles around are all stored and alike, dry or wet: PyramidTiles::Block; else on the CPU); texels as large as
        // the cells (hef's are 64-254 m), which the pyramid holds, copied on the GPU from its tiles there (the atlas);
        // and both again with an atlas of 40 tiles, fewer than a frame needs: it drops tiles every frame, and copies
        // the tiles and interpolates the blocks it cannot place on the CPU.
        struct Flight {
            int texels;
            uint32_t atlasTiles;
        };
        uint64_t onGpuWithWholeAtlas = 0;
        for (const Flight flight : {Flight{512, 0}, Flight{128, 0}, Flight{128, 40}, Flight{512, 40}}) {
            const uint32_t atlasTiles = flight.atlasTiles;
            GlRenderer::limitAtlasForTest(atlasTiles);
            const std::unique_ptr<GlRenderer> gl = GlRenderer::headless(scene);
            GlRenderer::limitAtlasForTest(0);
            RenderOptions o = smallOptions();
            o.texelsPerSide = flight.texels;
            Camera cam = lowOblique(scene, 320, 200);
            // East (x) and up (z) [m] before each frame. The climbing frames grow the cascades: with the pyramid a
            // cascade's side follows its extent in steps of 64 texels, so some keep the texels of a last-frame cascade
            // of another side.
            struct Move {
                double dx, dz;
            };
            const Move moves[] = {{0, 0},   {20, 0},  {20, 0},  {2000, 0}, {20, 0},  {-2000, 0},
                                  {20, 0},  {20, 0},  {20, 0},  {30, 40},  {30, 40}, {30, 40},
                                  {30, 40}, {30, 40}, {30, 40}, {30, 40},  {30, 40}, {0, 0}};
            const size_t failedBefore = 8;  // a frame that fails after the swap comes before this one
            int sideChanges = 0;
            uint64_t freshBytes = 0, onGpuInterpolated = 0, roundedOtherwise = 0, interpolated = 0;
            std::vector<Cascade> lastCascades;  // the reference's last frame
            std::vector<detail::CascadeTextures> lastTextures;
            for (size_t f = 0; f < std::size(moves); ++f) {
                const std::string tag = "frame " + std::to_string(f) + ", " + std::to_string(flight.texels) +
                                        " texels" + (atlasTiles ? ", an atlas of 40 tiles" : "");
                cam.xWorld += moves[f].dx, cam.zWorld += moves[f].dz;
                const bool fresh = f == 0 || f + 1 == std::size(moves) || f == failedBefore;
                if (f == failedBefore) {
                    RenderOptions huge = o;
                    huge.cascades = 4, huge.texelsPerSide = 8192;  // over 2^31 bytes of textures: more than a storage
                                                                   // block holds (llvmpipe 128 MiB, NVIDIA 2 GiB)
                    Timings th;
                    EXPECT_THROW((void)gl->render(cam, huge, th), hc::Error) << tag;
                }
                if (fresh) lastCascades.clear(), lastTextures.clear();
                if (fresh && f != failedBefore)
                    gl->forgetCascades();  // after the failure the renderer must start afresh itself
                Timings t;
                (void)gl->render(cam, o, t);
                uint64_t kept = 0, visible = 0;
                for (const CascadeStats& cs : t.cascades)
                    kept += cs.reusedTexels, visible += cs.visibleTexels, interpolated += cs.pyramidInterpolated;
                onGpuInterpolated += t.atlasInterpolated;
                if (fresh) {
                    EXPECT_EQ(kept, 0u) << tag << ": a fresh frame";
                    if (f == 0) freshBytes = t.uploadBytes;
                    if (flight.texels == 128) {
                        EXPECT_GT(t.atlasTexels, 0u)
                            << tag << ": a fresh frame copies texels from the pyramid's tiles on the GPU";
                    }
                    if (f == 0 && flight.texels == 128) {
                        EXPECT_GT(t.atlasTilesUploaded, 0u) << tag;
                        if (atlasTiles) {
                            EXPECT_EQ(t.atlasTilesUploaded, 2 * atlasTiles)
                                << tag << ": every slot of both atlases (elevation, water) taken";
                        }
                    }
                } else if (moves[f].dx == 20 && moves[f].dz == 0) {
                    EXPECT_GT(kept, visible * 9 / 10) << tag << ": a 20 m step keeps most texels";
                    if (!atlasTiles) {  // (an atlas too small uploads its tiles again)
                        EXPECT_LT(t.uploadBytes, freshBytes / 10) << tag << ": and uploads few";
                    }
                }
                // The reference: this frame's cascades on the CPU, each keeping the texels of the last frame's cascade
                // of the same texel size and lattice placed nearest to it, whatever its side (renderer.cpp's
                // reusableCascade).
                const detail::FrameSetup setup = detail::setUpFrame(scene, cam);
                Timings tf;
                const CascadeFit fit = detail::fitFrame(scene, cam, setup, o, tf);
                const std::vector<GlRenderer::CascadeTexels> onGpu = gl->cascadeTexturesForTest();
                ASSERT_EQ(onGpu.size(), fit.cascades.size()) << tag;
                std::vector<detail::CascadeTextures> textures(fit.cascades.size());
                std::vector<bool> taken(lastCascades.size(), false);
                uint64_t keptOnCpu = 0;
                for (size_t k = 0; k < fit.cascades.size(); ++k) {
                    const Cascade& c = fit.cascades[k];
                    ASSERT_EQ(onGpu[k].n, c.empty() ? 0 : c.n) << tag << " cascade " << k;
                    if (c.empty()) continue;
                    std::optional<detail::TexelReuse> reuse;
                    size_t from = 0;
                    for (size_t e = 0; e < lastCascades.size(); ++e) {
                        const Cascade& old = lastCascades[e];
                        if (taken[e] || old.empty() || old.texelM != c.texelM) continue;
                        const double fi = (c.x0 - old.x0) / c.texelM, fj = (c.y0 - old.y0) / c.texelM;
                        if (std::abs(fi - std::round(fi)) >= 1e-6 || std::abs(fj - std::round(fj)) >= 1e-6) continue;
                        const detail::TexelReuse r{&old, &lastTextures[e], int(std::round(fi)), int(std::round(fj))};
                        if (!reuse || std::max(std::abs(r.di), std::abs(r.dj)) <
                                          std::max(std::abs(reuse->di), std::abs(reuse->dj)))
                            reuse = r, from = e;
                    }
                    if (reuse) taken[from] = true, sideChanges += reuse->cascade->n != c.n;
                    detail::CascadeTextures& cpu = textures[k];
                    keptOnCpu += detail::approximate(scene, c, cpu, o.waterMinDepthM, 0, reuse ? &*reuse : nullptr,
                                                     o.pyramidInterpolateLevels)
                                     .reusedTexels;
                    cpu.extendWaterToShores(0);  // as renderFrame() and shore.comp, before the mipmaps
                    const TexelDiff d = diffTextures(cpu, onGpu[k], float(o.waterMinDepthM), t.atlasInterpolated > 0);
                    roundedOtherwise += d.rounded;
                    const size_t differ = d.differ, first = d.first;
                    EXPECT_EQ(differ, 0u) << tag << " cascade " << k << ": first at texel " << first << " of "
                                          << cpu.terrain.h.size() << " (n " << c.n << ")";
                }
                EXPECT_EQ(keptOnCpu, kept) << tag << ": the GPU kept what the CPU keeps";
                lastCascades = fit.cascades;
                lastTextures = std::move(textures);
            }
            EXPECT_GT(sideChanges, 0) << "no frame kept texels of a cascade of another side: the climb checks nothing";
            std::printf("%d cascades kept texels of a last-frame cascade of another side\n", sideChanges);
            if (flight.texels ==
                512) {  // texels finer than level 0: those in blocks of level-0 tiles interpolated on the GPU
                EXPECT_GT(onGpuInterpolated, 0u) << "atlas " << atlasTiles;
                // The rest where level 0 is not stored (hef's finest cells are few), from levels above, on the CPU.
                EXPECT_LT(onGpuInterpolated, interpolated) << "atlas " << atlasTiles;
                if (!atlasTiles)
                    onGpuWithWholeAtlas = onGpuInterpolated;
                else
                    EXPECT_LT(onGpuInterpolated, onGpuWithWholeAtlas)
                        << "an atlas of 40 tiles leaves blocks to the CPU";
            }
            std::printf(
                "%d texels, atlas %u: %llu texels interpolated, %llu on the GPU, %llu of them rounded otherwise than "
                "on the CPU\n",
                flight.texels, atlasTiles, (unsigned long long)interpolated, (unsigned long long)onGpuInterpolated,
                (unsigned long long)roundedOtherwise);
        }
    }
}

// A later water step out of core (the first step's pyramid for the terrain, the step's own water pyramid, as
// hc-influence --step builds it: influence::buildWaterPyramid): the texels finer than level 0 that the GL backend
// interpolates on the GPU from level 0's terrain and water tiles give the CPU's textures (diffTextures), wet ones among
// them. Fails when interpolate.comp drops the water, or when the blocks' kinds are taken from the base's water (every
// block dry) instead of the step's.
TEST_F(RenderGlWater, OutOfCoreWaterStepInterpolatedOnTheGpuAsOnTheCpu) {
    namespace detail = hc::render::detail;
    World& w = hef();
    HC_REQUIRE_GL(w);
    const std::filesystem::path path = dir_ / "steps.hcg";
    hc::ingest::Options in;
    in.input = hc::test::dataFile("hef_srtm.tif");
    in.toleranceM = 1;
    in.maxCellM = 512;
    in.water = hc::ingest::WaterSource::Level;
    in.waterLevelsM = {1900, 2000, 2800};
    hc::ingest::LoadReport rep;
    hc::ingest::ingestToFile(in, path.string(), rep);
    const hc::influence::KernelParams params{};
    const hc::influence::SurfacePyramid base =
        hc::influence::buildSurfacePyramid(hc::readGrid(path.string(), nullptr, 0), params);
    const hc::influence::SurfacePyramid water =
        hc::influence::buildWaterPyramid(hc::readGrid(path.string(), nullptr, 2), params);
    const hc::GridRegionReader file(path.string(), 2);
    const Scene scene(file, params, &base, &water);
    ASSERT_TRUE(scene.outOfCore() && scene.hasWater());
    const std::unique_ptr<GlRenderer> gl = GlRenderer::headless(scene);
    RenderOptions o = smallOptions();
    o.texelsPerSide = 512;  // a near cascade finer than level 0
    uint64_t onGpu = 0, wetInterpolated = 0, rounded = 0;
    for (const Camera& cam : {overviewCamera(scene, 320, 200), lowOblique(scene, 320, 200)}) {
        gl->forgetCascades();
        Timings t;
        (void)gl->render(cam, o, t);
        onGpu += t.atlasInterpolated;
        const detail::FrameSetup setup = detail::setUpFrame(scene, cam);
        Timings tf;
        const CascadeFit fit = detail::fitFrame(scene, cam, setup, o, tf);
        const std::vector<GlRenderer::CascadeTexels> textures = gl->cascadeTexturesForTest();
        ASSERT_EQ(textures.size(), fit.cascades.size());
        for (size_t k = 0; k < fit.cascades.size(); ++k) {
            const Cascade& c = fit.cascades[k];
            if (c.empty()) continue;
            detail::CascadeTextures cpu;
            const detail::ApproximationWork work =
                detail::approximate(scene, c, cpu, o.waterMinDepthM, 0, nullptr, o.pyramidInterpolateLevels);
            cpu.extendWaterToShores(0);
            const TexelDiff d = diffTextures(cpu, textures[k], float(o.waterMinDepthM), t.atlasInterpolated > 0);
            EXPECT_EQ(d.differ, 0u) << "cascade " << k << ": first at texel " << d.first << " (n " << c.n << ")";
            rounded += d.rounded;
            if (work.pyramidLevel < 0 && work.pyramidInterpolated > 0)
                for (size_t i = 0; i < cpu.water.h.size(); ++i)
                    wetInterpolated += std::isfinite(cpu.water.h[i]) && cpu.depth[i] > 0;
        }
    }
    std::printf(
        "%llu texels interpolated on the GPU, %llu of them rounded otherwise than on the CPU; %llu wet texels in "
        "cascades finer than level 0\n",
        (unsigned long long)onGpu, (unsigned long long)rounded, (unsigned long long)wetInterpolated);
    EXPECT_GT(onGpu, 0u);
    EXPECT_GT(wetInterpolated, 0u) << "the flood must lie in the fine cascades for the comparison to mean anything";
}

// In memory the GL backend keeps its cascades on the GPU too (the incremental cascades of docs/design.md section 5): a
// moving camera's frame sums only the texels it newly sees. Over 20 m steps each frame keeps over 90 % of its visible
// texels and evaluates under a tenth of a fresh frame's Gaussians; its textures are a fresh frame's (the same camera
// after forgetCascades) to 1 mm with no surface at the same texels (a kept texel was summed at a centre computed
// from another frame's lattice origin: equal to double rounding); and its picture is the CPU's. Fails when the kept
// texels are shifted, or summed again (the Gaussians), or when approximate.comp writes outside its spans.
// The bytes the cascades of a frame take in the GL backend's heights buffer, counted here from their sides (n):
// every cascade's texels (terrain, water level, depth) and its max mipmaps (terrain and water, side n - 1 halving to
// 1), 4 bytes each.
uint64_t heightsBytes(const std::vector<GlRenderer::CascadeTexels>& cascades, bool water) {
    uint64_t floats = 0;
    for (const GlRenderer::CascadeTexels& c : cascades) {
        if (c.n == 0) continue;
        floats += uint64_t(c.n) * uint64_t(c.n) * (water ? 3 : 1);
        for (uint64_t side = uint64_t(c.n) - 1;; side = (side + 1) / 2) {
            floats += side * side * (water ? 2 : 1);
            if (side <= 1) break;
        }
    }
    return floats * 4;
}

// Where the driver's largest storage buffer cannot hold the cascades at the pyramid's spacings (up to 2N texels a
// side: 153 MiB at 1920x1080 over the hef flood, llvmpipe allows 128), the GL backend draws N texels a side at the next
// coarser spacing, the CPU's picture with --pyramid-coarse, and says so in the frame's notes; where it can, the
// ladder's picture and no note.
TEST_F(RenderGl, OutOfCoreTexturesHeldToTheDriversStorageBuffer) {
    World& w = hef();
    HC_REQUIRE_GL(w);
    const GridOnDisk disk(w, dir_ / "held.hcg");
    const hc::GridRegionReader file(disk.path.string());
    const Scene scene(file, {}, &disk.pyramid);
    const Camera cam = lowOblique(scene, 320, 200);
    const RenderOptions o = smallOptions();
    RenderOptions coarse = o;
    coarse.pyramidCoarseTexels = true;
    // The two layouts' sizes, from a renderer with the driver's own limit.
    uint64_t ladderBytes = 0, coarseBytes = 0;
    {
        const std::unique_ptr<GlRenderer> gl = GlRenderer::headless(scene);
        Timings t;
        (void)gl->render(cam, coarse, t);
        coarseBytes = heightsBytes(gl->cascadeTexturesForTest(), scene.hasWater());
        gl->forgetCascades();
        const Frame g = gl->render(cam, o, t);
        ladderBytes = heightsBytes(gl->cascadeTexturesForTest(), scene.hasWater());
        Timings tc;
        expectSameFrames(renderFrame(scene, cam, o, tc), g, tc, t, "ladder, room enough");
        EXPECT_TRUE(t.notes.empty());
    }
    ASSERT_GT(ladderBytes, coarseBytes) << "the ladder's textures are larger than N texels a side";
    GlRenderer::limitStorageBlockForTest((ladderBytes + coarseBytes) / 2);
    const std::unique_ptr<GlRenderer> held = GlRenderer::headless(scene);
    GlRenderer::limitStorageBlockForTest(0);
    Timings tg, tc;
    const Frame g = held->render(cam, o, tg);
    const Frame cpu = renderFrame(scene, cam, coarse, tc);
    expectSameFrames(cpu, g, tc, tg, "held to the storage buffer");
    ASSERT_EQ(tg.cascades.size(), tc.cascades.size());
    for (size_t k = 0; k < tc.cascades.size(); ++k)
        EXPECT_EQ(tg.cascades[k].texelM, tc.cascades[k].texelM) << "cascade " << k << ": --pyramid-coarse's spacing";
    ASSERT_EQ(tg.notes.size(), 1u);
    EXPECT_NE(tg.notes[0].find("next coarser spacing"), std::string::npos) << tg.notes[0];
    EXPECT_NE(tg.toTable().find("note: the cascade textures"), std::string::npos);
    EXPECT_NE(tg.toJson().find("\"notes\""), std::string::npos);
}

TEST_F(RenderGl, InMemoryMovingCameraSumsOnlyTheNewTexels) {
    World& w = hef();
    HC_REQUIRE_GL(w);
    const RenderOptions o = smallOptions();
    Camera cam = lowOblique(*w.scene, 320, 200);
    w.gl->forgetCascades();
    Timings t0;
    (void)w.gl->render(cam, o, t0);
    uint64_t fresh = 0;
    for (const CascadeStats& cs : t0.cascades) fresh += cs.gaussians;
    ASSERT_GT(fresh, 0u);
    for (int f = 1; f <= 3; ++f) {
        const std::string tag = "frame " + std::to_string(f);
        cam.xWorld += 20;
        Timings t;
        const Frame g = w.gl->render(cam, o, t);
        uint64_t kept = 0, visible = 0, gaussians = 0;
        for (const CascadeStats& cs : t.cascades)
            kept += cs.reusedTexels, visible += cs.visibleTexels, gaussians += cs.gaussians;
        EXPECT_GT(kept, visible * 9 / 10) << tag;
        EXPECT_LT(gaussians, fresh / 10) << tag;
        const std::vector<GlRenderer::CascadeTexels> moving = w.gl->cascadeTexturesForTest();
        Timings tc;
        const Frame cpu = renderFrame(*w.scene, cam, o, tc);
        const Comparison c = compare(cpu, g, "hef_in_memory_moving");
        EXPECT_GE(double(c.agree) / double(c.pixels), 0.995) << tag;
        EXPECT_GE(c.psnr, 35.0) << tag;
        w.gl->forgetCascades();
        Timings tf;
        (void)w.gl->render(cam, o, tf);
        const std::vector<GlRenderer::CascadeTexels> again = w.gl->cascadeTexturesForTest();
        ASSERT_EQ(moving.size(), again.size()) << tag;
        for (size_t k = 0; k < moving.size(); ++k) {
            ASSERT_EQ(moving[k].n, again[k].n) << tag << " cascade " << k;
            size_t surfaceDiffers = 0;
            double worst = 0;
            for (size_t i = 0; i < moving[k].terrain.size(); ++i) {
                for (const auto& [ma, aa] :
                     {std::pair{&moving[k].terrain, &again[k].terrain}, {&moving[k].water, &again[k].water}}) {
                    const float a = (*ma)[i], b = (*aa)[i];
                    if (std::isfinite(a) != std::isfinite(b))
                        ++surfaceDiffers;
                    else if (std::isfinite(a))
                        worst = std::max(worst, double(std::abs(a - b)));
                }
                worst = std::max(worst, double(std::abs(moving[k].depth[i] - again[k].depth[i])));
            }
            EXPECT_EQ(surfaceDiffers, 0u) << tag << " cascade " << k;
            EXPECT_LE(worst, 1e-3) << tag << " cascade " << k;
        }
        // Back to texels kept: the next step keeps this fresh frame's.
    }
}

// Given near and far planes reach the GL backend through the shared frame set-up: the same picture as the CPU's
// with the same planes, and no GL hit outside them.

}  // namespace
