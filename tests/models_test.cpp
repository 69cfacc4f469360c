// Flood model results (docs/models.md): model files written as the models write them, from real rasters (the buscot
// floodplain DEM), read back by hc-ingest's readers: a quadtree with float32 node coordinates fitted to its lattice, a
// SFINCS regular map taken cell by cell, a triangle mesh sampled exactly as the model defines its fields (the same mesh
// as UGRID and as Selafin giving the same grid), a mesh's water on a DEM, and files that are wrong refused by name.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>

#include "heightcast/core/error.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/ingest/ingest.h"
#include "heightcast/ingest/mesh.h"
#include "heightcast/ingest/model.h"
#include "model_files.h"
#include "temp_dir.h"
#include "test_data.h"

namespace {

namespace fs = std::filesystem;
using hc::Grid;
using hc::test::NcWriter;

class Models : public hc::test::TempDirTest {
protected:
    Models() : TempDirTest("hc_models_") {}
};

hc::ingest::BuildSummary ingestModel(const std::string& in, const std::string& out, hc::ingest::Options o = {}) {
    o.input = in;
    hc::ingest::LoadReport r;
    return hc::ingest::ingestModelToFile(o, out, r);
}

// The cell of `g` at world point (x, y), if any.
std::optional<uint32_t> cellAt(const Grid& g, double x, double y) {
    double lx = 0, ly = 0;
    g.worldToLocal(x, y, lx, ly);
    return g.locate(lx, ly);
}

// A SFINCS quadtree map written from a real grid: every cell a face of four nodes of its own, the grid turned by
// `deg` about (x0, y0) and stored as float32 (0.5 m apart at y = 5e6), zb per face, zs per step (-99999 where dry).
void writeQuadtreeMap(const std::string& gridPath, const std::string& out, double deg, double x0, double y0) {
    const Grid g = hc::readGrid(gridPath);
    const double c = std::cos(deg * M_PI / 180), s = std::sin(deg * M_PI / 180);
    std::vector<double> nx, ny, conn, zb(g.values[0].begin(), g.values[0].end());
    for (size_t i = 0; i < g.cellCount(); ++i) {
        double cx = 0, cy = 0;
        g.cellCenterLocal(i, cx, cy);
        const double h = g.cellSizeM(i) / 2;
        const double corners[4][2] = {{cx - h, cy - h}, {cx + h, cy - h}, {cx + h, cy + h}, {cx - h, cy + h}};
        for (const auto& p : corners) {
            nx.push_back(double(float(x0 + c * p[0] - s * p[1]))),
                ny.push_back(double(float(y0 + s * p[0] + c * p[1])));
            conn.push_back(double(nx.size() - 1));
        }
    }
    std::vector<double> times, zs;
    for (size_t k = 0; k < g.steps.size(); ++k) {
        const Grid at = hc::readGrid(gridPath, nullptr, k);
        times.push_back(at.steps[k].timeS / 3600);
        for (size_t i = 0; i < at.cellCount(); ++i)
            zs.push_back(at.values[1][i] > 0 ? double(at.values[0][i]) + double(at.values[1][i]) : -99999.0);
    }
    NcWriter w(out);
    ASSERT_TRUE(w.ok());
    w.globalText("Producer", "SFINCS model: Super-Fast INundation of CoastS");  // as SFINCS writes it
    auto nodes = w.dim("nmesh2d_node", nx.size()), faces = w.dim("nmesh2d_face", g.cellCount()),
         four = w.dim("max_nmesh2d_face_nodes", 4);
    auto time = w.dim("time", times.size());
    auto topo = w.array("mesh2d", {}, GDT_Int32, {},
                        {{"cf_role", "mesh_topology"},
                         {"node_coordinates", "mesh2d_node_x mesh2d_node_y"},
                         {"face_node_connectivity", "mesh2d_face_nodes"},
                         {"face_dimension", "nmesh2d_face"}});
    w.intAttr(topo, "topology_dimension", 2);
    w.array("mesh2d_node_x", {nodes}, GDT_Float32, nx);
    w.array("mesh2d_node_y", {nodes}, GDT_Float32, ny);
    auto fn = w.array("mesh2d_face_nodes", {faces, four}, GDT_Int32, conn, {}, -999.0);
    w.intAttr(fn, "start_index", 0);
    w.array("zb", {faces}, GDT_Float32, zb, {{"location", "face"}, {"mesh", "mesh2d"}}, -99999.0);
    w.array("time", {time}, GDT_Float64, times, {{"units", "hours since 2020-01-01 00:00:00"}});
    w.array("zs", {time, faces}, GDT_Float64, zs, {{"location", "face"}, {"mesh", "mesh2d"}}, -99999.0);
}

// A real flood scenario on the buscot floodplain (50 m pixels, 67.7-83.8 m): bathtub levels at 0, 1 and 2 hours, cells
// of 50, 100 and 200 m (as the SFINCS quadtree).
std::string buscotScenario(const std::string& dem, const std::string& out) {
    hc::ingest::Options o;
    o.input = dem;
    o.sourceSrs = "local";
    o.maxCellM = 200;
    o.water = hc::ingest::WaterSource::Level;
    o.waterLevelsM = {69.5, 70.5, 71.5};
    o.timesS = {0, 3600, 7200};
    hc::ingest::LoadReport r;
    hc::ingest::ingestToFile(o, out, r);
    return out;
}

// The SFINCS quadtree: nodes stored as float32 at y = 5e6 scatter by 0.5 m, so no face is a square to double
// precision; the lattice fitted to every node gives back every cell, its elevation and each step's depth.
TEST_F(Models, Float32QuadtreeFitsItsLatticeCellForCell) {
    HC_REQUIRE_DATA(dem, "buscot_50m.asc");
    const std::string src = buscotScenario(dem, path("src.hcg"));
    writeQuadtreeMap(src, path("sfincs_quadtree_map.nc"), 27.0, 450000.0, 5000000.0);
    ASSERT_EQ(hc::ingest::modelFormatOf(path("sfincs_quadtree_map.nc")), "SFINCS quadtree map (UGRID-1.0)");
    const hc::ingest::BuildSummary b = ingestModel(path("sfincs_quadtree_map.nc"), path("q.hcg"));
    const Grid a = hc::readGrid(src), q = hc::readGrid(path("q.hcg"));
    ASSERT_EQ(q.codes, a.codes) << "one cell per face, each where the source grid had it";
    std::set<int> levels;
    for (size_t i = 0; i < q.cellCount(); ++i) levels.insert(q.level(i));
    EXPECT_EQ(levels, (std::set<int>{0, 1, 2})) << "faces of 50, 100 and 200 m";
    EXPECT_EQ(q.values[0], a.values[0]);
    // The fit: 50 m, 27 degrees; the origin within the nodes' rounding (0.25 m) of where it was put.
    // The finest side to float32's rounding over the mesh: 0.25 m over 3.8 km is 6.6e-5 of 50 m at worst.
    EXPECT_NEAR(q.finestCellM, a.finestCellM, 3.3e-3);
    // The turn to float32's rounding over the mesh: 0.25 m at either end of 3.8 km is 4e-3 degrees at worst.
    EXPECT_NEAR(q.rotationDeg, 27.0, 1e-3);
    EXPECT_NEAR(q.originWorldX, 450000.0, 0.25);
    EXPECT_NEAR(q.originWorldY, 5000000.0, 0.25);
    // Every node lies within float32's rounding of the lattice (0.5 m apart: at most 0.25 m each way, plus the fit's
    // own error), and some lie off it: the default tolerance is 2 ulps, 1 m.
    EXPECT_GT(q.stats.latticeResidualM, 0.05);
    EXPECT_LE(q.stats.latticeResidualM, 0.5);
    EXPECT_EQ(
        q.stats.sourceFormat.rfind("SFINCS quadtree map (UGRID-1.0): " + std::to_string(a.cellCount()) + " faces", 0),
        0u)
        << q.stats.sourceFormat << ": hc-info names the model, the format and the faces";
    ASSERT_EQ(b.steps.size(), 3u);
    for (size_t k = 0; k < 3; ++k) {
        const Grid x = hc::readGrid(src, nullptr, k), y = hc::readGrid(path("q.hcg"), nullptr, k);
        EXPECT_EQ(y.stepTimeS(), x.stepTimeS());
        ASSERT_EQ(y.steps[k].wetCells, x.steps[k].wetCells);
        for (size_t i = 0; i < x.cellCount();
             ++i)  // level = elevation + depth in double, minus elevation: the depth to a rounding
            ASSERT_NEAR(y.values[1][i], x.values[1][i], 1e-5f * std::max(1.0f, x.values[1][i]))
                << "step " << k << " cell " << i;
    }
    // A tolerance tighter than the file's own precision refuses the mesh, naming the face and its residual.
    hc::ingest::Options tight;
    tight.meshToleranceM = 0.01;
    try {
        ingestModel(path("sfincs_quadtree_map.nc"), path("tight.hcg"), tight);
        ADD_FAILURE() << "accepted";
    } catch (const hc::Error& e) {
        EXPECT_NE(std::string(e.what()).find("do not fit one lattice: a node of face "), std::string::npos) << e.what();
    }
    EXPECT_FALSE(fs::exists(path("tight.hcg")));
}

// A SFINCS regular map (2-D x/y of a turned 50 m grid as float32, zb and msk as (n, m), zs over time) is taken cell by
// cell: every active cell where its centre says, with its own bed and each step's depth; inactive cells are holes.
// The same map with zs stored (time, m, n) reads the same.
TEST_F(Models, SfincsRegularMapIsTakenCellByCell) {
    HC_REQUIRE_DATA(dem, "buscot_50m.asc");
    const hc::test::RasterValues r = hc::test::readRasterValues(dem);
    ASSERT_FALSE(r.v.empty());
    const size_t n = r.height, m = r.width;
    const double deg = 30, c = std::cos(deg * M_PI / 180), s = std::sin(deg * M_PI / 180), x0 = 300000, y0 = 5700000;
    std::vector<double> x, y, zb, msk;
    for (size_t j = 0; j < n; ++j)  // row j = 0 the southern-most, as SFINCS counts n
        for (size_t i = 0; i < m; ++i) {
            const double u = (double(i) + 0.5) * 50, v = (double(j) + 0.5) * 50;
            x.push_back(double(float(x0 + c * u - s * v))), y.push_back(double(float(y0 + s * u + c * v)));
            zb.push_back(r.at(i, n - 1 - j));
            msk.push_back(i < 10 && j < 10 ? 0 : 1);  // a corner outside the model's domain
        }
    const std::vector<double> levels = {70.0, 72.0};
    for (bool transposed : {false, true}) {
        SCOPED_TRACE(transposed ? "zs (time, m, n)" : "zs (time, n, m)");
        const std::string nc = path(transposed ? "t_map.nc" : "sfincs_map.nc");
        {
            NcWriter w(nc);
            auto dn = w.dim("n", n), dm = w.dim("m", m), time = w.dim("time", levels.size());
            w.array("x", {dn, dm}, GDT_Float32, x, {{"units", "m"}}, -99999.0);
            w.array("y", {dn, dm}, GDT_Float32, y, {{"units", "m"}}, -99999.0);
            w.array("zb", {dn, dm}, GDT_Float32, zb, {}, -99999.0);
            w.array("msk", {dn, dm}, GDT_Float32, msk);
            w.array("crs", {}, GDT_Int32, {}, {{"epsg_code", "EPSG:32630"}});
            w.array("time", {time}, GDT_Float64, {0, 1800}, {{"units", "seconds since 2021-06-01 00:00:00"}});
            std::vector<double> zs;
            for (double level : levels)
                for (size_t a = 0; a < (transposed ? m : n); ++a)
                    for (size_t b = 0; b < (transposed ? n : m); ++b) {
                        const size_t cell = transposed ? b * m + a : a * m + b;
                        zs.push_back(level > zb[cell] ? level : zb[cell]);  // SFINCS writes zs = zb where dry
                    }
            w.array("zs", transposed ? std::vector{time, dm, dn} : std::vector{time, dn, dm}, GDT_Float32, zs, {},
                    -99999.0);
        }
        ASSERT_EQ(hc::ingest::modelFormatOf(nc), "SFINCS regular map (NetCDF)");
        const hc::ingest::BuildSummary b = ingestModel(nc, path("r.hcg"));
        EXPECT_EQ(b.cellCount, n * m - 100);
        EXPECT_NEAR(b.shape.rotationDeg, deg, 1e-3);  // float32 centres: as for the quadtree above
        EXPECT_NE(b.shape.crsName.find("32630"), std::string::npos) << b.shape.crsName;
        for (size_t k = 0; k < levels.size(); ++k) {
            const Grid g = hc::readGrid(path("r.hcg"), nullptr, k);
            for (size_t cell = 0; cell < x.size(); ++cell) {
                const auto at = cellAt(g, x[cell], y[cell]);
                if (msk[cell] == 0) {
                    ASSERT_FALSE(at) << "an inactive cell is a hole";
                    continue;
                }
                ASSERT_TRUE(at) << cell;
                ASSERT_EQ(g.values[0][*at], float(zb[cell]));
                const double depth =
                    levels[k] > double(float(zb[cell])) ? double(float(levels[k])) - double(float(zb[cell])) : 0.0;
                ASSERT_NEAR(g.values[1][*at], depth, 1e-5) << "cell " << cell << " step " << k;
            }
        }
    }
}

// A triangle mesh with the bed and levels at its nodes (TELEMAC, ANUGA) is sampled as the model defines the fields:
// linear over each triangle. With --tolerance 0 no cell merges, so every cell is one pixel, and its value is the
// interpolation at its centre; wet where the interpolated level is above the interpolated bed.
TEST_F(Models, TriangleMeshIsSampledLinearlyOverItsTriangles) {
    HC_REQUIRE_DATA(dem, "buscot_50m.asc");
    const hc::test::RasterValues r = hc::test::readRasterValues(dem);
    const hc::test::TriMesh tm = hc::test::triangulate(r, 3, 1000.0, 9000.0, 50.0);
    std::vector<double> level(tm.bed.size());
    for (size_t i = 0; i < level.size(); ++i) level[i] = 70.0 + 0.0004 * (tm.x[i] - 1000.0);  // a sloping water surface
    hc::test::writeSelafin(tm, {0.0, 600.0}, {tm.bed, level}, path("mesh.slf"));
    ASSERT_EQ(hc::ingest::modelFormatOf(path("mesh.slf")), "TELEMAC Selafin");
    hc::ingest::Options o;
    o.toleranceM = 0;
    o.minCellM = 25.0;
    ingestModel(path("mesh.slf"), path("s.hcg"), o);
    const Grid g = hc::readGrid(path("s.hcg"), nullptr, 1);
    size_t wet = 0, checked = 0;
    for (size_t i = 0; i < g.cellCount(); ++i) {
        ASSERT_EQ(g.level(i), 0) << "tolerance 0: no merge";
        double lx = 0, ly = 0, wx = 0, wy = 0;
        g.cellCenterLocal(i, lx, ly);
        g.localToWorld(lx, ly, wx, wy);
        const double z = hc::test::interpolate(tm, tm.bed, wx, wy), l = hc::test::interpolate(tm, level, wx, wy);
        ASSERT_FALSE(std::isnan(z)) << "a cell outside the mesh at " << wx << "," << wy;
        // float32 bed values (Selafin single precision) interpolated in double, stored as float32: a few ulps of 80 m.
        ASSERT_NEAR(g.values[0][i], z, 5e-5) << wx << "," << wy;
        const double depth = l - z;
        if (depth > 1e-4) {
            ASSERT_NEAR(g.values[1][i], depth, 1e-4);
            ++wet;
        }
        if (depth < -1e-4) {
            ASSERT_EQ(g.values[1][i], 0.0f);
        }
        ++checked;
    }
    // The mesh's hull: every pixel centre inside (triangles of 150 m over 25 m pixels), no other.
    const size_t inside = size_t((double(tm.cols - 1) * 150.0) / 25.0) * size_t((double(tm.rows - 1) * 150.0) / 25.0);
    EXPECT_EQ(checked, inside);
    EXPECT_GT(wet, checked / 10);
    EXPECT_LT(wet, checked - checked / 10);

    // The same mesh and fields as a UGRID map with node variables: the same cells and values, bit for bit.
    {
        NcWriter w(path("mesh.nc"));
        auto nodes = w.dim("nNodes", tm.x.size()), faces = w.dim("nFaces", tm.tris.size()), three = w.dim("three", 3),
             time = w.dim("time", 2);
        auto topo =
            w.array("mesh", {}, GDT_Int32, {},
                    {{"cf_role", "mesh_topology"}, {"node_coordinates", "nx ny"}, {"face_node_connectivity", "fn"}});
        w.intAttr(topo, "topology_dimension", 2);
        std::vector<double> f32x, f32y, conn, bed32, lv32;
        for (size_t i = 0; i < tm.x.size(); ++i)  // Selafin stored them as float32: so do we here
            f32x.push_back(float(tm.x[i])), f32y.push_back(float(tm.y[i])), bed32.push_back(float(tm.bed[i]));
        for (double v : tm.bed) lv32.push_back(float(v));
        for (double v : level) lv32.push_back(float(v));
        for (const auto& t : tm.tris) conn.insert(conn.end(), {double(t[0]), double(t[1]), double(t[2])});
        w.array("nx", {nodes}, GDT_Float64, f32x);
        w.array("ny", {nodes}, GDT_Float64, f32y);
        w.array("fn", {faces, three}, GDT_Int32, conn);
        w.array("mesh2d_node_z", {nodes}, GDT_Float64, bed32, {{"location", "node"}});
        w.array("time", {time}, GDT_Float64, {0, 600}, {{"units", "seconds since 2000-01-01"}});
        w.array("mesh2d_s1", {time, nodes}, GDT_Float64, lv32, {{"location", "node"}});
    }
    // The same mesh as an SMS .2dm (terrain only; full-precision coordinates and bed): the same cells, and elevations
    // within float32's rounding of the Selafin ones (which stored both as float32).
    hc::test::writeTwoDm(tm, path("mesh.2dm"));
    ASSERT_EQ(hc::ingest::modelFormatOf(path("mesh.2dm")), "SMS/TUFLOW .2dm mesh (terrain only)");
    ingestModel(path("mesh.2dm"), path("t.hcg"), o);
    {
        const Grid a = hc::readGrid(path("s.hcg")), t = hc::readGrid(path("t.hcg"));
        ASSERT_EQ(a.codes, t.codes);
        for (size_t i = 0; i < a.cellCount(); ++i) ASSERT_NEAR(a.values[0][i], t.values[0][i], 5e-5) << i;
    }
    o.terrainVar = "mesh2d_node_z", o.waterSurfaceVar = "mesh2d_s1";
    ingestModel(path("mesh.nc"), path("u.hcg"), o);
    for (size_t k = 0; k < 2; ++k) {
        const Grid a = hc::readGrid(path("s.hcg"), nullptr, k), b = hc::readGrid(path("u.hcg"), nullptr, k);
        ASSERT_EQ(a.codes, b.codes);
        EXPECT_EQ(a.values, b.values) << "step " << k;
    }
}

// DEM + model results: the terrain from the raster, the water levels from the mesh, depth = level - terrain on every
// pixel the mesh covers; pixels no face covers are dry, however low.
TEST_F(Models, WaterMeshFloodsTheDem) {
    HC_REQUIRE_DATA(dem, "buscot_50m.asc");
    const hc::test::RasterValues r = hc::test::readRasterValues(dem);
    // The raster's own georeferencing: its west and north edges.
    GDALAllRegister();
    double gt[6];
    {
        std::unique_ptr<GDALDataset> ds(GDALDataset::Open(dem.c_str(), GDAL_OF_RASTER));
        ds->GetGeoTransform(gt);
    }
    hc::test::RasterValues west = r;  // the mesh covers the western half: nodes every 4th pixel up to column 36
    west.width = 37;
    west.v.clear();
    for (size_t j = 0; j < r.height; ++j)
        for (size_t i = 0; i < west.width; ++i) west.v.push_back(r.at(i, j));
    // Nodes 10 m off the pixel centres: no pixel centre lies on a triangle's edge, where either triangle may hold it.
    const hc::test::TriMesh tm = hc::test::triangulate(west, 4, gt[0] + 10, gt[3] - 10, 50.0);
    const std::vector<double> level(tm.x.size(), 72.0);
    hc::test::writeSelafin(tm, {0.0}, {level}, path("w.slf"));
    hc::ingest::Options o;
    o.input = dem;
    o.sourceSrs = "local";
    o.waterMesh = path("w.slf");
    o.toleranceM = 0;
    hc::ingest::LoadReport rep;
    hc::ingest::ingestToFile(o, path("d.hcg"), rep);
    const Grid g = hc::readGrid(path("d.hcg"), nullptr, 0);
    size_t wet = 0;
    for (size_t i = 0; i < g.cellCount(); ++i) {
        double lx = 0, ly = 0, wx = 0, wy = 0;
        g.cellCenterLocal(i, lx, ly);
        g.localToWorld(lx, ly, wx, wy);
        std::array<size_t, 3> t;
        double u = 0, v = 0;
        const bool inMesh = hc::test::triangleAt(tm, wx, wy, t, u, v);
        // The model is dry on a triangle whose three nodes' bed is at or above the level: the DEM below it stays dry.
        const bool modelWet = inMesh && (tm.bed[t[0]] < 72.0 || tm.bed[t[1]] < 72.0 || tm.bed[t[2]] < 72.0);
        const double z = g.values[0][i], expect = modelWet && 72.0 > z ? 72.0 - z : 0.0;
        ASSERT_NEAR(g.values[1][i], expect, 1e-4) << wx << "," << wy << (inMesh ? " in the mesh" : " outside it");
        wet += g.values[1][i] > 0;
    }
    EXPECT_GT(wet, 100u);
}

// A fill value the file does not declare (-9999 on the bed of a face): said, with the fix; --nodata -9999 makes it a
// hole.
TEST_F(Models, UndeclaredFillValuesAreSaidAndNodataMakesThemHoles) {
    {
        NcWriter w(path("fill.nc"));
        auto nodes = w.dim("nNodes", 9), faces = w.dim("nFaces", 4), four = w.dim("four", 4), time = w.dim("time", 1);
        auto topo =
            w.array("mesh", {}, GDT_Int32, {},
                    {{"cf_role", "mesh_topology"}, {"node_coordinates", "nx ny"}, {"face_node_connectivity", "fn"}});
        w.intAttr(topo, "topology_dimension", 2);
        w.array("nx", {nodes}, GDT_Float64, {0, 10, 20, 0, 10, 20, 0, 10, 20});
        w.array("ny", {nodes}, GDT_Float64, {0, 0, 0, 10, 10, 10, 20, 20, 20});
        w.array("fn", {faces, four}, GDT_Int32, {0, 1, 4, 3, 1, 2, 5, 4, 3, 4, 7, 6, 4, 5, 8, 7});
        w.array("zb", {faces}, GDT_Float64, {1, -9999, 3, 4});
        w.array("time", {time}, GDT_Float64, {0}, {{"units", "seconds since 2000-01-01"}});
        w.array("zs", {time, faces}, GDT_Float64, {2, 5, 5, 5});
    }
    hc::ingest::Options o;
    o.input = path("fill.nc");
    hc::ingest::LoadReport r;
    EXPECT_EQ(hc::ingest::ingestModelToFile(o, path("a.hcg"), r).cellCount, 4u);
    bool said = false;
    for (const std::string& w : r.warnings) said = said || w.find("1 bed values are -9999") != std::string::npos;
    EXPECT_TRUE(said) << "the sentinel and --nodata -9999 are named";
    o.nodata = -9999;
    hc::ingest::LoadReport r2;
    const hc::ingest::BuildSummary b = hc::ingest::ingestModelToFile(o, path("b.hcg"), r2);
    EXPECT_EQ(b.cellCount, 3u) << "the face is a hole";
    EXPECT_EQ(b.steps.at(0).wetCells, 3u);
}

// Files that are wrong: each refused naming the file and the face or step, nothing written.
TEST_F(Models, BrokenModelFilesAreRefusedByName) {
    auto refused = [&](const std::string& file, const std::string& what) {
        SCOPED_TRACE(what);
        try {
            ingestModel(file, path("bad.hcg"));
            ADD_FAILURE() << "accepted";
        } catch (const hc::Error& e) {
            EXPECT_NE(std::string(e.what()).find(file), std::string::npos) << e.what();
            EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
        }
        EXPECT_FALSE(fs::exists(path("bad.hcg")));
    };
    // A small triangle mesh, written with one thing wrong at a time.
    auto write = [&](const std::string& nc, int badNode, size_t levelFaces, std::vector<double> times) {
        NcWriter w(nc);
        auto nodes = w.dim("nNodes", 4), faces = w.dim("nFaces", 2), three = w.dim("three", 3),
             time = w.dim("time", times.size());
        auto lf = levelFaces == 2 ? faces : w.dim("other", levelFaces);
        auto topo =
            w.array("mesh", {}, GDT_Int32, {},
                    {{"cf_role", "mesh_topology"}, {"node_coordinates", "nx ny"}, {"face_node_connectivity", "fn"}});
        w.intAttr(topo, "topology_dimension", 2);
        w.array("nx", {nodes}, GDT_Float64, {0, 10, 10, 0});
        w.array("ny", {nodes}, GDT_Float64, {0, 0, 10, 10});
        w.array("fn", {faces, three}, GDT_Int32, {0, 1, 2, 0, 2, double(badNode)}, {}, -1.0);
        w.array("zb", {faces}, GDT_Float64, {1, 2});
        w.array("time", {time}, GDT_Float64, times, {{"units", "hours since 2000-01-01"}});
        w.array("zs", {time, lf}, GDT_Float64, std::vector<double>(times.size() * levelFaces, 3.0));
    };
    write(path("node.nc"), 7, 2, {0, 1});
    refused(path("node.nc"), "face 1 names node 7");
    write(path("steps.nc"), 3, 3, {0, 1});
    refused(path("steps.nc"), "zs is not a (time, face) or (time, node) variable");
    write(path("back.nc"), 3, 2, {0, 2, 1});
    refused(path("back.nc"), "step 2 at 3600 s follows 7200 s");
    // Truncated: a NetCDF-4 file cut in half no longer opens; a Selafin file cut in its last step names the step.
    write(path("whole.nc"), 3, 2, {0, 1});
    fs::copy_file(path("whole.nc"), path("cut.nc"));
    fs::resize_file(path("cut.nc"), fs::file_size(path("cut.nc")) / 2);
    refused(path("cut.nc"), "cut.nc");
    HC_REQUIRE_DATA(dem, "buscot_50m.asc");
    const hc::test::TriMesh tm = hc::test::triangulate(hc::test::readRasterValues(dem), 8, 0, 0, 50);
    hc::test::writeSelafin(tm, {0.0, 60.0}, {tm.bed, tm.bed}, path("cut.slf"));
    fs::resize_file(path("cut.slf"), fs::file_size(path("cut.slf")) - 100);
    refused(path("cut.slf"), "step 1");
    // A model whose results are not read here: the format named, and what to convert it to.
    std::ofstream(path("run.dfsu")) << "not read";
    refused(path("run.dfsu"), "MIKE 21");
}

}  // namespace
