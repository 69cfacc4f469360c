// tests/model_files.h: flood model result files written the way the models write them, from real rasters, for the
// model readers' tests (models_test.cpp): NetCDF through GDAL's multidimensional API, Selafin as its big-endian
// Fortran records.
#pragma once

#include <gtest/gtest.h>

#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <gdal_priv.h>

namespace hc::test {

// A real raster's first band, row 0 the northern-most (NaN for nodata).
struct RasterValues {
    size_t width = 0, height = 0;
    std::vector<double> v;
    double at(size_t col, size_t row) const { return v[row * width + col]; }
};

inline RasterValues readRasterValues(const std::string& path) {
    GDALAllRegister();
    std::unique_ptr<GDALDataset> ds(GDALDataset::Open(path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY));
    RasterValues r;
    if (!ds) return r;
    r.width = size_t(ds->GetRasterXSize()), r.height = size_t(ds->GetRasterYSize());
    r.v.resize(r.width * r.height);
    GDALRasterBand* b = ds->GetRasterBand(1);
    if (b->RasterIO(GF_Read, 0, 0, int(r.width), int(r.height), r.v.data(), int(r.width), int(r.height), GDT_Float64, 0,
                    0) != CE_None)
        r.v.clear();
    int has = 0;
    const double nodata = b->GetNoDataValue(&has);
    for (double& x : r.v)
        if (has && x == nodata) x = NAN;
    return r;
}

// A NetCDF file being written through GDAL's multidimensional API.
class NcWriter {
public:
    explicit NcWriter(const std::string& path) {
        GDALAllRegister();
        ds_.reset(
            GetGDALDriverManager()->GetDriverByName("netCDF")->CreateMultiDimensional(path.c_str(), nullptr, nullptr));
        if (ds_) root_ = ds_->GetRootGroup();
    }
    bool ok() const { return root_ != nullptr; }
    std::shared_ptr<GDALDimension> dim(const std::string& name, size_t n) {
        return root_->CreateDimension(name, "", "", n);
    }
    // An array of `type` holding `values` (converted), with text attributes and an optional fill value.
    std::shared_ptr<GDALMDArray> array(const std::string& name, const std::vector<std::shared_ptr<GDALDimension>>& dims,
                                       GDALDataType type, const std::vector<double>& values,
                                       std::vector<std::pair<std::string, std::string>> attrs = {},
                                       std::optional<double> fill = std::nullopt) {
        auto a = root_->CreateMDArray(name, dims, GDALExtendedDataType::Create(type));
        if (!a) return a;
        if (fill) a->SetNoDataValue(*fill);
        for (const auto& [k, v] : attrs)
            a->CreateAttribute(k, {}, GDALExtendedDataType::CreateString())->Write(v.c_str());
        std::vector<GUInt64> start(dims.size(), 0);
        std::vector<size_t> count;
        for (const auto& d : dims) count.push_back(size_t(d->GetSize()));
        if (!values.empty()) {
            EXPECT_TRUE(a->Write(start.data(), count.data(), nullptr, nullptr,
                                 GDALExtendedDataType::Create(GDT_Float64), values.data()))
                << name;
        }
        return a;
    }
    void intAttr(const std::shared_ptr<GDALMDArray>& a, const std::string& k, int v) {
        a->CreateAttribute(k, {}, GDALExtendedDataType::Create(GDT_Int32))->WriteInt(v);
    }
    void globalNum(const std::string& k, double v) {
        root_->CreateAttribute(k, {}, GDALExtendedDataType::Create(GDT_Float64))->Write(v);
    }
    void globalText(const std::string& k, const std::string& v) {
        root_->CreateAttribute(k, {}, GDALExtendedDataType::CreateString())->Write(v.c_str());
    }
    void close() { ds_.reset(), root_.reset(); }

private:
    std::unique_ptr<GDALDataset> ds_;
    std::shared_ptr<GDALGroup> root_;
};

// A triangle mesh over a raster's pixel centres, every `step`-th pixel a node, two triangles a square of nodes
// (split along the south-west to north-east diagonal); node values the raster's. Coordinates: pixel centres of a
// raster of `pixel` metres whose north-west corner is (west, north).
struct TriMesh {
    size_t cols = 0, rows = 0;      // nodes along x and y, row 0 the northern-most
    std::vector<double> x, y, bed;  // per node
    std::vector<std::array<uint32_t, 3>> tris;
    double spacing = 0;  // between nodes [m]
};

inline TriMesh triangulate(const RasterValues& r, size_t step, double west, double north, double pixel) {
    TriMesh m;
    m.cols = (r.width - 1) / step + 1, m.rows = (r.height - 1) / step + 1, m.spacing = double(step) * pixel;
    for (size_t j = 0; j < m.rows; ++j)
        for (size_t i = 0; i < m.cols; ++i) {
            m.x.push_back(west + (double(i * step) + 0.5) * pixel);
            m.y.push_back(north - (double(j * step) + 0.5) * pixel);
            m.bed.push_back(r.at(i * step, j * step));
        }
    auto n = [&](size_t i, size_t j) { return uint32_t(j * m.cols + i); };
    for (size_t j = 0; j + 1 < m.rows; ++j)
        for (size_t i = 0; i + 1 < m.cols; ++i) {
            // (i, j+1) is south-west, (i+1, j) north-east: counterclockwise triangles.
            m.tris.push_back({n(i, j + 1), n(i + 1, j + 1), n(i + 1, j)});
            m.tris.push_back({n(i, j + 1), n(i + 1, j), n(i, j)});
        }
    return m;
}

// The triangle of `m` that holds (px, py): its three nodes (south-west, then the two others), and the point's offsets
// east (u) and north (v) from the south-west node in node spacings; false outside the mesh.
inline bool triangleAt(const TriMesh& m, double px, double py, std::array<size_t, 3>& nodes, double& u, double& v) {
    const double fi = (px - m.x[0]) / m.spacing, fj = (m.y[0] - py) / m.spacing;
    if (fi < 0 || fj < 0 || fi > double(m.cols - 1) || fj > double(m.rows - 1)) return false;
    const size_t i = std::min(size_t(fi), m.cols - 2), j = std::min(size_t(fj), m.rows - 2);
    u = fi - double(i), v = double(j + 1) - fj;
    auto n = [&](size_t a, size_t b) { return b * m.cols + a; };
    nodes = u >= v ? std::array<size_t, 3>{n(i, j + 1), n(i + 1, j + 1), n(i + 1, j)}
                   : std::array<size_t, 3>{n(i, j + 1), n(i, j), n(i + 1, j)};
    return true;
}

// The linear interpolation of node values over the triangle of `m` that holds (px, py); NaN outside the mesh.
inline double interpolate(const TriMesh& m, const std::vector<double>& values, double px, double py) {
    std::array<size_t, 3> t;
    double u = 0, v = 0;
    if (!triangleAt(m, px, py, t, u, v)) return NAN;
    // South-east half: sw + u (se - sw) + v (ne - se); north-west half: sw + v (nw - sw) + u (ne - nw).
    return u >= v ? values[t[0]] + u * (values[t[1]] - values[t[0]]) + v * (values[t[2]] - values[t[1]])
                  : values[t[0]] + v * (values[t[1]] - values[t[0]]) + u * (values[t[2]] - values[t[1]]);
}

// The mesh as a TELEMAC Selafin file (single precision, TELEMAC's English names), levels per step per node.
inline void writeSelafin(const TriMesh& m, const std::vector<double>& times,
                         const std::vector<std::vector<double>>& levels, const std::string& path) {
    std::ofstream out(path, std::ios::binary);
    auto be32 = [&](uint32_t v) {
        const uint32_t b = std::endian::native == std::endian::little ? __builtin_bswap32(v) : v;
        out.write(reinterpret_cast<const char*>(&b), 4);
    };
    auto record = [&](const std::vector<uint32_t>& words) {
        be32(uint32_t(4 * words.size()));
        for (uint32_t w : words) be32(w);
        be32(uint32_t(4 * words.size()));
    };
    auto text = [&](std::string s, size_t n) {
        s.resize(n, ' ');
        be32(uint32_t(n));
        out.write(s.data(), long(n));
        be32(uint32_t(n));
    };
    auto reals = [&](const std::vector<double>& v) {
        std::vector<uint32_t> w;
        for (double d : v) w.push_back(std::bit_cast<uint32_t>(float(d)));
        record(w);
    };
    text("heightcast test mesh                                                    SERAFIN ", 80);
    record({2, 0});
    text("BOTTOM          M               ", 32);
    text("FREE SURFACE    M               ", 32);
    record({1, 0, 0, 0, 0, 0, 0, 0, 0, 0});
    record({uint32_t(m.tris.size()), uint32_t(m.x.size()), 3, 1});
    std::vector<uint32_t> ikle, ipobo(m.x.size(), 0);
    for (const auto& t : m.tris) ikle.insert(ikle.end(), {t[0] + 1, t[1] + 1, t[2] + 1});
    record(ikle);
    record(ipobo);
    reals(m.x);
    reals(m.y);
    for (size_t k = 0; k < times.size(); ++k) {
        record({std::bit_cast<uint32_t>(float(times[k]))});
        reals(m.bed);
        reals(levels[k]);
    }
}

// The mesh as an SMS .2dm (nodes with the bed as z, E3T triangles), as TUFLOW and SMS write their meshes.
inline void writeTwoDm(const TriMesh& m, const std::string& path) {
    std::ofstream out(path);
    out.precision(17);
    out << "MESH2D\n";
    for (size_t i = 0; i < m.tris.size(); ++i)
        out << "E3T " << i + 1 << ' ' << m.tris[i][0] + 1 << ' ' << m.tris[i][1] + 1 << ' ' << m.tris[i][2] + 1
            << " 1\n";
    for (size_t i = 0; i < m.x.size(); ++i)
        out << "ND " << i + 1 << ' ' << m.x[i] << ' ' << m.y[i] << ' ' << m.bed[i] << '\n';
}

}  // namespace hc::test
