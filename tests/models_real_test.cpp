// Real flood model outputs from public repositories (the MDAL project's test data, MIT), read end to end by hc-ingest's
// readers: each file's model and format, faces, steps, how it was taken (cells or sampled), wet cells at the last step
// within the model's own counts. The files live in ../shared/data/models/mdal/ (the paths of MDAL's tests/data; their
// provenance in ../shared/data/SOURCES.md), or where HC_MODEL_DATA says: without them this test skips, saying so.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <string>

#include "heightcast/core/error.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/ingest/mesh.h"
#include "heightcast/ingest/model.h"
#include "temp_dir.h"

namespace {

namespace fs = std::filesystem;

class ModelsReal : public hc::test::TempDirTest {
protected:
    ModelsReal() : TempDirTest("hc_models_real_") {}
};

struct Case {
    const char* path;     // under models/mdal/
    const char* format;   // the start of modelFormatOf's name
    size_t faces, steps;  // as the reader gives them
    bool cells;           // faces taken as cells (a quadtree) rather than sampled
};

// The figures each reader gave on these files when they were written (docs/models.md); a reader that changes how it
// reads a model changes them here, on purpose.
const Case kCases[] = {
    {"ugrid/D-Flow1.1/simplebox_hex7_map.nc", "D-Flow FM map (UGRID-1.0)", 810, 13, false},
    {"ugrid/D-Flow1.1/manzese_1d2d_small_map.nc", "D-Flow FM map (UGRID-1.0)", 1824, 6, true},
    {"hec2d/2d_6.1/Muncie2DOnly_SI.p01.hdf", "HEC-RAS 2D plan results (HDF5, HEC-RAS 6.1", 2972, 49, false},
    {"hec2d/2areas/baldeagle_multi2d.hdf", "HEC-RAS 2D plan results (HDF5, HEC-RAS 5.0", 617, 7, false},
    {"sww/anuga-viewer/cairns.sww", "ANUGA sww", 4962, 51, false},
    {"slf/example_res_fr.slf", "TELEMAC Selafin", 26000, 2, false},
    {"3di/2d_groundwater/results_3di.nc", "3Di results (NetCDF)", 5653, 5, true},
    {"tuflowfv/withoutMaxes/trap_steady_05_3D.nc", "TUFLOW FV results (NetCDF)", 320, 37, false},
};

TEST_F(ModelsReal, EveryModelReadsEndToEnd) {
    const char* env = std::getenv("HC_MODEL_DATA");  // another copy of the same files (a checkout of MDAL's tests/data)
    const fs::path dir = env ? fs::path(env) : fs::path(HC_SHARED_DATA_DIR) / "models" / "mdal";
    if (!fs::exists(dir)) GTEST_SKIP() << dir.string() << " is not there (real model outputs; docs/models.md): skipped";
    for (const Case& c : kCases) {
        SCOPED_TRACE(c.path);
        const std::string file = (dir / c.path).string();
        ASSERT_TRUE(fs::exists(file));
        EXPECT_EQ(hc::ingest::modelFormatOf(file).rfind(c.format, 0), 0u) << hc::ingest::modelFormatOf(file);
        const hc::ingest::ModelMesh m = hc::ingest::readModelMesh(file, {});
        EXPECT_EQ(m.faceCount(), c.faces);
        EXPECT_EQ(m.timesS.size(), c.steps);
        hc::ingest::Options o;
        o.input = file;
        hc::ingest::LoadReport r;
        const std::string out = path("g.hcg");
        fs::remove(out);
        const hc::ingest::BuildSummary b = hc::ingest::ingestModelToFile(o, out, r);
        EXPECT_EQ(!b.shape.stats.sourceKind.empty(), c.cells) << r.method;
        if (c.cells) {
            EXPECT_LE(b.cellCount, c.faces) << "one cell per face with a bed";
        }
        ASSERT_EQ(b.steps.size(), c.steps);
        // Water where the model has it: some cell wet at the last step, and never more than the grid's cells.
        EXPECT_GT(b.steps.back().wetCells, 0u);
        EXPECT_LE(b.steps.back().wetCells, b.cellCount);
        const hc::Grid g = hc::readGrid(out, nullptr, c.steps - 1);
        for (size_t i = 0; i < g.cellCount(); ++i) ASSERT_GE(g.values[1][i], 0.0f) << "depths are never negative";
    }
}

}  // namespace
