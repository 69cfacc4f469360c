// hc-bench-models: a flood model's results of any size, for the model-ingest benchmark (bench/models/run.sh): a real
// raster written as a UGRID-1.0 map, as a quadtree model writes it (one square face per pixel, the bed per face) or as
// a finite-element model does (nodes at the pixel centres, two triangles a square of them, the bed per node), with a
// flood rising over N steps (the level rises evenly from the lowest to the highest bed; zs is the bed where dry, as
// SFINCS and D-Flow FM write it). Steps are written one at a time: memory stays at the raster and the mesh.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <gdal_priv.h>

#include "heightcast/support/cli.h"
#include "heightcast/core/error.h"
#include "heightcast/core/progress.h"

namespace {

using ArrayPtr = std::shared_ptr<GDALMDArray>;

struct Raster {
    size_t w = 0, h = 0;
    double gt[6] = {0, 1, 0, 0, 0, -1};
    std::vector<float> z;
    std::string wkt;
};

Raster readRaster(const std::string& path) {
    std::unique_ptr<GDALDataset> ds(GDALDataset::Open(path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY));
    if (!ds) throw hc::Error(path + ": cannot be opened");
    Raster r;
    r.w = size_t(ds->GetRasterXSize()), r.h = size_t(ds->GetRasterYSize());
    ds->GetGeoTransform(r.gt);
    if (ds->GetSpatialRef()) {
        char* wkt = nullptr;
        ds->GetSpatialRef()->exportToWkt(&wkt);
        r.wkt = wkt ? wkt : "";
        CPLFree(wkt);
    }
    r.z.resize(r.w * r.h);
    if (ds->GetRasterBand(1)->RasterIO(GF_Read, 0, 0, int(r.w), int(r.h), r.z.data(), int(r.w), int(r.h), GDT_Float32,
                                       0, 0) != CE_None)
        throw hc::Error(path + ": cannot be read");
    return r;
}

void write(const ArrayPtr& a, const std::vector<GUInt64>& start, const std::vector<size_t>& count, const void* data,
           GDALDataType t) {
    if (!a->Write(start.data(), count.data(), nullptr, nullptr, GDALExtendedDataType::Create(t), data))
        throw hc::Error("cannot write " + a->GetName() + ": " + CPLGetLastErrorMsg());
}

void text(const ArrayPtr& a, const std::string& k, const std::string& v) {
    a->CreateAttribute(k, {}, GDALExtendedDataType::CreateString())->Write(v.c_str());
}

void writeMesh(const Raster& r, const std::string& out, bool quads, size_t steps) {
    // 2^31 nodes or connectivity entries at the most: int32 indices.
    GDALDriver* nc = GetGDALDriverManager()->GetDriverByName("netCDF");
    std::unique_ptr<GDALDataset> ds(nc->CreateMultiDimensional(out.c_str(), nullptr, nullptr));
    if (!ds) throw hc::Error(out + ": cannot be created");
    auto root = ds->GetRootGroup();
    // Quads: nodes at the pixel corners, a face per pixel. Triangles: nodes at the pixel centres.
    const size_t nw = quads ? r.w + 1 : r.w, nh = quads ? r.h + 1 : r.h,
                 faces = quads ? r.w * r.h : 2 * (r.w - 1) * (r.h - 1);
    const size_t per = quads ? 4 : 3;
    auto dn = root->CreateDimension("mesh2d_nNodes", "", "", nw * nh),
         df = root->CreateDimension("mesh2d_nFaces", "", "", faces);
    auto dk = root->CreateDimension("mesh2d_nMax_face_nodes", "", "", per),
         dt = root->CreateDimension("time", "", "", steps);
    auto mesh = root->CreateMDArray("mesh2d", {}, GDALExtendedDataType::Create(GDT_Int32));
    text(mesh, "cf_role", "mesh_topology");
    mesh->CreateAttribute("topology_dimension", {}, GDALExtendedDataType::Create(GDT_Int32))->WriteInt(2);
    text(mesh, "node_coordinates", "mesh2d_node_x mesh2d_node_y");
    text(mesh, "face_node_connectivity", "mesh2d_face_nodes");
    text(mesh, "face_dimension", "mesh2d_nFaces");
    if (!r.wkt.empty()) {
        auto crs = root->CreateMDArray("crs", {}, GDALExtendedDataType::Create(GDT_Int32));
        text(crs, "crs_wkt", r.wkt);
    }
    std::vector<double> x(nw * nh), y(nw * nh);
    const double off = quads ? 0.0 : 0.5;
    for (size_t j = 0; j < nh; ++j)
        for (size_t i = 0; i < nw; ++i)
            x[j * nw + i] = r.gt[0] + (double(i) + off) * r.gt[1],
                       y[j * nw + i] = r.gt[3] + (double(j) + off) * r.gt[5];
    auto ax = root->CreateMDArray("mesh2d_node_x", {dn}, GDALExtendedDataType::Create(GDT_Float64));
    auto ay = root->CreateMDArray("mesh2d_node_y", {dn}, GDALExtendedDataType::Create(GDT_Float64));
    write(ax, {0}, {x.size()}, x.data(), GDT_Float64);
    write(ay, {0}, {y.size()}, y.data(), GDT_Float64);
    x = {}, y = {};
    std::vector<int32_t> conn;
    conn.reserve(faces * per);
    auto n = [&](size_t i, size_t j) { return int32_t(j * nw + i); };
    for (size_t j = 0; j + 1 < nh; ++j)
        for (size_t i = 0; i + 1 < nw; ++i) {
            if (quads)
                conn.insert(conn.end(), {n(i, j + 1), n(i + 1, j + 1), n(i + 1, j), n(i, j)});
            else
                conn.insert(conn.end(), {n(i, j + 1), n(i + 1, j + 1), n(i + 1, j), n(i, j + 1), n(i + 1, j), n(i, j)});
        }
    auto fn = root->CreateMDArray("mesh2d_face_nodes", {df, dk}, GDALExtendedDataType::Create(GDT_Int32));
    write(fn, {0, 0}, {faces, per}, conn.data(), GDT_Int32);
    conn = {};
    auto where = quads ? df : dn;
    auto bed = root->CreateMDArray(quads ? "zb" : "mesh2d_node_z", {where}, GDALExtendedDataType::Create(GDT_Float32));
    text(bed, "location", quads ? "face" : "node");
    write(bed, {0}, {r.z.size()}, r.z.data(), GDT_Float32);
    auto t = root->CreateMDArray("time", {dt}, GDALExtendedDataType::Create(GDT_Float64));
    text(t, "units", "seconds since 2000-01-01 00:00:00");
    std::vector<double> times(steps);
    for (size_t k = 0; k < steps; ++k) times[k] = 600.0 * double(k);
    write(t, {0}, {steps}, times.data(), GDT_Float64);
    auto zs = root->CreateMDArray(quads ? "zs" : "mesh2d_s1", {dt, where}, GDALExtendedDataType::Create(GDT_Float32));
    text(zs, "location", quads ? "face" : "node");
    const auto [lo, hi] = std::minmax_element(r.z.begin(), r.z.end());
    std::vector<float> level(r.z.size());
    hc::Progress progress("writing steps", steps);
    for (size_t k = 0; k < steps; ++k) {
        const float l = *lo + (*hi - *lo) * float(k + 1) / float(steps);
        for (size_t i = 0; i < level.size(); ++i) level[i] = std::max(l, r.z[i]);
        write(zs, {GUInt64(k), 0}, {1, level.size()}, level.data(), GDT_Float32);
        progress.advance(1);
    }
}

}  // namespace

