// A model mesh's coordinates brought into the metric frame of a grid (mesh_frame.h).
#include "mesh_frame.h"

#include <algorithm>
#include <cmath>
#include <memory>

#include <fmt/format.h>
#include <ogr_spatialref.h>

#include "../gdal_util.h"
#include "heightcast/core/error.h"
#include "sample_mesh.h"

namespace hc::ingest::detail {
namespace {

struct Box {
    double x0 = HUGE_VAL, x1 = -HUGE_VAL, y0 = HUGE_VAL, y1 = -HUGE_VAL;
    bool degreesLike() const { return x0 >= -360 && x1 <= 360 && y0 >= -90 && y1 <= 90; }
};

Box boxOf(const ModelMesh& m) {
    Box b;
    for (uint32_t n : m.faceNodes) {
        b.x0 = std::min(b.x0, m.nodeX[n]), b.x1 = std::max(b.x1, m.nodeX[n]);
        b.y0 = std::min(b.y0, m.nodeY[n]), b.y1 = std::max(b.y1, m.nodeY[n]);
    }
    return b;
}

OGRSpatialReference parse(const ModelMesh& m, const std::string& text, const std::string& what) {
    OGRSpatialReference srs;
    if (srs.SetFromUserInput(text.c_str()) != OGRERR_NONE)
        throw Error(m.source + ": the CRS " + what + " '" + text.substr(0, 80) + "' is not one GDAL reads");
    srs.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
    return srs;
}

void transform(ModelMesh& m, const OGRSpatialReference& from, const OGRSpatialReference& to) {
    std::unique_ptr<OGRCoordinateTransformation> ct(OGRCreateCoordinateTransformation(&from, &to));
    if (!ct) throw Error(m.source + ": cannot transform the mesh's coordinates: " + lastGdalError());
    constexpr size_t kChunk = size_t{1} << 20;  // Transform counts in int
    std::vector<int> ok(kChunk);
    for (size_t b = 0; b < m.nodeX.size(); b += kChunk) {
        const size_t n = std::min(kChunk, m.nodeX.size() - b);
        if (ct->Transform(int(n), m.nodeX.data() + b, m.nodeY.data() + b, nullptr, ok.data())) continue;
        for (size_t i = 0; i < n; ++i)
            if (!ok[i])
                throw Error(m.source + ": node " + std::to_string(b + i) + " cannot be transformed from " +
                            crsName(&from) + " to " + crsName(&to));
    }
}

// Whether projected coordinates can lie in `srs`: their centre maps to a longitude/latitude within 5 degrees of the
// CRS's area of use (where it declares one).
bool plausible(const OGRSpatialReference& srs, const Box& b) {
    std::unique_ptr<OGRSpatialReference> geo(srs.CloneGeogCS());
    if (!geo) return true;
    geo->SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
    std::unique_ptr<OGRCoordinateTransformation> ct(OGRCreateCoordinateTransformation(&srs, geo.get()));
    double x = (b.x0 + b.x1) / 2, y = (b.y0 + b.y1) / 2;
    CPLErrorStateBackuper quiet;
    if (!ct || !ct->Transform(1, &x, &y) || !std::isfinite(x) || !std::isfinite(y)) return false;
    double w = 0, s = 0, e = 0, n = 0;
    const char* name = nullptr;
    if (!srs.GetAreaOfUse(&w, &s, &e, &n, &name) || w < -1000) return true;
    if (e < w) e += 360, x = x < w ? x + 360 : x;  // an area across 180 degrees
    return x >= w - 5 && x <= e + 5 && y >= s - 5 && y <= n + 5;
}

}  // namespace

MeshFrame meshToMetric(ModelMesh& m, const std::string& override, LoadReport& report) {
    MeshFrame fr;
    const Box box = boxOf(m);
    std::string text = override == "local" ? "" : override.empty() ? m.crs : override;
    if (text.empty()) {
        // Degrees by the numbers alone only where metres would make faces under a centimetre: no flood model's.
        if (override.empty() && box.degreesLike() && box.x1 - box.x0 < 20 && box.y1 - box.y0 < 20 &&
            finestFaceSide(m) < 0.01) {
            report.warnings.push_back(m.source +
                                      ": the mesh names no CRS and its coordinates look like degrees: taken as WGS 84 "
                                      "longitude/latitude (--s_srs names its CRS, --s_srs local insists on metres)");
            text = "EPSG:4326";
        } else {
            const bool said = std::any_of(report.warnings.begin(), report.warnings.end(), [&](const std::string& w) {
                return w.rfind(m.source, 0) == 0 && w.find("CRS") != std::string::npos;
            });
            if (!said && override.empty())
                report.warnings.push_back(m.source +
                                          ": the mesh names no CRS: coordinates taken as metres in a local frame (name "
                                          "the CRS with --s_srs)");
            return fr;
        }
    }
    const std::string what = override.empty() ? "the file names" : "--s_srs";
    OGRSpatialReference srs = parse(m, text, what);
    fr.sourceCrsName = crsName(&srs);
    if (srs.IsGeographic()) {
        if (!box.degreesLike()) {
            report.warnings.push_back(fmt::format(
                "{}: the CRS {} is geographic, but the coordinates reach {:.9g}, {:.9g}: not degrees; taken as "
                "metres in a local frame (--s_srs names the right CRS)",
                m.source, fr.sourceCrsName, box.x1, box.y1));
            return fr;
        }
        const double lon = std::remainder((box.x0 + box.x1) / 2, 360.0), lat = (box.y0 + box.y1) / 2;
        const int zone = std::clamp(int(std::floor((lon + 180) / 6)) + 1, 1, 60);
        OGRSpatialReference utm;
        utm.CopyGeogCSFrom(&srs);
        utm.SetUTM(zone, lat >= 0);
        utm.SetProjCS(
            fmt::format("{} / UTM zone {}{}", srs.GetName() ? srs.GetName() : "unnamed", zone, lat >= 0 ? "N" : "S")
                .c_str());
        utm.AutoIdentifyEPSG();  // WGS 84's zones become EPSG:326zz / 327zz
        utm.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
        transform(m, srs, utm);
        fr.crsWkt = toWkt(utm), fr.crsName = crsName(&utm);
        fr.moved = fr.geographic = true;
        return fr;
    }
    if (!srs.IsProjected() || !plausible(srs, box)) {
        report.warnings.push_back(fmt::format(
            "{}: the coordinates ({:.9g}..{:.9g}, {:.9g}..{:.9g}) cannot lie in {} ({}): taken as metres in a "
            "local frame (--s_srs names the right CRS)",
            m.source, box.x0, box.x1, box.y0, box.y1, fr.sourceCrsName,
            srs.IsProjected() ? "outside its area of use" : "not a projected CRS"));
        fr.sourceCrsName.clear();
        return fr;
    }
    if (std::abs(srs.GetLinearUnits() - 1.0) > 1e-12) {
        OGRSpatialReference metric(srs);
        metric.SetLinearUnitsAndUpdateParameters(SRS_UL_METER, 1.0);
        metric.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
        transform(m, srs, metric);
        report.warnings.push_back(fmt::format(
            "{}: the CRS's unit is {:.10g} m: coordinates converted to metres (the same projection in metres); "
            "levels are taken as the reader gave them",
            m.source, srs.GetLinearUnits()));
        fr.crsWkt = toWkt(metric), fr.crsName = crsName(&metric), fr.moved = true;
        return fr;
    }
    fr.crsWkt = toWkt(srs), fr.crsName = fr.sourceCrsName;
    return fr;
}

void meshToTarget(ModelMesh& m, const std::string& override, const std::string& targetWkt, LoadReport& report) {
    const std::string text = override == "local" ? "" : override.empty() ? m.crs : override;
    if (text.empty() || targetWkt.empty()) {
        if (text.empty() && !targetWkt.empty())
            report.warnings.push_back(m.source +
                                      ": the mesh names no CRS: its coordinates are taken in the terrain's CRS "
                                      "(--mesh-srs names the mesh's)");
        if (!text.empty() && targetWkt.empty())
            report.warnings.push_back(
                m.source +
                ": the terrain has no CRS: the mesh's coordinates are taken as they are, in the terrain's frame");
        return;
    }
    OGRSpatialReference from = parse(m, text, override.empty() ? "the file names" : "--mesh-srs"), to;
    to.importFromWkt(targetWkt.c_str());
    to.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
    if (!from.IsSame(&to)) transform(m, from, to);
}

}  // namespace hc::ingest::detail
