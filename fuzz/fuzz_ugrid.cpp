// fuzz_ugrid: hc-ingest's UGRID quadtree mesh reader (hc::ingest::ingestUgridToFile) on meshes made from the input.
//
// Mutating a NetCDF file's bytes would fuzz the netCDF and HDF5 libraries, not our reader: their header checks stop
// almost every mutation. So the input is read as a small mesh, written through GDAL's multidimensional API as a
// simulation would write it, and every input reaches our checks (four-node square faces, power-of-two sides,
// alignment to the finest lattice and to their own size, one orientation, overlaps, terrain and level fill values,
// times that must increase). Only hc::Error may come out; a grid the reader accepts must read back as a valid file
// holding one cell per face with terrain, and a refused mesh must leave no file.
//
// Input bytes (missing bytes read as 0):
//   0      node count - 1 (mod 48)          1  face count - 1 (mod 24)
//   2      flags: bit 0 start_index 1, bit 1 water levels, bits 2-3 steps - 1, bit 4 zb _FillValue -99,
//          bit 5 turn the mesh by 30 degrees, bit 6 node x/y in tenths
//   then per node x, y (int8), per face 4 node indices (uint8; 255: the connectivity's fill value), per face zb
//   (int8), per step a time increment (int8, hours), per step and face zs (int8; 127: zs's fill value)
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <gdal_priv.h>

#include "heightcast/core/error.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/ingest/ugrid.h"

