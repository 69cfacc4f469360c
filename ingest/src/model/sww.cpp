// ANUGA .sww results (NetCDF: triangles, node stage over time) -> ModelMesh.
#include <cctype>
#include <cmath>

#include "../gdal_util.h"
#include "heightcast/core/error.h"
#include "md_util.h"
#include "readers.h"

namespace hc::ingest::detail {
namespace {

// The triangles (volumes, 0-based node indexes) and the nodes (x, y plus the file's xllcorner, yllcorner).
void readTriangles(const MdFile& f, ModelMesh& m) {
    readNodes(f, "x", "y", m);
    const double x0 = rootNum(f, "xllcorner").value_or(0), y0 = rootNum(f, "yllcorner").value_or(0);
    for (size_t i = 0; i < m.nodeX.size(); ++i) m.nodeX[i] += x0, m.nodeY[i] += y0;

    ArrayPtr vol = f.open("volumes", "the triangles");
    const std::vector<size_t> shape = shapeOf(vol);
    if (shape.size() != 2 || shape[1] != 3) f.fail("volumes is not (triangles, 3)");
    const std::vector<double> v = f.read(vol);
    const double nodes = double(m.nodeX.size());
    m.faceNodes.reserve(v.size());
    m.faceStart.assign(1, 0);
    for (size_t t = 0; t < shape[0]; ++t) {
        for (size_t k = 0; k < 3; ++k) {
            const double node = v[t * 3 + k];
            if (!(node >= 0 && node < nodes) || node != std::floor(node))
                f.fail("triangle " + std::to_string(t) + " (volumes) names node " + fmt(node, 9) + ", not one of the " +
                       std::to_string(m.nodeX.size()) + " nodes");
            m.faceNodes.push_back(uint32_t(node));
        }
        m.faceStart.push_back(m.faceNodes.size());
    }
    m.faceName = [](size_t face) { return "triangle " + std::to_string(face); };
    if (lower(rootText(f, "vertices_are_stored_uniquely")) == "true")
        m.notes.push_back("nodes stored per triangle (not smoothed): each triangle linear over its own three nodes");
}

// One value per node of a (nodes) variable, or of step `k` of a (time, nodes) one; fill values become NaN.
std::vector<double> nodeValues(const MdFile& f, const ArrayPtr& a, size_t nodes, size_t k, size_t& fills) {
    const std::vector<size_t> shape = shapeOf(a);
    const bool timed = shape.size() == 2;
    if ((shape.size() != 1 && !timed) || shape.back() != nodes)
        f.fail(a->GetName() + " is not a node variable: (" + std::to_string(nodes) + ") or (time, " +
               std::to_string(nodes) + ")");
    std::vector<double> v = timed ? f.readSlice(a, k) : f.read(a);
    fills += fillToNaN(v, fillOf(a));
    return v;
}

// The bed: elevation (ANUGA), z (older files), or --terrain-var; a time-varying bed's first step.
void readBed(const MdFile& f, const MeshReadOptions& opt, ModelMesh& m) {
    ArrayPtr bed =
        !opt.terrainVar.empty() ? f.open(opt.terrainVar, "the bed level, --terrain-var") : f.find("elevation");
    if (!bed) bed = f.find("z");
    if (!bed) {
        m.warnings.push_back(f.path +
                             ": no bed level (elevation, z; --terrain-var names one): a DEM must give the terrain");
        return;
    }
    size_t fills = 0;
    m.bed.at = MeshAt::Node;
    m.bed.values = nodeValues(f, bed, m.nodeX.size(), 0, fills);
    if (shapeOf(bed).size() == 2 && shapeOf(bed)[0] > 1)
        m.warnings.push_back(f.path + ": the bed " + bed->GetName() +
                             " varies over time: its first step taken as the terrain "
                             "(--terrain-var names another)");
    if (fills)
        m.warnings.push_back(f.path + ": " + std::to_string(fills) + " values of " + bed->GetName() +
                             " are fill values: holes");
}

// A PROJ string for UTM zone `zone` on an ANUGA datum other than WGS 84 ("" when the datum is unknown).
std::string utmProj(const std::string& datum, int zone, bool south) {
    std::string base = "+proj=utm +zone=" + std::to_string(zone) + (south ? " +south" : "");
    if (datum == "gda94" || datum == "gda2020" || datum == "grs80")
        return base + " +ellps=GRS80 +towgs84=0,0,0 +units=m +no_defs";
    if (datum == "nad83") return base + " +datum=NAD83 +units=m +no_defs";
    if (datum == "nad27") return base + " +datum=NAD27 +units=m +no_defs";
    // Australia's older datums and ED50, with EPSG's mean shifts to WGS 84.
    if (datum == "agd66") return base + " +ellps=aust_SA +towgs84=-133,-48,148,0,0,0,0 +units=m +no_defs";
    if (datum == "agd84") return base + " +ellps=aust_SA +towgs84=-134,-48,149,0,0,0,0 +units=m +no_defs";
    if (datum == "ed50") return base + " +ellps=intl +towgs84=-87,-98,-121,0,0,0,0 +units=m +no_defs";
    return "";
}

// ANUGA's georeference (zone, hemisphere or false_northing, datum, projection) as a CRS GDAL reads; "" and a warning
// where it names none (ANUGA writes zone -1 when the model was set up without one).
std::string swwCrs(const MdFile& f, ModelMesh& m) {
    const std::string noCrs = ": coordinates taken as metres in a local frame (name the CRS with --s_srs)";
    const std::optional<double> zoneNum = rootNum(f, "zone");
    const std::string projection = lower(rootText(f, "projection"));
    if (!zoneNum || !(*zoneNum >= 1 && *zoneNum <= 60) || *zoneNum != std::floor(*zoneNum)) {
        m.warnings.push_back(f.path + ": the georeference names no UTM zone (zone " +
                             (zoneNum ? fmt(*zoneNum) : "missing") + ")" + noCrs);
        return "";
    }
    if (!projection.empty() && projection != "utm") {
        m.warnings.push_back(f.path + ": the georeference's projection is '" + projection + "', not UTM" + noCrs);
        return "";
    }
    const int zone = int(*zoneNum);
    // The hemisphere as newer ANUGA writes it; else from the false northing (10 000 000 m: the southern one).
    const std::string hemi = lower(rootText(f, "hemisphere"));
    bool south = hemi.rfind("s", 0) == 0;
    if (hemi.rfind("s", 0) != 0 && hemi.rfind("n", 0) != 0) {
        const double fn = rootNum(f, "false_northing").value_or(0);
        south = fn >= 5e6;
        m.warnings.push_back(f.path + ": no hemisphere named: UTM zone " + std::to_string(zone) + (south ? "S" : "N") +
                             " taken from the false northing " + fmt(fn, 10) + " m (--s_srs names another CRS)");
    }
    std::string datum;
    for (char c : lower(rootText(f, "datum")))
        if (std::isalnum(static_cast<unsigned char>(c))) datum += c;
    if (datum.empty() || datum == "wgs84" || datum == "wgs1984")
        return "EPSG:" + std::to_string((south ? 32700 : 32600) + zone);
    std::string proj = utmProj(datum, zone, south);
    if (proj.empty()) {
        m.warnings.push_back(f.path + ": the datum '" + rootText(f, "datum") + "' is not one known here: UTM zone " +
                             std::to_string(zone) + " on WGS 84 taken (--s_srs names another CRS)");
        proj = "EPSG:" + std::to_string((south ? 32700 : 32600) + zone);
    }
    return proj;
}

// A (time, nodes) variable read a step at a time.
std::function<MeshField(size_t)> nodeSteps(const MdFile& f, const ArrayPtr& a, size_t nodes) {
    return [f, a, nodes](size_t k) {
        size_t fills = 0;
        return MeshField{MeshAt::Node, nodeValues(f, a, nodes, k, fills)};
    };
}

// The times (seconds after the file's starttime), the stage over them, and the step layers.
void readSteps(const MdFile& f, const MeshReadOptions& opt, ModelMesh& m) {
    if (opt.waterSurfaceVar == "-") return;
    ArrayPtr stage = f.find(opt.waterSurfaceVar.empty() ? "stage" : opt.waterSurfaceVar);
    if (!stage && !opt.waterSurfaceVar.empty())
        f.fail("no variable '" + opt.waterSurfaceVar + "' (--water-surface-var)");
    if (!stage) {
        m.notes.push_back("no stage variable: a terrain mesh only");
        return;
    }
    const size_t nodes = m.nodeX.size();
    const std::vector<size_t> shape = shapeOf(stage);
    if (shape.size() != 2 || shape[1] != nodes)
        f.fail(stage->GetName() + " is not a (time, " + std::to_string(nodes) + " nodes) variable");
    ArrayPtr time = f.open("time", "the output times");
    m.timesS = f.read(time);
    if (m.timesS.size() != shape[0])
        f.fail("time has " + std::to_string(m.timesS.size()) + " steps, " + stage->GetName() + " " +
               std::to_string(shape[0]));
    // NetCDF classic files read as zeros past their end: a time of 0 after the first step says the file was cut short.
    for (size_t k = 1; k < m.timesS.size(); ++k)
        if (m.timesS[k] == 0 && m.timesS[k - 1] >= 0)
            f.fail("time is 0 at step " + std::to_string(k) + " of " + std::to_string(m.timesS.size()) +
                   ": the file is cut short (a NetCDF classic file reads as zeros past its end)");
    checkIncreasing(f, m.timesS, "time");
    if (const double start = rootNum(f, "starttime").value_or(0); start != 0)
        m.notes.push_back("times are seconds after the run's starttime " + fmt(start, 12) + " s");
    m.level = nodeSteps(f, stage, nodes);
    for (const std::string& name : opt.layerVars) {
        ArrayPtr a = f.open(name, "--face-layers");
        if (shapeOf(a) != shape) f.fail(name + " is not shaped as the stage (time, nodes): a step layer must be");
        m.layers.push_back({name, a->GetUnit().empty() ? textAttr(a, "units") : a->GetUnit(), nodeSteps(f, a, nodes)});
    }
}

}  // namespace

std::string swwFormat(const std::shared_ptr<GDALGroup>& root) {
    return holds(root, {"volumes", "x", "y"}, {"stage", "elevation", "z"}) ? "ANUGA sww" : "";
}

ModelMesh readSww(const std::string& path, std::shared_ptr<GDALDataset> keep, const MeshReadOptions& opt) {
    MdFile f{path, keep, keep->GetRootGroup()};
    if (!f.root) f.fail("no NetCDF root group");
    ModelMesh m;
    m.source = path;
    m.format = "ANUGA sww";
    m.kind = "triangles";
    readTriangles(f, m);
    readBed(f, opt, m);
    m.crs = swwCrs(f, m);
    readSteps(f, opt, m);
    checkModelMesh(m);
    return m;
}

}  // namespace hc::ingest::detail
