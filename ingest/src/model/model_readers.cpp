// The model formats read here, told apart by what their files hold, and the checks every mesh passes (mesh.h).
#include <cmath>
#include <filesystem>

#include "../gdal_util.h"
#include "heightcast/core/error.h"
#include "readers.h"

namespace hc::ingest {

namespace detail {

std::shared_ptr<GDALGroup> openMultidimRoot(const std::string& path, std::shared_ptr<GDALDataset>& keep) {
    ensureGdal();
    CPLErrorStateBackuper quiet;  // a file that is no multidimensional dataset leaves no error behind
    const char* const drivers[] = {"netCDF", "HDF5", nullptr};
    GDALDataset* ds =
        GDALDataset::Open(path.c_str(), GDAL_OF_MULTIDIM_RASTER | GDAL_OF_READONLY, drivers, nullptr, nullptr);
    if (!ds) return nullptr;
    keep = std::shared_ptr<GDALDataset>(ds, [](GDALDataset* d) { GDALClose(GDALDataset::ToHandle(d)); });
    return keep->GetRootGroup();
}

}  // namespace detail

namespace {

using Probe = std::string (*)(const std::shared_ptr<GDALGroup>&);
using Reader = ModelMesh (*)(const std::string&, std::shared_ptr<GDALDataset>, const MeshReadOptions&);
struct Format {
    Probe probe;
    Reader read;
};
// Most specific first: SFINCS, 3Di and TUFLOW FV files may carry UGRID attributes too.
const Format kFormats[] = {
    {detail::hecRasFormat, detail::readHecRas},     {detail::sfincsRegularFormat, detail::readSfincsRegular},
    {detail::swwFormat, detail::readSww},           {detail::threeDiFormat, detail::readThreeDi},
    {detail::tuflowFvFormat, detail::readTuflowFv}, {detail::ugridFormat, detail::readUgrid}};

// A .2dm mesh alone: terrain only (its nodes' z), no results.
bool isTwoDm(const std::string& path) {
    return detail::lower(std::filesystem::path(path).extension().string()) == ".2dm" &&
           std::filesystem::is_regular_file(path);
}

}  // namespace

std::string modelFormatOf(const std::string& path) {
    if (detail::isSelafin(path)) return "TELEMAC Selafin";
    if (isTwoDm(path)) return "SMS/TUFLOW .2dm mesh (terrain only)";
    if (std::string f = detail::xmdfFormat(path); !f.empty()) return f;
    std::shared_ptr<GDALDataset> keep;
    auto root = detail::openMultidimRoot(path, keep);
    if (!root) return "";
    CPLErrorStateBackuper quiet;
    for (const Format& f : kFormats)
        if (std::string name = f.probe(root); !name.empty()) return name;
    return "";
}

std::string unreadModelFormat(const std::string& path) {
    const std::string ext = detail::lower(std::filesystem::path(path).extension().string());
    if (ext == ".dfsu" || ext == ".dfs2")
        return "a MIKE 21 result (" + ext +
               "): not read here; convert it to a UGRID NetCDF map (mikeio: Dataset.to_xarray, "
               "then xugrid) or export the water level as GeoTIFFs per step (--water-surface)";
    if (ext == ".xmdf")
        return "an XMDF result without its mesh: put the .2dm beside it (NAME.2dm for NAME.xmdf, or MODEL.2dm for "
               "MODEL_anything.xmdf)";
    if (ext == ".dat")
        return "an SMS ASCII/binary .dat result: not read here; export the water level as GeoTIFFs per step from SMS "
               "or "
               "QGIS's mesh tools (--water-surface), or convert to XMDF or a UGRID NetCDF map";
    if (ext == ".sqlite" || ext == ".gpkg")
        return "a model's geometry database: give its results file (results_3di.nc)";
    return "";
}

ModelMesh readModelMesh(const std::string& path, const MeshReadOptions& opt) {
    if (detail::isSelafin(path)) return detail::readSelafin(path, opt);
    if (isTwoDm(path)) return readTwoDmMesh(path);
    if (!detail::xmdfFormat(path).empty()) return detail::readXmdf(path, opt);
    std::shared_ptr<GDALDataset> keep;
    auto root = detail::openMultidimRoot(path, keep);
    if (!root) {
        if (std::string hint = unreadModelFormat(path); !hint.empty()) throw Error(path + ": " + hint);
        throw Error(path +
                    ": cannot be opened as a model result (NetCDF, HDF5 or Selafin): " + detail::lastGdalError());
    }
    for (const Format& f : kFormats) {
        bool match = false;
        {
            CPLErrorStateBackuper quiet;
            match = !f.probe(root).empty();
        }
        if (match) return f.read(path, keep, opt);
    }
    throw Error(path +
                ": a NetCDF/HDF5 file holding no model result read here (no UGRID mesh_topology variable, and not "
                "a SFINCS, HEC-RAS 2D, ANUGA, 3Di or TUFLOW FV result); a raster variable is read as a raster: "
                "'NETCDF:\"" +
                path + "\":VAR'");
}

void checkModelMesh(const ModelMesh& m) {
    auto fail = [&](const std::string& what) { throw Error(m.source + ": " + what); };
    if (m.nodeX.size() != m.nodeY.size()) fail("the node coordinates differ in length");
    if (m.faceStart.empty() || m.faceStart.back() != m.faceNodes.size()) fail("the faces' node lists are inconsistent");
    if (m.faceCount() == 0) fail("no 2-D face: nothing to ingest");
    for (size_t i = 0; i < m.nodeX.size(); ++i)
        if (!std::isfinite(m.nodeX[i]) || !std::isfinite(m.nodeY[i]))
            fail("node " + std::to_string(i) + " has no coordinates (NaN or a fill value)");
    for (size_t f = 0; f < m.faceCount(); ++f) {
        if (m.faceStart[f + 1] < m.faceStart[f] || m.nodesOf(f) < 3)
            fail(m.nameOf(f) + " has " + std::to_string(m.nodesOf(f)) + " nodes: a face has 3 or more");
        for (uint64_t k = m.faceStart[f]; k < m.faceStart[f + 1]; ++k)
            if (m.faceNodes[k] >= m.nodeX.size())
                fail(m.nameOf(f) + " names node " + std::to_string(m.faceNodes[k]) + ", not one of the " +
                     std::to_string(m.nodeX.size()) + " nodes");
    }
    const size_t need[2] = {m.faceCount(), m.nodeX.size()};
    if (!m.bed.values.empty() && m.bed.values.size() != need[m.bed.at == MeshAt::Node])
        fail("the bed has " + std::to_string(m.bed.values.size()) + " values for " +
             std::to_string(need[m.bed.at == MeshAt::Node]) + (m.bed.at == MeshAt::Node ? " nodes" : " faces"));
    for (size_t k = 1; k < m.timesS.size(); ++k)
        if (!(m.timesS[k] > m.timesS[k - 1]))
            fail("the times do not increase: step " + std::to_string(k) + " at " + detail::fmt(m.timesS[k], 9) +
                 " s follows " + detail::fmt(m.timesS[k - 1], 9) + " s");
    if (!m.timesS.empty() && !m.level) fail("steps without water levels");
}

}  // namespace hc::ingest