int main(int argc, char** argv) {
    return hc::cli::run("hc-bench-models", [&] {
        std::string raster, out, faces = "quads";
        unsigned steps = 100;
        hc::cli::Parser p("hc-bench-models", "RASTER -o OUT.nc [--faces quads|triangles] [--steps N]",
                          "Writes a raster as a flood model's UGRID-1.0 map with a flood rising over N steps, for the\n"
                          "model-ingest benchmark (bench/models/run.sh).");
        p.positional("RASTER", "terrain raster (GDAL)", raster);
        p.option("-o", "OUT.nc", "the map file to write", out);
        p.option("--faces", "quads|triangles",
                 "one square face per pixel (bed per face), or two triangles a square of pixel centres\n"
                 "      (bed per node) (default quads)",
                 faces);
        p.option("--steps", "N", "time steps, 600 s apart (default 100)", steps);
        if (!p.parse(argc, argv)) return 0;
        if (out.empty() || (faces != "quads" && faces != "triangles") || steps == 0)
            throw hc::Error("give -o OUT.nc, --faces quads|triangles, --steps >= 1");
        GDALAllRegister();
        const Raster r = readRaster(raster);
        const std::string tmp = out + ".partial.nc";  // renamed when whole: a run stopped midway leaves no OUT.nc
        std::error_code ec;
        try {
            writeMesh(r, tmp, faces == "quads", steps);
        } catch (...) {
            std::filesystem::remove(tmp, ec);
            throw;
        }
        std::filesystem::rename(tmp, out, ec);
        if (ec) throw hc::Error(out + ": cannot be written: " + ec.message());
        std::printf("hc-bench-models: %s -> %s: %zu x %zu px as %s, %u steps\n", raster.c_str(), out.c_str(), r.w, r.h,
                    faces.c_str(), steps);
        return 0;
    });
}
