// A grid file as a UGRID-1.0 mesh in NetCDF (export.h: writeUgrid), through GDAL's multidimensional API.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <unordered_map>

#include <gdal_priv.h>
#include <ogr_spatialref.h>

#include "heightcast/core/error.h"
#include "heightcast/export/export.h"
#include "heightcast/grid/morton.h"

namespace hc::exporting {
namespace {

constexpr double kFill = -99999.0;  // zs and step layers on dry faces
constexpr int kNodeFill = -999;

struct Writer {
    std::string path;
    std::shared_ptr<GDALGroup> root;

    std::shared_ptr<GDALDimension> dim(const std::string& name, uint64_t size) {
        auto d = root->CreateDimension(name, "", "", size);
        if (!d) throw Error(path + ": cannot create the NetCDF dimension " + name + ": " + CPLGetLastErrorMsg());
        return d;
    }
    std::shared_ptr<GDALMDArray> array(const std::string& name, const std::vector<std::shared_ptr<GDALDimension>>& dims,
                                       GDALDataType type) {
        auto a = root->CreateMDArray(name, dims, GDALExtendedDataType::Create(type));
        if (!a) throw Error(path + ": cannot create the NetCDF variable " + name + ": " + CPLGetLastErrorMsg());
        return a;
    }
    void text(const std::shared_ptr<GDALMDArray>& a, const std::string& key, const std::string& value) {
        auto at = a->CreateAttribute(key, {}, GDALExtendedDataType::CreateString());
        if (!at || !at->Write(value.c_str()))
            throw Error(path + ": cannot write the attribute " + a->GetName() + ":" + key);
    }
    void integer(const std::shared_ptr<GDALMDArray>& a, const std::string& key, int value) {
        auto at = a->CreateAttribute(key, {}, GDALExtendedDataType::Create(GDT_Int32));
        if (!at || !at->WriteInt(value)) throw Error(path + ": cannot write the attribute " + a->GetName() + ":" + key);
    }
    template <typename T>
    void write(const std::shared_ptr<GDALMDArray>& a, const std::vector<T>& values, GDALDataType type) {
        const auto dims = a->GetDimensions();
        std::vector<GUInt64> start(dims.size(), 0);
        std::vector<size_t> count;
        for (const auto& d : dims) count.push_back(size_t(d->GetSize()));
        if (!a->Write(start.data(), count.data(), nullptr, nullptr, GDALExtendedDataType::Create(type), values.data()))
            throw Error(path + ": cannot write the NetCDF variable " + a->GetName() + ": " + CPLGetLastErrorMsg());
    }
};

}  // namespace

UgridSummary writeUgrid(const std::string& gridPath, const std::string& path, const UgridOptions& options) {
    if (options.startIndex != 0 && options.startIndex != 1) throw Error("UGRID start_index must be 0 or 1");
    GDALAllRegister();
    GDALDriver* driver = GetGDALDriverManager()->GetDriverByName("netCDF");
    if (!driver) throw Error(path + ": GDAL has no netCDF driver");
    Grid g = readGrid(gridPath, nullptr, 0);
    const size_t n = g.cellCount();
    const size_t steps = g.steps.size();
    // Nodes: every cell corner once, on the finest lattice; faces counterclockwise from the south-west corner.
    std::unordered_map<uint64_t, int> nodeOf;
    std::vector<double> nodeX, nodeY;
    std::vector<int> faces(4 * n);
    for (size_t i = 0; i < n; ++i) {
        const uint64_t key = codeKey(g.codes[i]);
        const uint64_t x = mortonX(key), y = mortonY(key), s = uint64_t{1} << g.level(i);
        const uint64_t corners[4][2] = {{x, y}, {x + s, y}, {x + s, y + s}, {x, y + s}};
        for (int c = 0; c < 4; ++c) {
            const uint64_t k = (corners[c][1] << 32) | corners[c][0];
            auto [it, added] = nodeOf.emplace(k, int(nodeX.size()));
            if (added) {
                double wx = 0, wy = 0;
                g.localToWorld(double(corners[c][0]) * g.finestCellM, double(corners[c][1]) * g.finestCellM, wx, wy);
                nodeX.push_back(wx), nodeY.push_back(wy);
            }
            faces[4 * i + size_t(c)] = it->second + options.startIndex;
        }
    }
    const std::string tmp = path + ".partial.nc";
    std::error_code ec;
    std::filesystem::remove(tmp, ec);
    UgridSummary out;
    try {
        std::unique_ptr<GDALDataset> ds(driver->CreateMultiDimensional(tmp.c_str(), nullptr, nullptr));
        if (!ds) throw Error(path + ": cannot create a NetCDF file: " + CPLGetLastErrorMsg());
        Writer w{path, ds->GetRootGroup()};
        auto nodes = w.dim("mesh2d_nNodes", nodeX.size());
        auto faceDim = w.dim("mesh2d_nFaces", n);
        auto corners = w.dim("mesh2d_nMax_face_nodes", 4);
        auto time = w.dim("time", std::max<size_t>(steps, 1));

        auto mesh = w.array("mesh2d", {}, GDT_Int32);
        w.text(mesh, "cf_role", "mesh_topology");
        w.text(mesh, "long_name",
               "quadtree mesh written by heightcast from " + std::filesystem::path(gridPath).filename().string());
        w.integer(mesh, "topology_dimension", 2);
        w.text(mesh, "node_coordinates", "mesh2d_node_x mesh2d_node_y");
        w.text(mesh, "face_node_connectivity", "mesh2d_face_nodes");
        w.text(mesh, "face_dimension", "mesh2d_nFaces");
        std::shared_ptr<GDALMDArray> crs;
        if (!g.crsWkt.empty()) {
            crs = w.array("crs", {}, GDT_Int32);
            w.text(crs, "crs_wkt", g.crsWkt);
            w.text(crs, "spatial_ref", g.crsWkt);
        }
        auto x = w.array("mesh2d_node_x", {nodes}, GDT_Float64);
        auto y = w.array("mesh2d_node_y", {nodes}, GDT_Float64);
        w.text(x, "standard_name", "projection_x_coordinate"), w.text(x, "units", "m"), w.text(x, "mesh", "mesh2d"),
            w.text(x, "location", "node");
        w.text(y, "standard_name", "projection_y_coordinate"), w.text(y, "units", "m"), w.text(y, "mesh", "mesh2d"),
            w.text(y, "location", "node");
        w.write(x, nodeX, GDT_Float64);
        w.write(y, nodeY, GDT_Float64);
        auto fn = w.array("mesh2d_face_nodes", {faceDim, corners}, GDT_Int32);
        w.text(fn, "cf_role", "face_node_connectivity");
        w.integer(fn, "start_index", options.startIndex);
        fn->SetNoDataValue(double(kNodeFill));
        w.write(fn, faces, GDT_Int32);

        auto faceVar = [&](const std::string& name, std::vector<std::shared_ptr<GDALDimension>> dims,
                           const std::string& units, const std::string& longName) {
            auto a = w.array(name, dims, GDT_Float64);
            w.text(a, "mesh", "mesh2d"), w.text(a, "location", "face"), w.text(a, "units", units),
                w.text(a, "long_name", longName);
            if (crs) w.text(a, "grid_mapping", "crs");
            return a;
        };
        auto zb = faceVar("zb", {faceDim}, g.layers[0].units, "bed level (terrain elevation)");
        std::vector<double> terrain(g.values[0].begin(), g.values[0].end());
        w.write(zb, terrain, GDT_Float64);

        auto t = w.array("time", {time}, GDT_Float64);
        w.text(t, "units", "seconds since 1970-01-01 00:00:00");
        w.text(t, "standard_name", "time");
        std::vector<double> times;
        for (size_t k = 0; k < std::max<size_t>(steps, 1); ++k) times.push_back(k < steps ? g.steps[k].timeS : 0.0);
        w.write(t, times, GDT_Float64);

        const size_t first = g.firstStepLayer();
        if (first < g.layers.size()) {
            // The water level (zs) and every further step layer, per step; fill where dry.
            std::vector<std::shared_ptr<GDALMDArray>> vars{faceVar("zs", {time, faceDim}, "m", "water level")};
            for (size_t l = first + 1; l < g.layers.size(); ++l)
                vars.push_back(faceVar(g.layers[l].name, {time, faceDim}, g.layers[l].units, g.layers[l].name));
            for (auto& v : vars) v->SetNoDataValue(kFill);
            std::vector<std::vector<double>> values(vars.size(), std::vector<double>(times.size() * n, kFill));
            for (size_t k = 0; k < times.size(); ++k) {
                if (k > 0) readGridStep(gridPath, g, k);
                const auto& depth = g.values[first];
                for (size_t i = 0; i < n; ++i) {
                    if (!(depth[i] > 0)) continue;
                    ++out.wetFaces;
                    values[0][k * n + i] = double(g.values[0][i]) + double(depth[i]);
                    for (size_t l = first + 1; l < g.layers.size(); ++l)
                        values[l - first][k * n + i] = double(g.values[l][i]);
                }
            }
            for (size_t v = 0; v < vars.size(); ++v) w.write(vars[v], values[v], GDT_Float64);
        }
        ds.reset();  // closes (and flushes) the file
        std::filesystem::rename(tmp, path, ec);
        if (ec) throw Error(path + ": cannot be written: " + ec.message());
    } catch (...) {
        std::filesystem::remove(tmp, ec);
        throw;
    }
    out.nodes = nodeX.size();
    out.faces = n;
    out.steps = steps;
    return out;
}

}  // namespace hc::exporting