namespace {

struct Bytes {
    const uint8_t* data;
    size_t size, at = 0;
    uint8_t next() { return at < size ? data[at++] : 0; }
};

std::string workDir() {
    static const std::string dir = [] {
        const auto d = std::filesystem::temp_directory_path() / ("fuzz_ugrid_" + std::to_string(::getpid()));
        std::filesystem::create_directories(d);
        return d.string();
    }();
    return dir;
}

template <typename T>
bool writeAll(const std::shared_ptr<GDALMDArray>& a, const std::vector<T>& v, GDALDataType type) {
    std::vector<GUInt64> start(a->GetDimensionCount(), 0);
    std::vector<size_t> count;
    for (const auto& d : a->GetDimensions()) count.push_back(size_t(d->GetSize()));
    return a->Write(start.data(), count.data(), nullptr, nullptr, GDALExtendedDataType::Create(type), v.data());
}

// The mesh of the input as a NetCDF file at `path`; false if GDAL could not write it (not a finding).
bool writeMesh(Bytes in, const std::string& path) {
    const size_t nodes = size_t(in.next() % 48) + 1, faces = size_t(in.next() % 24) + 1;
    const uint8_t flags = in.next();
    const int start = flags & 1;
    const bool water = flags & 2;
    const size_t steps = size_t((flags >> 2) & 3) + 1;
    const double scale = (flags & 64) ? 0.1 : 1.0, c = std::cos(M_PI / 6), s = std::sin(M_PI / 6);
    std::vector<double> x(nodes), y(nodes);
    for (size_t k = 0; k < nodes; ++k) {
        const double px = double(int8_t(in.next())) * scale, py = double(int8_t(in.next())) * scale;
        x[k] = (flags & 32) ? 5e5 + c * px - s * py : 5e5 + px;
        y[k] = (flags & 32) ? 5e6 + s * px + c * py : 5e6 + py;
    }
    std::vector<int> conn(4 * faces);
    for (int& v : conn) {
        const uint8_t b = in.next();
        v = b == 255 ? -1 : int(b % nodes) + start;
    }
    std::vector<double> zb(faces), times(steps), zs(steps * faces);
    for (double& v : zb) v = double(int8_t(in.next()));
    double t = 0;
    for (double& v : times) v = (t += double(int8_t(in.next())));
    for (double& v : zs) {
        const uint8_t b = in.next();
        v = b == 127 ? -99999.0 : double(int8_t(b));
    }

    GDALDriver* driver = GetGDALDriverManager()->GetDriverByName("netCDF");
    std::unique_ptr<GDALDataset> ds(driver ? driver->CreateMultiDimensional(path.c_str(), nullptr, nullptr) : nullptr);
    if (!ds) return false;
    auto root = ds->GetRootGroup();
    auto nNodes = root->CreateDimension("nNodes", "", "", nodes),
         nFaces = root->CreateDimension("nFaces", "", "", faces);
    auto nMax = root->CreateDimension("nMax", "", "", 4);
    auto text = [](const std::shared_ptr<GDALMDArray>& a, const char* k, const char* v) {
        return a->CreateAttribute(k, {}, GDALExtendedDataType::CreateString())->Write(v);
    };
    auto mesh = root->CreateMDArray("mesh", {}, GDALExtendedDataType::Create(GDT_Int32));
    if (!mesh || !text(mesh, "cf_role", "mesh_topology") || !text(mesh, "node_coordinates", "nx ny") ||
        !text(mesh, "face_node_connectivity", "fn") ||
        !mesh->CreateAttribute("topology_dimension", {}, GDALExtendedDataType::Create(GDT_Int32))->WriteInt(2))
        return false;
    auto nx = root->CreateMDArray("nx", {nNodes}, GDALExtendedDataType::Create(GDT_Float64));
    auto ny = root->CreateMDArray("ny", {nNodes}, GDALExtendedDataType::Create(GDT_Float64));
    auto fn = root->CreateMDArray("fn", {nFaces, nMax}, GDALExtendedDataType::Create(GDT_Int32));
    auto zbVar = root->CreateMDArray("zb", {nFaces}, GDALExtendedDataType::Create(GDT_Float64));
    if (!nx || !ny || !fn || !zbVar || !fn->SetNoDataValue(-1.0) ||
        !fn->CreateAttribute("start_index", {}, GDALExtendedDataType::Create(GDT_Int32))->WriteInt(start))
        return false;
    if ((flags & 16) && !zbVar->SetNoDataValue(-99.0)) return false;
    if (!writeAll(nx, x, GDT_Float64) || !writeAll(ny, y, GDT_Float64) || !writeAll(fn, conn, GDT_Int32) ||
        !writeAll(zbVar, zb, GDT_Float64))
        return false;
    if (water) {
        auto time = root->CreateDimension("time", "", "", steps);
        auto tv = root->CreateMDArray("time", {time}, GDALExtendedDataType::Create(GDT_Float64));
        auto zsVar = root->CreateMDArray("zs", {time, nFaces}, GDALExtendedDataType::Create(GDT_Float64));
        if (!tv || !zsVar || !text(tv, "units", "hours since 2024-01-01 00:00:00") ||
            !zsVar->SetNoDataValue(-99999.0) || !writeAll(tv, times, GDT_Float64) || !writeAll(zsVar, zs, GDT_Float64))
            return false;
    }
    return true;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    static const bool registered = (GDALAllRegister(), CPLSetErrorHandler(CPLQuietErrorHandler), true);
    (void)registered;
    const std::string nc = workDir() + "/mesh.nc", out = workDir() + "/mesh.hcg";
    std::filesystem::remove(nc);
    std::filesystem::remove(out);
    if (!writeMesh(Bytes{data, size}, nc)) return 0;
    hc::ingest::Options o;
    o.input = nc;
    o.sourceSrs = "local";
    hc::ingest::LoadReport report;
    try {
        const hc::ingest::BuildSummary s = hc::ingest::ingestUgridToFile(o, out, report);
        const hc::Grid g = hc::readGrid(out);  // what was written reads back, every check passed
        if (g.cellCount() != s.cellCount || g.cellCount() == 0) __builtin_trap();
    } catch (const hc::Error&) {
        if (std::filesystem::exists(out)) __builtin_trap();  // a refused mesh leaves nothing
    }
    return 0;
}
