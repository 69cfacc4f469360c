// SFINCS regular map files (sfincs_map.nc: 2-D x/y of a possibly turned grid, zb, zs over time) -> ModelMesh of
// square faces, one per active cell, its corners from corner_x/corner_y or from the centres' lattice.
#include <cmath>

#include <fmt/format.h>

#include "../gdal_util.h"
#include "heightcast/core/error.h"
#include "md_util.h"
#include "readers.h"

namespace hc::ingest::detail {
namespace {

struct Lattice {
    size_t rows = 0, cols = 0;              // the 2-D arrays' dimensions as stored (n, m; or transposed)
    std::vector<double> x, y;               // cell centres, NaN where the file has a fill value
    double ux = 0, uy = 0, vx = 0, vy = 0;  // one cell along a row (u) and down the columns (v)
};

// One cell's step along each axis: the mean of the differences of neighbouring valid centres (float32 centres
// scatter by their rounding; the mean of many differences does not).
void cellSteps(const MdFile& f, Lattice& l) {
    double su[2] = {0, 0}, sv[2] = {0, 0};
    size_t nu = 0, nv = 0;
    for (size_t r = 0; r < l.rows; ++r)
        for (size_t c = 0; c < l.cols; ++c) {
            const size_t i = r * l.cols + c;
            if (std::isnan(l.x[i]) || std::isnan(l.y[i])) continue;
            if (c + 1 < l.cols && !std::isnan(l.x[i + 1]) && !std::isnan(l.y[i + 1]))
                su[0] += l.x[i + 1] - l.x[i], su[1] += l.y[i + 1] - l.y[i], ++nu;
            if (r + 1 < l.rows && !std::isnan(l.x[i + l.cols]) && !std::isnan(l.y[i + l.cols]))
                sv[0] += l.x[i + l.cols] - l.x[i], sv[1] += l.y[i + l.cols] - l.y[i], ++nv;
        }
    if (!nu || !nv)
        f.fail(
            "the cell centres (x, y) have no two neighbouring valid cells along each axis: cannot find the grid's cell "
            "size");
    l.ux = su[0] / double(nu), l.uy = su[1] / double(nu), l.vx = sv[0] / double(nv), l.vy = sv[1] / double(nv);
}

}  // namespace

std::string sfincsRegularFormat(const std::shared_ptr<GDALGroup>& root) {
    MdFile f{"", nullptr, root};
    ArrayPtr x = f.find("x"), zb = f.find("zb");
    if (!x || !zb || x->GetDimensionCount() != 2 || zb->GetDimensionCount() != 2) return "";
    return "SFINCS regular map (NetCDF)";
}

ModelMesh readSfincsRegular(const std::string& path, std::shared_ptr<GDALDataset> keep, const MeshReadOptions& opt) {
    MdFile f{path, keep, keep->GetRootGroup()};
    ModelMesh m;
    m.source = path;
    m.format = sfincsRegularFormat(f.root);
    Lattice l;
    ArrayPtr xv = f.open("x", "cell centre x"), yv = f.open("y", "cell centre y");
    const std::vector<size_t> shape = shapeOf(xv);
    if (shapeOf(yv) != shape) f.fail("x and y differ in shape");
    l.rows = shape[0], l.cols = shape[1];
    l.x = f.read(xv), l.y = f.read(yv);
    fillToNaN(l.x, fillOf(xv)), fillToNaN(l.y, fillOf(yv));
    m.coordsFloat32 = xv->GetDataType().GetNumericDataType() == GDT_Float32;
    ArrayPtr zbv = f.open(opt.terrainVar.empty() ? "zb" : opt.terrainVar, "the bed level, --terrain-var");
    if (shapeOf(zbv) != shape)
        f.fail(zbv->GetName() + " is not shaped as x and y (" + std::to_string(l.rows) + " x " +
               std::to_string(l.cols) + ")");
    std::vector<double> zb = f.read(zbv);
    const size_t bedFills = fillToNaN(zb, fillOf(zbv));
    std::vector<double> msk;
    if (ArrayPtr mv = f.find("msk"); mv && shapeOf(mv) == shape) msk = f.read(mv);
    cellSteps(f, l);
    // One square face per active cell (msk > 0, or a bed value where there is no mask), corners at centre +- half
    // steps.
    std::vector<size_t> cells;
    for (size_t i = 0; i < l.x.size(); ++i) {
        if (std::isnan(l.x[i]) || std::isnan(l.y[i]) || std::isnan(zb[i]) || (!msk.empty() && !(msk[i] > 0))) continue;
        for (int k = 0; k < 4; ++k) {
            const double su = (k == 1 || k == 2) ? 0.5 : -0.5, sv = k >= 2 ? 0.5 : -0.5;
            m.nodeX.push_back(l.x[i] + su * l.ux + sv * l.vx);
            m.nodeY.push_back(l.y[i] + su * l.uy + sv * l.vy);
            m.faceNodes.push_back(uint32_t(m.nodeX.size() - 1));
        }
        m.faceStart.push_back(m.faceNodes.size());
        m.bed.values.push_back(zb[i]);
        cells.push_back(i);
    }
    if (cells.empty()) f.fail("no active cell (every cell masked out or without a bed level)");
    m.bed.at = MeshAt::Face;
    const size_t cols = l.cols;
    m.faceName = [cells, cols](size_t face) {
        return "cell (n " + std::to_string(cells[face] / cols) + ", m " + std::to_string(cells[face] % cols) + ")";
    };
    const double du = std::hypot(l.ux, l.uy), dv = std::hypot(l.vx, l.vy);
    m.quadtreeModel = std::abs(du - dv) <= 1e-3 * du;  // dx = dy: squares, one cell each; else sampled
    m.kind = fmt::format("a regular grid of {} x {} cells of {:.6g} x {:.6g} m, {} active", l.cols, l.rows, du, dv,
                         cells.size());
    if (bedFills) m.notes.push_back(std::to_string(bedFills) + " cells without a bed level (fill values) left out");
    if (ArrayPtr crs = f.find("crs")) {
        const std::string code = textAttr(crs, "epsg_code");
        if (!code.empty() && code != "EPSG:" && code != "EPSG:0" && code != "EPSG:-") m.crs = code;
    }
    if (m.crs.empty())
        m.warnings.push_back(
            path +
            ": crs:epsg_code names no CRS: coordinates taken as metres in a local frame (name the CRS with --s_srs)");
    // Water levels: zs (time, rows, cols) as x, or with the two grid dimensions the other way round.
    ArrayPtr zs =
        opt.waterSurfaceVar == "-" ? nullptr : f.find(opt.waterSurfaceVar.empty() ? "zs" : opt.waterSurfaceVar);
    if (!zs) return checkModelMesh(m), m;
    const std::vector<size_t> zshape = shapeOf(zs);
    const bool same = zshape.size() == 3 && zshape[1] == l.rows && zshape[2] == l.cols;
    const bool swapped = zshape.size() == 3 && zshape[1] == l.cols && zshape[2] == l.rows && !same;
    if (!same && !swapped)
        f.fail(zs->GetName() + " is not (time, " + std::to_string(l.rows) + ", " + std::to_string(l.cols) +
               ") as x and y are");
    ArrayPtr time = zs->GetDimensions()[0]->GetIndexingVariable();
    if (!time) time = f.find("time");
    if (!time) f.fail("no time variable for " + zs->GetName());
    m.timesS = cfTimesS(f, time);
    if (m.timesS.size() != zshape[0]) f.fail("the time variable and " + zs->GetName() + " differ in steps");
    const size_t rows = l.rows;
    m.level = [f, zs, cells, swapped, rows, cols](size_t k) {
        std::vector<double> all = f.readSlice(zs, k);
        fillToNaN(all, fillOf(zs));
        MeshField out;
        out.values.reserve(cells.size());
        for (size_t i : cells) out.values.push_back(all[swapped ? (i % cols) * rows + i / cols : i]);
        return out;
    };
    checkModelMesh(m);
    return m;
}

}  // namespace hc::ingest::detail
