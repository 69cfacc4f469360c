// UGRID quadtree meshes (docs/design.md section 6) and rotated grids: meshes written by hc-export's writer (and by
// hand, through GDAL's multidimensional API, for what the writer never writes) read back by hc-ingest's reader; a
// rotated grid probed and rendered as the same grid unrotated seen from a turned camera.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <optional>

#include <gdal_priv.h>

#include "heightcast/core/error.h"
#include "heightcast/export/export.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/influence/influence.h"
#include "heightcast/influence/surface.h"
#include "heightcast/ingest/ingest.h"
#include "heightcast/ingest/ugrid.h"
#include "heightcast/render/renderer.h"
#include "temp_dir.h"
#include "test_data.h"

namespace {

namespace fs = std::filesystem;
using hc::Grid;

class Mesh : public hc::test::TempDirTest {
protected:
    Mesh() : TempDirTest("hc_mesh_") {}
};

// A real scenario: the 1 m LiDAR tile flooded at 394.5, 395.5 and 396.5 m at 0, 10 and 20 minutes.
std::string lidarScenario(const std::string& dem, const std::string& out) {
    hc::ingest::Options o;
    o.input = dem;
    o.water = hc::ingest::WaterSource::Level;
    o.waterLevelsM = {394.5, 395.5, 396.5};
    o.timesS = {0, 600, 1200};
    hc::ingest::LoadReport rep;
    hc::ingest::ingestToFile(o, out, rep);
    return out;
}

// `src` rewritten with its origin kept and its axes turned by `deg` (every step).
void writeRotated(const std::string& src, const std::string& out, double deg) {
    Grid g = hc::readGrid(src);
    Grid shape = g;
    shape.rotationDeg = deg;
    hc::GridFileWriter w(out, shape, g.cellCount(), g.steps.size());
    w.append(g.codes, {std::span<const float>(g.values[0])});
    for (size_t k = 0; k < g.steps.size(); ++k) {
        if (k > 0) hc::readGridStep(src, g, k);
        w.appendStep(hc::sparseStep(g));
    }
    w.commit(g.stats);
}

// The grid a mesh reads back as must be the grid it was written from: the same cells and levels, bit for bit the
// same values in every step, the same times; the geometry to within what node coordinates in double carry (the
// finest size and the origin come back from differences of coordinates of ~5e6 m: 1e-9 relative, 1e-6 m). Not the
// declared coarsest level (Grid::maxLevel): a mesh has only the faces it has.
void expectSameGrid(const std::string& wrote, const std::string& read) {
    const Grid a = hc::readGrid(wrote), b0 = hc::readGrid(read);
    ASSERT_EQ(a.codes, b0.codes);
    EXPECT_EQ(a.rootLevel, b0.rootLevel);
    EXPECT_NEAR(b0.finestCellM, a.finestCellM, 1e-9 * a.finestCellM);
    EXPECT_NEAR(b0.originWorldX, a.originWorldX, 1e-6);
    EXPECT_NEAR(b0.originWorldY, a.originWorldY, 1e-6);
    EXPECT_NEAR(b0.rotationDeg, a.rotationDeg, 1e-7);
    EXPECT_EQ(b0.crsWkt.empty(), a.crsWkt.empty());
    EXPECT_EQ(a.values[0], b0.values[0]) << "elevations are the file's own (float32 through double: exact)";
    ASSERT_EQ(a.steps.size(), b0.steps.size());
    for (size_t k = 0; k < a.steps.size(); ++k) {
        SCOPED_TRACE("step " + std::to_string(k));
        const Grid x = hc::readGrid(wrote, nullptr, k), y = hc::readGrid(read, nullptr, k);
        EXPECT_EQ(x.stepTimeS(), y.stepTimeS());
        EXPECT_EQ(x.values[1], y.values[1]) << "depth = level - terrain in double, then float32: the written depth";
    }
}

TEST_F(Mesh, UgridRoundTripOfARealScenario) {
    HC_REQUIRE_DATA(dem, "lidar1m_minnesota_utm15.tif");
    lidarScenario(dem, path("flood.hcg"));
    for (int start : {0, 1}) {
        SCOPED_TRACE("start_index " + std::to_string(start));
        const std::string nc = path("flood" + std::to_string(start) + ".nc");
        const hc::exporting::UgridSummary m = hc::exporting::writeUgrid(path("flood.hcg"), nc, {start});
        EXPECT_EQ(m.steps, 3u);
        ASSERT_TRUE(hc::ingest::isUgridMesh(nc));
        EXPECT_FALSE(hc::ingest::isUgridMesh(dem)) << "a GeoTIFF is no mesh";
        hc::ingest::Options o;
        o.input = nc;
        hc::ingest::LoadReport rep;
        const hc::ingest::BuildSummary s = hc::ingest::ingestUgridToFile(o, path("back.hcg"), rep);
        EXPECT_EQ(s.cellCount, m.faces);
        expectSameGrid(path("flood.hcg"), path("back.hcg"));
        EXPECT_EQ(hc::readGrid(path("back.hcg")).crsName, "NAD83 / UTM zone 15N (EPSG:26915)");
    }
}

TEST_F(Mesh, RotatedQuadtreeIsTakenWithItsRotation) {
    HC_REQUIRE_DATA(dem, "lidar1m_minnesota_utm15.tif");
    lidarScenario(dem, path("flood.hcg"));
    for (double deg : {30.0, -17.25, 90.0, 180.0}) {
        SCOPED_TRACE("rotation " + std::to_string(deg));
        writeRotated(path("flood.hcg"), path("turned.hcg"), deg);
        hc::exporting::writeUgrid(path("turned.hcg"), path("turned.nc"));
        hc::ingest::Options o;
        o.input = path("turned.nc");
        hc::ingest::LoadReport rep;
        hc::ingest::ingestUgridToFile(o, path("back.hcg"), rep);
        // A turn by a multiple of 90 degrees is the same lattice: the reader keeps the orientation in (-45, 45],
        // so only 30 and -17.25 come back as such; 90 and 180 come back as 0 with the cells relabelled.
        const Grid back = hc::readGrid(path("back.hcg"));
        if (deg == 30.0 || deg == -17.25) {
            expectSameGrid(path("turned.hcg"), path("back.hcg"));
        } else {
            EXPECT_EQ(back.rotationDeg, 0.0);
            EXPECT_EQ(back.cellCount(), hc::readGrid(path("turned.hcg")).cellCount());
        }
        EXPECT_NE(rep.method.find(deg == 30.0 || deg == -17.25 ? "turned" : "no resampling"), std::string::npos)
            << rep.method;
    }
}

// A rotated grid is the unrotated one seen in turned axes: probing it at the turned points gives the same values.
TEST_F(Mesh, RotatedGridProbesAsTheUnrotatedOne) {
    HC_REQUIRE_DATA(dem, "lidar1m_minnesota_utm15.tif");
    lidarScenario(dem, path("flood.hcg"));
    writeRotated(path("flood.hcg"), path("turned.hcg"), 30.0);
    const Grid a = hc::readGrid(path("flood.hcg"), nullptr, 2), b = hc::readGrid(path("turned.hcg"), nullptr, 2);
    const hc::influence::KernelParams params;
    const auto la = hc::influence::buildInfluenceLists(a, params, 0, false),
               lb = hc::influence::buildInfluenceLists(b, params, 0, false);
    const hc::influence::SurfaceEvaluator ea(a, la), eb(b, lb);
    const auto water = hc::influence::Layer::byName(a, "water_surface");
    size_t wet = 0;
    for (int i = 0; i < 200; ++i) {
        const double lx = 5 + 1.93 * i, ly = 7 + 1.71 * ((i * 37) % 200);  // local points over the tile
        double wx = 0, wy = 0, bx = 0, by = 0;
        b.localToWorld(lx, ly, wx, wy);
        b.worldToLocal(wx, wy, bx, by);  // the world point the user would probe, back in the turned grid
        EXPECT_NEAR(bx, lx, 1e-9);
        EXPECT_NEAR(by, ly, 1e-9);
        const auto za = ea.value(lx, ly, hc::influence::Layer{}), zb = eb.value(bx, by, hc::influence::Layer{});
        ASSERT_EQ(za.has_value(), zb.has_value());
        if (za) {
            EXPECT_NEAR(*za, *zb, 1e-6);  // the point moved by 1e-9 m at most: the surface by far less than 1e-6 m
        }
        const auto sa = ea.value(lx, ly, water), sb = eb.value(bx, by, water);
        EXPECT_EQ(sa.has_value(), sb.has_value());
        wet += sa.has_value();
    }
    EXPECT_GT(wet, 5u) << "the points must reach the water for the water half to mean anything";
    // An export samples a world-aligned raster: each pixel is the turned grid's surface at that world point, the
    // rotated grid's extent is the box around its turned bounds.
    const hc::exporting::SampledRaster r =
        hc::exporting::sampleSurface(eb, hc::influence::Layer{}, "elevation", 7.0, std::nullopt, true, 0, false);
    double x0, y0, x1, y1;
    b.boundsLocal(x0, y0, x1, y1);
    double ex = 0, ey = 0;  // the turned bounds' top-right corner in the world: inside the raster
    b.localToWorld(x1, y1, ex, ey);
    EXPECT_LE(r.westWorld, ex);
    EXPECT_GE(r.westWorld + double(r.width) * r.pixelSizeM, ex);
    size_t defined = 0;
    for (size_t row = 0; row < r.height; row += 3)
        for (size_t col = 0; col < r.width; col += 3) {
            const double wx = r.westWorld + (double(col) + 0.5) * r.pixelSizeM,
                         wy = r.northWorld - (double(row) + 0.5) * r.pixelSizeM;
            double lx = 0, ly = 0;
            b.worldToLocal(wx, wy, lx, ly);
            const auto v = eb.value(lx, ly, hc::influence::Layer{});
            const float got = r.values[row * r.width + col];
            ASSERT_EQ(v.has_value(), !std::isnan(got)) << col << "," << row;
            if (v) {
                EXPECT_NEAR(got, *v, 1e-4 * std::abs(*v));  // float32 storage
                ++defined;
            }
        }
    EXPECT_GT(defined, 100u);
    EXPECT_LT(defined, r.width * r.height / 9 + 1)
        << "the corners of the box around a turned square lie outside the grid";
}

// Rendering a rotated grid from the turned camera gives the unrotated grid's picture (the rays are cast in the local
// frame: the same rays, up to the rounding of turning the eye there and back).
TEST_F(Mesh, RotatedGridRendersAsTheUnrotatedOneFromATurnedCamera) {
    HC_REQUIRE_DATA(dem, "lidar1m_minnesota_utm15.tif");
    lidarScenario(dem, path("flood.hcg"));
    writeRotated(path("flood.hcg"), path("turned.hcg"), 30.0);
    const Grid a = hc::readGrid(path("flood.hcg"), nullptr, 1), b = hc::readGrid(path("turned.hcg"), nullptr, 1);
    const hc::influence::KernelParams params;
    const auto la = hc::influence::buildInfluenceLists(a, params, 0, false),
               lb = hc::influence::buildInfluenceLists(b, params, 0, false);
    const hc::render::Scene sa(a, la), sb(b, lb);
    hc::render::Camera ca = hc::render::overviewCamera(sa, 160, 100);
    hc::render::Camera cb = ca;
    double lx = 0, ly = 0;
    a.worldToLocal(ca.xWorld, ca.yWorld, lx, ly);
    b.localToWorld(lx, ly, cb.xWorld, cb.yWorld);
    cb.yawDeg = ca.yawDeg - 30.0;
    hc::render::RenderOptions opt;
    opt.texelsPerSide = 128;
    hc::render::Timings ta, tb;
    const hc::render::Frame fa = hc::render::renderFrame(sa, ca, opt, ta),
                            fb = hc::render::renderFrame(sb, cb, opt, tb);
    ASSERT_GT(ta.hits, 1000u);
    size_t differ = 0, hits = 0;
    for (size_t i = 0; i < fa.distanceM.size(); ++i) {
        if (std::isinf(fa.distanceM[i]) != std::isinf(fb.distanceM[i])) {
            ++differ;
            continue;
        }
        if (std::isinf(fa.distanceM[i])) continue;
        ++hits;
        if (std::abs(fa.distanceM[i] - fb.distanceM[i]) > 1e-3f * fa.distanceM[i]) ++differ;
        // Positions come back along the CRS's axes: the turned grid's are the unrotated ones turned by 30 degrees.
        double px = 0, py = 0;
        b.localToWorldDir(fa.posX[i], fa.posY[i], px, py);
        EXPECT_NEAR(fb.posX[i], px, 0.05 + 1e-3 * fa.distanceM[i]);
        EXPECT_NEAR(fb.posY[i], py, 0.05 + 1e-3 * fa.distanceM[i]);
    }
    EXPECT_GT(hits, 1000u);
    EXPECT_LE(differ, fa.distanceM.size() / 500) << "at most 0.2 % of the pixels (edges where a ray grazes) may differ";
}

// Meshes that are no quadtree, written by hand: each refused naming the face and the problem, nothing written.
struct HandMesh {
    std::vector<double> x, y;
    std::vector<std::array<int, 4>> faces;  // -1: no node (a triangle)
    std::vector<double> zb;
    std::optional<double> zbFill;  // zb's _FillValue
    std::vector<double> times;
    std::vector<std::vector<double>> zs;   // per time, per face
    std::vector<std::vector<double>> vel;  // per time, per face: a further face variable "vel" [m/s] (empty: none)
};

void writeHandMesh(const HandMesh& m, const std::string& path) {
    GDALAllRegister();
    std::unique_ptr<GDALDataset> ds(
        GetGDALDriverManager()->GetDriverByName("netCDF")->CreateMultiDimensional(path.c_str(), nullptr, nullptr));
    ASSERT_TRUE(ds);
    auto root = ds->GetRootGroup();
    auto nodes = root->CreateDimension("nNodes", "", "", m.x.size());
    auto faces = root->CreateDimension("nFaces", "", "", m.faces.size());
    auto four = root->CreateDimension("nMax", "", "", 4);
    auto str = [](const std::shared_ptr<GDALMDArray>& a, const char* k, const char* v) {
        a->CreateAttribute(k, {}, GDALExtendedDataType::CreateString())->Write(v);
    };
    auto writeAll = [](const std::shared_ptr<GDALMDArray>& a, const void* data, GDALDataType t) {
        std::vector<GUInt64> start(a->GetDimensionCount(), 0);
        std::vector<size_t> count;
        for (const auto& d : a->GetDimensions()) count.push_back(size_t(d->GetSize()));
        ASSERT_TRUE(a->Write(start.data(), count.data(), nullptr, nullptr, GDALExtendedDataType::Create(t), data));
    };
    auto topo = root->CreateMDArray("mesh", {}, GDALExtendedDataType::Create(GDT_Int32));
    str(topo, "cf_role", "mesh_topology");
    topo->CreateAttribute("topology_dimension", {}, GDALExtendedDataType::Create(GDT_Int32))->WriteInt(2);
    str(topo, "node_coordinates", "nx ny");
    str(topo, "face_node_connectivity", "fn");
    auto nx = root->CreateMDArray("nx", {nodes}, GDALExtendedDataType::Create(GDT_Float64));
    auto ny = root->CreateMDArray("ny", {nodes}, GDALExtendedDataType::Create(GDT_Float64));
    writeAll(nx, m.x.data(), GDT_Float64);
    writeAll(ny, m.y.data(), GDT_Float64);
    auto fn = root->CreateMDArray("fn", {faces, four}, GDALExtendedDataType::Create(GDT_Int32));
    fn->SetNoDataValue(-1.0);
    std::vector<int> flat;
    for (const auto& f : m.faces) flat.insert(flat.end(), f.begin(), f.end());
    writeAll(fn, flat.data(), GDT_Int32);
    auto zb = root->CreateMDArray("zb", {faces}, GDALExtendedDataType::Create(GDT_Float64));
    if (m.zbFill) zb->SetNoDataValue(*m.zbFill);
    writeAll(zb, m.zb.data(), GDT_Float64);
    if (!m.times.empty()) {
        auto time = root->CreateDimension("time", "", "", m.times.size());
        auto t = root->CreateMDArray("time", {time}, GDALExtendedDataType::Create(GDT_Float64));
        str(t, "units", "hours since 2024-01-01 00:00:00");
        writeAll(t, m.times.data(), GDT_Float64);
        auto zs = root->CreateMDArray("zs", {time, faces}, GDALExtendedDataType::Create(GDT_Float64));
        zs->SetNoDataValue(-99999.0);
        std::vector<double> all;
        for (const auto& row : m.zs) all.insert(all.end(), row.begin(), row.end());
        writeAll(zs, all.data(), GDT_Float64);
        if (!m.vel.empty()) {
            auto vel = root->CreateMDArray("vel", {time, faces}, GDALExtendedDataType::Create(GDT_Float64));
            vel->SetNoDataValue(-99999.0);
            str(vel, "units", "m s-1");
            std::vector<double> v;
            for (const auto& row : m.vel) v.insert(v.end(), row.begin(), row.end());
            writeAll(vel, v.data(), GDT_Float64);
        }
    }
}

// Two levels: one face of side 2 at (0, 0) and four of side 1 at (2..4, 0..2), nodes on a 5 x 3 lattice.
HandMesh goodMesh() {
    HandMesh m;
    for (int j = 0; j <= 2; ++j)
        for (int i = 0; i <= 4; ++i) m.x.push_back(1000.0 + i), m.y.push_back(2000.0 + j);
    auto n = [](int i, int j) { return j * 5 + i; };
    m.faces = {{n(0, 0), n(2, 0), n(2, 2), n(0, 2)},
               {n(2, 0), n(3, 0), n(3, 1), n(2, 1)},
               {n(3, 0), n(4, 0), n(4, 1), n(3, 1)},
               {n(2, 1), n(3, 1), n(3, 2), n(2, 2)},
               {n(3, 1), n(4, 1), n(4, 2), n(3, 2)}};
    m.zb = {10, 11, 12, 13, 14};
    m.times = {0, 1.5};
    m.zs = {{-99999, 11.5, -99999, 12.0, 15}, {10.25, 12, 13, 14, 15}};
    return m;
}

TEST_F(Mesh, HandWrittenQuadtreeReadsAsWritten) {
    writeHandMesh(goodMesh(), path("good.nc"));
    hc::ingest::Options o;
    o.input = path("good.nc");
    o.sourceSrs = "EPSG:32632";
    hc::ingest::LoadReport rep;
    hc::ingest::ingestUgridToFile(o, path("g.hcg"), rep);
    const Grid g = hc::readGrid(path("g.hcg"), nullptr, 0);
    ASSERT_EQ(g.cellCount(), 5u);
    EXPECT_EQ(g.finestCellM, 1.0);
    EXPECT_EQ(g.rotationDeg, 0.0);
    EXPECT_EQ(g.originWorldX, 1000.0);
    EXPECT_EQ(g.originWorldY, 2000.0);
    EXPECT_EQ(g.crsName, "WGS 84 / UTM zone 32N (EPSG:32632)") << "--s_srs names the CRS of a mesh that has none";
    ASSERT_EQ(g.steps.size(), 2u);
    EXPECT_EQ(g.steps[1].timeS, 5400.0) << "1.5 hours since ...";
    // Step 0: faces 1 (11.5 over 11) and 3 (12 over 13: below the terrain, dry) and 4 (15 over 14).
    EXPECT_EQ(g.steps[0].wetCells, 2u);
    EXPECT_EQ(g.steps[1].wetCells, 5u);
    const auto c = g.locate(2.5, 0.5);
    ASSERT_TRUE(c);
    EXPECT_EQ(g.values[0][*c], 11.0f);
    EXPECT_EQ(g.values[1][*c], 0.5f);
    const auto big = g.locate(1.0, 1.0);
    ASSERT_TRUE(big);
    EXPECT_EQ(g.level(*big), 1);
    EXPECT_EQ(g.values[1][*big], 0.0f) << "a fill value is dry";
}

// A further face variable over time becomes a step layer: its values on the wet faces, 0 on dry ones, a fill value on a
// wet face taken as 0 and counted in a warning; and it goes out to a mesh and back with the same values.
TEST_F(Mesh, FaceLayersBecomeStepLayers) {
    HandMesh m = goodMesh();
    m.vel = {{0.1, 0.2, 0.3, 0.4, -99999}, {1.1, 1.2, 1.3, 1.4, 1.5}};
    writeHandMesh(m, path("vel.nc"));
    hc::ingest::Options o;
    o.input = path("vel.nc");
    o.faceLayerVars = {"vel"};
    hc::ingest::LoadReport rep;
    hc::ingest::ingestUgridToFile(o, path("v.hcg"), rep);
    ASSERT_EQ(rep.warnings.size(), 2u) << "no CRS, and one fill value on a wet face";
    EXPECT_NE(rep.warnings[1].find("vel is a fill value on 1 wet face"), std::string::npos) << rep.warnings[1];
    const Grid g0 = hc::readGrid(path("v.hcg"), nullptr, 0), g1 = hc::readGrid(path("v.hcg"), nullptr, 1);
    ASSERT_EQ(g0.layers.size(), 3u);
    EXPECT_EQ(g0.layers[2].name, "vel");
    EXPECT_EQ(g0.layers[2].units, "m s-1");
    auto at = [](const Grid& g, double x, double y) { return g.values[2][*g.locate(x, y)]; };
    EXPECT_EQ(at(g0, 2.5, 0.5), 0.2f) << "face 1, wet in step 0";
    EXPECT_EQ(at(g0, 1.0, 1.0), 0.0f) << "face 0, dry in step 0: no value stored";
    EXPECT_EQ(at(g0, 3.5, 1.5), 0.0f) << "face 4, wet in step 0 with a fill value";
    EXPECT_EQ(at(g1, 1.0, 1.0), 1.1f);
    EXPECT_EQ(at(g1, 3.5, 1.5), 1.5f);
    // Out and back: the layer keeps its name, units and values.
    hc::exporting::writeUgrid(path("v.hcg"), path("out.nc"));
    o.input = path("out.nc");
    hc::ingest::ingestUgridToFile(o, path("back.hcg"), rep);
    for (size_t k = 0; k < 2; ++k) {
        const Grid a = hc::readGrid(path("v.hcg"), nullptr, k), b = hc::readGrid(path("back.hcg"), nullptr, k);
        EXPECT_EQ(a.layers[2].units, b.layers[2].units);
        EXPECT_EQ(a.values[2], b.values[2]) << "step " << k;
    }
    // Names that are not further variables are refused.
    for (const std::string bad : {"zs", "water_depth", "nosuch"}) {
        o.input = path("vel.nc");
        o.faceLayerVars = {bad};
        EXPECT_THROW(hc::ingest::ingestUgridToFile(o, path("bad.hcg"), rep), hc::Error) << bad;
        EXPECT_FALSE(fs::exists(path("bad.hcg")));
    }
}

// A step layer after water_depth (velocity, ...) is a field of the wet cells (surface.h, Layer::WaterCells): a
// constant on every wet cell is exactly that constant wherever water is drawn, undefined where it is not (dry
// neighbours bring no zeros in), and the exact evaluator, its batch path and brute force agree on a varying one.
TEST_F(Mesh, StepLayerIsAFieldOfTheWetCells) {
    HC_REQUIRE_DATA(dem, "lidar1m_minnesota_utm15.tif");
    lidarScenario(dem, path("flood.hcg"));
    Grid g = hc::readGrid(path("flood.hcg"), nullptr, 1);
    const std::vector<float> depth = g.values[1];  // a copy: values grows below
    g.layers.push_back({"vel", "m s-1"});
    g.values.emplace_back(g.cellCount(), 0.0f);
    for (size_t i = 0; i < g.cellCount(); ++i)
        if (depth[i] > 0) g.values[2][i] = 0.75f;
    const auto lists = hc::influence::buildInfluenceLists(g, hc::influence::KernelParams{}, 0, false);
    const hc::influence::SurfaceEvaluator e(g, lists);
    const auto vel = hc::influence::Layer::byName(g, "vel"), water = hc::influence::Layer::byName(g, "water_surface");
    ASSERT_EQ(vel.kind, hc::influence::Layer::WaterCells);
    std::vector<std::array<double, 2>> pts;
    for (int i = 0; i < 400; ++i) pts.push_back({2.5 + 0.99 * i, 3.0 + 0.97 * ((i * 53) % 400)});
    size_t drawn = 0, dry = 0;
    for (const auto& p : pts) {
        const auto w = e.value(p[0], p[1], water), v = e.value(p[0], p[1], vel);
        ASSERT_EQ(w.has_value(), v.has_value()) << p[0] << "," << p[1];
        if (v) {
            EXPECT_EQ(*v, 0.75)
                << "a constant on the wet cells stays exactly constant (values relative to a wet cell's)";
        }
        drawn += v.has_value();
        dry += !v.has_value();
    }
    EXPECT_GT(drawn, 20u);
    EXPECT_GT(dry, 20u);
    // A varying layer: exact = batch = brute force (1e-9 relative: sums in another order).
    for (size_t i = 0; i < g.cellCount(); ++i) {
        double x = 0, y = 0;
        g.cellCenterLocal(i, x, y);
        g.values[2][i] = depth[i] > 0 ? float(0.2 + 0.003 * x + 0.001 * y) : 0.0f;
    }
    const hc::influence::SurfaceEvaluator e2(g, lists);
    const auto batch = e2.values(pts, vel, 2);
    for (size_t i = 0; i < pts.size(); i += 7) {
        const auto v = e2.value(pts[i][0], pts[i][1], vel), b = e2.valueBruteForce(pts[i][0], pts[i][1], vel);
        ASSERT_EQ(v.has_value(), b.has_value());
        ASSERT_EQ(v.has_value(), batch[i].has_value());
        if (v) {
            EXPECT_NEAR(*v, *b, 1e-9 * std::abs(*b));
            EXPECT_EQ(*v, *batch[i]);
        }
    }
}

// --color-by a step layer: every water hit is coloured by the layer's exact value there (Frame::colorLayerValue, to
// float rounding of the hit position), dry hits carry none; an unknown layer and an out-of-core scene are refused.
TEST_F(Mesh, ColorByAStepLayerShowsItsExactValuesOnTheWater) {
    HC_REQUIRE_DATA(dem, "lidar1m_minnesota_utm15.tif");
    lidarScenario(dem, path("flood.hcg"));
    Grid g = hc::readGrid(path("flood.hcg"), nullptr, 2);
    const std::vector<float> depth = g.values[1];
    g.layers.push_back({"vel", "m s-1"});
    g.values.emplace_back(g.cellCount(), 0.0f);
    for (size_t i = 0; i < g.cellCount(); ++i) g.values[2][i] = depth[i] > 0 ? std::sqrt(9.81f * depth[i]) : 0.0f;
    g.steps.at(2).layerMin = {*std::min_element(depth.begin(), depth.end()), 0.0f};  // the legend's range (step table)
    g.steps.at(2).layerMax = {*std::max_element(depth.begin(), depth.end()), 9.0f};
    const auto lists = hc::influence::buildInfluenceLists(g, hc::influence::KernelParams{}, 0, false);
    const hc::render::Scene scene(g, lists);
    const hc::render::Camera cam = hc::render::overviewCamera(scene, 200, 120);
    hc::render::RenderOptions opt;
    opt.texelsPerSide = 256;
    opt.colorLayer = "vel";
    hc::render::Timings t;
    const hc::render::Frame f = hc::render::renderFrame(scene, cam, opt, t);
    ASSERT_EQ(f.colorLayerValue.size(), f.distanceM.size());
    const hc::influence::SurfaceEvaluator e(g, lists);
    const auto vel = hc::influence::Layer::byName(g, "vel");
    size_t water = 0, dry = 0;
    for (size_t i = 0; i < f.distanceM.size(); ++i) {
        if (!std::isfinite(f.distanceM[i]) || f.wall[i] != 0) continue;
        if (f.waterDepthM[i] > 0) {
            const auto v = e.value(f.posX[i], f.posY[i], vel);
            // The hit lies on the drawn water; its float position may straddle the water's edge by a rounding.
            if (!v) continue;
            ASSERT_FALSE(std::isnan(f.colorLayerValue[i])) << i;
            EXPECT_NEAR(f.colorLayerValue[i], *v, 1e-4 * std::max(1.0, *v));
            ++water;
        } else {
            EXPECT_TRUE(std::isnan(f.colorLayerValue[i])) << "dry land has no velocity";
            ++dry;
        }
    }
    EXPECT_GT(water, 200u);
    EXPECT_GT(dry, 200u);
    opt.colorLayer = "nosuch";
    EXPECT_THROW(hc::render::renderFrame(scene, cam, opt, t), hc::Error);
}

// A simulation's first time is often dry: a step with no wet cell reads (readGrid, readGridStep) as every cell dry.
// Regression: fuzz_ugrid's first finding (fuzz/corpus/ugrid/finding_dry_step), a memcpy from an empty step's section
// into an empty vector's null data() (undefined behaviour that UBSan reports).
TEST_F(Mesh, DryStepsRead) {
    HandMesh m = goodMesh();
    m.zs[0].assign(m.zs[0].size(), -99999);  // step 0: every level a fill value
    writeHandMesh(m, path("dry.nc"));
    hc::ingest::Options o;
    o.input = path("dry.nc");
    hc::ingest::LoadReport rep;
    hc::ingest::ingestUgridToFile(o, path("d.hcg"), rep);
    Grid g = hc::readGrid(path("d.hcg"), nullptr, 0);
    ASSERT_EQ(g.steps.size(), 2u);
    EXPECT_EQ(g.steps[0].wetCells, 0u);
    EXPECT_EQ(std::count(g.values[1].begin(), g.values[1].end(), 0.0f), long(g.cellCount()));
    hc::readGridStep(path("d.hcg"), g, 1);
    EXPECT_EQ(g.steps[1].wetCells, 5u);
    hc::readGridStep(path("d.hcg"), g, 0);
    EXPECT_EQ(std::count(g.values[1].begin(), g.values[1].end(), 0.0f), long(g.cellCount()));
}

// A face whose terrain is a fill value (or NaN) is a hole: no cell there, its neighbours as they are.
TEST_F(Mesh, FacesWithoutTerrainAreHoles) {
    HandMesh m = goodMesh();
    m.zb[0] = std::nan("");  // the large face
    m.zb[3] = -99999;        // one small face: the terrain's fill value
    m.zbFill = -99999;
    writeHandMesh(m, path("holes.nc"));
    hc::ingest::Options o;
    o.input = path("holes.nc");
    hc::ingest::LoadReport rep;
    hc::ingest::ingestUgridToFile(o, path("h.hcg"), rep);
    const Grid g = hc::readGrid(path("h.hcg"), nullptr, 1);
    auto at = [&](double wx, double wy) {  // the cell at a world point (the origin follows the faces kept)
        double x = 0, y = 0;
        g.worldToLocal(wx, wy, x, y);
        return g.locate(x, y);
    };
    EXPECT_EQ(g.cellCount(), 3u);
    EXPECT_FALSE(at(1001.0, 2001.0)) << "the NaN face is a hole";
    EXPECT_FALSE(at(1002.5, 2001.5)) << "the fill-value face is a hole";
    ASSERT_TRUE(at(1003.5, 2001.5));
    EXPECT_EQ(g.values[0][*at(1003.5, 2001.5)], 14.0f);
    EXPECT_EQ(g.steps[1].wetCells, 3u) << "the holes' water is not counted";
}

TEST_F(Mesh, MeshesThatAreNoQuadtreeAreRefused) {
    auto refused = [&](HandMesh m, const std::string& what) {
        SCOPED_TRACE(what);
        const std::string nc = path("bad.nc");
        fs::remove(nc);
        fs::remove(path("bad.hcg"));
        writeHandMesh(m, nc);
        hc::ingest::Options o;
        o.input = nc;
        hc::ingest::LoadReport rep;
        try {
            hc::ingest::ingestUgridToFile(o, path("bad.hcg"), rep);
            ADD_FAILURE() << "accepted";
        } catch (const hc::Error& e) {
            EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
        }
        EXPECT_FALSE(fs::exists(path("bad.hcg")));
    };
    HandMesh m = goodMesh();
    m.faces[2][3] = -1;
    refused(m, "face 2 has 3 nodes");
    m = goodMesh();
    m.x[4] = 1004.5, m.x[9] = 1004.5;  // faces 2 and 4 become 1.5 x 1 rectangles
    refused(m, "face 2 is not a square");
    m = goodMesh();
    for (int j = 0; j <= 2; ++j) m.x[size_t(j * 5 + 0)] = 999.0;  // face 0 becomes 3 x 2: not square either
    refused(m, "face 0 is not a square");
    m = goodMesh();
    m.times = {0, -1};
    refused(m, "do not increase");
    // A side of 3 finest faces: a square, but not a power-of-two multiple.
    HandMesh t;
    t.x = {0, 1, 1, 0, 1, 4, 4, 1};
    t.y = {0, 0, 1, 1, 0, 0, 3, 3};
    t.faces = {{0, 1, 2, 3}, {4, 5, 6, 7}};
    t.zb = {1, 2};
    refused(t, "not a power-of-two multiple");
    // Two faces of side 2 three finest faces apart (a face of side 1 between them): one of them is not aligned to
    // its size, whatever the origin.
    HandMesh a;
    a.x = {0, 2, 2, 0, 2, 3, 3, 2, 3, 5, 5, 3};
    a.y = {0, 0, 2, 2, 0, 0, 1, 1, 0, 0, 2, 2};
    a.faces = {{0, 1, 2, 3}, {4, 5, 6, 7}, {8, 9, 10, 11}};
    a.zb = {1, 2, 3};
    refused(a, "not aligned to its own size");
    // One face turned against the other.
    HandMesh r;
    const double c = std::cos(0.3), s = std::sin(0.3);
    r.x = {0, 1, 1, 0, 5, 5 + c, 5 + c - s, 5 - s};
    r.y = {0, 0, 1, 1, 0, s, s + c, c};
    r.faces = {{0, 1, 2, 3}, {4, 5, 6, 7}};
    r.zb = {1, 2};
    refused(r, "share one orientation");
}

}  // namespace
