// HEC-RAS 2D plan results and geometry files (HDF5, HEC-RAS 5 and 6) read into a ModelMesh (mesh.h, readers.h).
#include <algorithm>
#include <cfloat>
#include <cmath>
#include <memory>
#include <optional>

#include <ogr_spatialref.h>

#include "../gdal_util.h"
#include "heightcast/core/error.h"
#include "md_util.h"
#include "readers.h"

namespace hc::ingest::detail {
namespace {

// Where HEC-RAS keeps the 2-D flow areas' geometry, and the time series of the plan's base output.
const std::string kGeometry = "/Geometry/2D Flow Areas";
const std::string kSeries = "/Results/Unsteady/Output/Output Blocks/Base Output/Unsteady Time Series";
const std::string kBedVar = "Cells Minimum Elevation";
const std::string kLevelVar = "Water Surface";
constexpr double kFootM = 0.3048;
constexpr double kUsSurveyFootM = 1200.0 / 3937.0;

std::shared_ptr<GDALGroup> group(const std::shared_ptr<GDALGroup>& root, const std::string& path) {
    CPLErrorStateBackuper quiet;
    return root ? root->OpenGroupFromFullname(path) : nullptr;
}

// The values of a one-dimensional text variable (area names), trimmed of HEC-RAS's padding.
std::vector<std::string> readStrings(const MdFile& f, const ArrayPtr& a) {
    const std::vector<size_t> shape = shapeOf(a);
    if (shape.size() != 1) f.fail("'" + a->GetFullName() + "' is not a list of names");
    std::vector<char*> raw(shape[0], nullptr);
    const GUInt64 start = 0;
    const size_t count = shape[0];
    const bool ok =
        !count || a->Read(&start, &count, nullptr, nullptr, GDALExtendedDataType::CreateString(), raw.data());
    std::vector<std::string> out;
    for (char* s : raw) out.push_back(trim(s ? s : "")), CPLFree(s);
    if (!ok) f.fail("cannot read the names '" + a->GetFullName() + "': " + lastGdalError());
    return out;
}

// How many rows a table of the geometry has (cross sections, storage areas), 0 where it is missing.
size_t rowsOf(const MdFile& f, const std::string& path) {
    ArrayPtr a = f.find(path);
    const std::vector<size_t> shape = a ? shapeOf(a) : std::vector<size_t>{};
    return shape.empty() ? 0 : shape[0];
}

// A 2-D flow area as listed by the file: its name and, where the file says, how many of its cells are real (the rest
// of its cell rows are the virtual cells HEC-RAS adds outside the perimeter for the boundary conditions).
struct AreaRef {
    std::string name;
    std::optional<size_t> realCells;
};

// The areas in the file's order: HEC-RAS 5.0.5 and 6 list them in the compound table 'Attributes' (Name, Cell Count),
// 5.0.0 in 'Names'; failing both, the area groups as GDAL lists them.
std::vector<AreaRef> listAreas(const MdFile& f) {
    std::vector<AreaRef> out;
    if (ArrayPtr attrs = f.find(kGeometry + "/Attributes")) {
        CPLErrorStateBackuper quiet;
        ArrayPtr names = attrs->GetView("[\"Name\"]"), counts = attrs->GetView("[\"Cell Count\"]");
        if (names) {
            const std::vector<std::string> n = readStrings(f, names);
            const std::vector<double> c = counts ? f.read(counts) : std::vector<double>{};
            for (size_t i = 0; i < n.size(); ++i)
                out.push_back({n[i], i < c.size() && c[i] >= 0 ? std::optional<size_t>(size_t(c[i])) : std::nullopt});
        }
    } else if (ArrayPtr names = f.find(kGeometry + "/Names")) {
        for (const std::string& n : readStrings(f, names)) out.push_back({n, std::nullopt});
    }
    if (out.empty())
        if (auto g = group(f.root, kGeometry))
            for (const std::string& n : g->GetGroupNames()) out.push_back({n, std::nullopt});
    return out;
}

// One area as read into the mesh: its faces [firstFace, firstFace + cells.size()) are its cells `cells` (the file's
// cell indexes, which index its result columns too), out of `cellRows` rows.
struct Area {
    std::string name;
    size_t firstFace = 0, cellRows = 0;
    std::vector<uint32_t> cells;
};
using Areas = std::shared_ptr<std::vector<Area>>;

// The virtual cells HEC-RAS adds outside each area's perimeter (for its boundary conditions) come after its real
// cells. HEC-RAS 5.0.5 and 6 give the real cells' count; 5.0.0 does not: there the virtual cells are the rows at the
// end with fewer than 3 face points (they hold 2, the ends of the perimeter face they lie beyond).
size_t realCells(const AreaRef& ref, const std::vector<double>& corners, size_t rows, size_t width) {
    if (ref.realCells) return std::min(*ref.realCells, rows);
    size_t real = rows;
    auto used = [&](size_t c) {
        return std::count_if(corners.begin() + ptrdiff_t(c * width), corners.begin() + ptrdiff_t((c + 1) * width),
                             [](double v) { return v >= 0; });
    };
    while (real > 0 && used(real - 1) < 3) --real;
    return real;
}

// The area's real cells appended as faces, each its face points in order up to the first -1 of the padding (cells
// of fewer than 3 face points left out, with a warning); the nodes of the area start at `firstNode`.
void appendCells(const MdFile& f, const AreaRef& ref, size_t firstNode, size_t points, Area& area, ModelMesh& m) {
    const std::string in = " of 2-D area '" + ref.name + "'";
    ArrayPtr idx = f.open(kGeometry + "/" + ref.name + "/Cells FacePoint Indexes", "the cells' face points" + in);
    const std::vector<size_t> shape = shapeOf(idx);
    if (shape.size() != 2 || shape[1] < 3) f.fail("the cells' face point lists" + in + " are not (cell, corner) rows");
    const std::vector<double> corners = f.read(idx);
    const size_t rows = shape[0], width = shape[1], real = realCells(ref, corners, rows, width);
    area.cellRows = rows;
    size_t degenerate = 0;
    for (size_t c = 0; c < real; ++c) {
        const double* row = &corners[c * width];
        size_t n = 0;
        for (; n < width && row[n] >= 0; ++n)
            if (row[n] >= double(points))
                f.fail("cell " + std::to_string(c) + in + " names face point " + fmt(row[n], 12) + ", not one of its " +
                       std::to_string(points));
        if (n < 3) {
            ++degenerate;
            continue;
        }
        for (size_t j = 0; j < n; ++j) m.faceNodes.push_back(uint32_t(firstNode + size_t(row[j])));
        m.faceStart.push_back(m.faceNodes.size());
        area.cells.push_back(uint32_t(c));
    }
    if (real < rows)
        m.notes.push_back(std::to_string(rows - real) + " virtual boundary cells" + in + " past its " +
                          std::to_string(real) + " cells (not drawn)");
    if (degenerate)
        m.warnings.push_back(f.path + ": " + std::to_string(degenerate) + " cells" + in +
                             " have fewer than 3 face points: left out");
}

// The bed of the area's faces [m]: its cells' minimum elevation (or --terrain-var's), NaN where there is none.
void appendBed(const MdFile& f, const Area& area, const MeshReadOptions& opt, double toM, ModelMesh& m) {
    const std::string in = " of 2-D area '" + area.name + "'";
    const std::string var = opt.terrainVar.empty() ? kBedVar : opt.terrainVar;
    ArrayPtr bed = f.find(kGeometry + "/" + area.name + "/" + var);
    if (!bed) {
        if (!opt.terrainVar.empty()) f.fail("no variable '" + var + "'" + in + " (--terrain-var)");
        return;
    }
    std::vector<double> z = f.read(bed);
    if (z.size() != area.cellRows)
        f.fail("'" + var + "'" + in + " has " + std::to_string(z.size()) + " values for its " +
               std::to_string(area.cellRows) + " cells");
    fillToNaN(z, fillOf(bed));
    size_t none = 0;
    for (uint32_t c : area.cells) {
        m.bed.values.push_back(z[c] * toM);
        none += std::isnan(z[c]);
    }
    if (none)
        m.warnings.push_back(f.path + ": " + std::to_string(none) + " cells" + in + " have no '" + var +
                             "' (NaN): no bed there unless a DEM is given");
}

// One 2-D flow area appended to the mesh: its face points as nodes (offset by those of the areas before), its real
// cells as faces, their bed. Returns the area with its map from faces to the file's cells.
Area readArea(const MdFile& f, const AreaRef& ref, const MeshReadOptions& opt, double toM, ModelMesh& m) {
    const std::string in = " of 2-D area '" + ref.name + "'";
    ArrayPtr xy = f.open(kGeometry + "/" + ref.name + "/FacePoints Coordinate", "the face points" + in);
    const std::vector<size_t> shape = shapeOf(xy);
    if (shape.size() != 2 || shape[1] != 2) f.fail("the face points" + in + " are not (point, x/y) pairs");
    const size_t firstNode = m.nodeX.size();
    const std::vector<double> coords = f.read(xy);
    for (size_t p = 0; p < shape[0]; ++p) m.nodeX.push_back(coords[2 * p]), m.nodeY.push_back(coords[2 * p + 1]);
    if (m.nodeX.size() > UINT32_MAX)
        f.fail("more face points than 32-bit node indexes hold (at 2-D area '" + ref.name + "')");
    Area area{ref.name, m.faceCount(), 0, {}};
    appendCells(f, ref, firstNode, shape[0], area, m);
    appendBed(f, area, opt, toM, m);
    return area;
}

// Metres per unit of the file's elevations, with the warning that says so where they are feet.
double elevationUnit(const MdFile& f, const OGRSpatialReference* srs, ModelMesh& m) {
    const std::string system = rootText(f, "Units System");
    const std::string low = lower(system);
    if (low.find("us customary") != std::string::npos || low.find("english") != std::string::npos) {
        const bool survey = srs && srs->IsProjected() && std::abs(srs->GetLinearUnits() - kUsSurveyFootM) < 1e-9;
        const double foot = survey ? kUsSurveyFootM : kFootM;
        m.warnings.push_back(f.path + ": the root attribute 'Units System' is '" + system +
                             "': bed and water levels converted from " +
                             (survey ? "US survey feet (the CRS's unit)" : "international feet") + " to metres (x " +
                             fmt(foot, 10) + "); node coordinates stay in the CRS's units");
        return foot;
    }
    if (low.find("si") == std::string::npos)
        m.warnings.push_back(f.path + ": the root attribute 'Units System' is " +
                             (system.empty() ? "missing" : "'" + system + "'") + ": levels taken as metres");
    return 1;
}

// The CRS from the root attribute 'Projection' (ESRI WKT), or "" with a warning.
std::string readCrs(const MdFile& f, OGRSpatialReference& srs, ModelMesh& m) {
    const std::string text = rootText(f, "Projection");
    std::string local = ": coordinates taken as metres in a local frame unless --s_srs names one";
    if (lower(rootText(f, "Units System")).find("us customary") != std::string::npos)
        local += " (the file's units are US customary: its coordinates are likely feet)";
    if (text.empty()) {
        m.warnings.push_back(f.path + ": names no CRS (root attribute 'Projection' missing or empty)" + local);
        return "";
    }
    CPLErrorStateBackuper quiet;
    if (srs.SetFromUserInput(text.c_str()) != OGRERR_NONE) {
        m.warnings.push_back(f.path + ": the root attribute 'Projection' is no CRS GDAL reads ('" + text.substr(0, 60) +
                             "...')" + local);
        srs.Clear();
        return "";
    }
    return text;
}

// The times of the output [s] from 'Time' (days since the start, as HEC-RAS writes them; its unit from the attribute
// 'Time' in 6, 'Variables' = "Time|Days" in 5), rounded to the millisecond of HEC-RAS's own time stamps so that days
// stored as doubles give whole seconds.
std::vector<double> readTimes(const MdFile& f, ModelMesh& m) {
    ArrayPtr time = f.open(kSeries + "/Time", "the output times");
    std::string unit = lower(textAttr(time, "Time"));
    if (unit.empty()) unit = lower(textAttr(time, "Variables"));
    if (unit.rfind("time|", 0) == 0) unit = unit.substr(5);
    unit = trim(unit);
    double seconds = 86400;
    if (unit.rfind("hour", 0) == 0)
        seconds = 3600;
    else if (unit.rfind("min", 0) == 0)
        seconds = 60;
    else if (unit.rfind("sec", 0) == 0)
        seconds = 1;
    else if (unit.rfind("day", 0) != 0)
        m.warnings.push_back(f.path + ": the output times name no unit ('" + unit +
                             "'): taken as days since the start");
    std::vector<double> t = f.read(time);
    if (auto actual = numAttr(time, "Number of actual Time Steps");
        actual && *actual >= 0 && size_t(*actual) < t.size())
        t.resize(size_t(*actual));
    for (double& v : t) v = std::round(v * seconds * 1000) / 1000 + 0.0;  // + 0.0: no -0
    checkIncreasing(f, t, "'Time' of the base output");
    return t;
}

// The per-cell result `var` of each area (time, cell rows), checked against the times and the area's cells.
std::vector<ArrayPtr> cellSeries(const MdFile& f, const std::vector<Area>& areas, const std::string& var, size_t steps,
                                 const std::string& option) {
    std::vector<ArrayPtr> out;
    for (const Area& a : areas) {
        const std::string in = " of 2-D area '" + a.name + "'";
        ArrayPtr arr = f.find(kSeries + "/2D Flow Areas/" + a.name + "/" + var);
        if (!arr) {
            std::string have;
            if (auto g = group(f.root, kSeries + "/2D Flow Areas/" + a.name))
                for (const std::string& n : g->GetMDArrayNames()) have += (have.empty() ? "" : ", ") + n;
            f.fail("no result '" + var + "'" + in + option + " (it has: " + (have.empty() ? "none" : have) + ")");
        }
        const std::vector<size_t> s = shapeOf(arr);
        const size_t used = a.cells.empty() ? 0 : a.cells.back() + 1;
        if (s.size() != 2 || s[0] < steps)
            f.fail("'" + var + "'" + in + " is not a (time, cell) result of " + std::to_string(steps) + " steps");
        if (s[1] != a.cellRows && s[1] != used)
            f.fail("'" + var + "'" + in + " has " + std::to_string(s[1]) + " values per step for its " +
                   std::to_string(a.cellRows) + " cells (per face rather than per cell?)");
        out.push_back(arr);
    }
    return out;
}

// Step `k` of the areas' results `arrays` on the mesh's faces, times `scale`.
MeshField readStep(const MdFile& f, const std::vector<Area>& areas, const std::vector<ArrayPtr>& arrays, size_t faces,
                   size_t k, double scale) {
    MeshField out{MeshAt::Face, std::vector<double>(faces, NAN)};
    for (size_t i = 0; i < areas.size(); ++i) {
        const Area& a = areas[i];
        std::vector<double> v = f.readSlice(arrays[i], k);
        const size_t need = a.cells.empty() ? 0 : a.cells.back() + 1;
        if (v.size() < need)
            f.fail("'" + arrays[i]->GetName() + "' of 2-D area '" + a.name + "' at step " + std::to_string(k) +
                   " has " + std::to_string(v.size()) + " values for its " + std::to_string(a.cellRows) + " cells");
        fillToNaN(v, fillOf(arrays[i]));
        for (size_t j = 0; j < a.cells.size(); ++j) out.values[a.firstFace + j] = v[a.cells[j]] * scale;
    }
    return out;
}

// HEC-RAS gives a dry cell a water surface a float32 step or so above its minimum elevation (both stored as float32),
// which would make it wet by a fraction of a millimetre. A level at most 2 FLT_EPSILON |bed| above the bed (2 to 4
// float32 steps) is taken as the bed: dry.
void snapDry(MeshField& level, const std::vector<double>& bed) {
    if (bed.size() != level.values.size()) return;
    for (size_t i = 0; i < bed.size(); ++i)
        if (level.values[i] > bed[i] && level.values[i] - bed[i] <= 2 * FLT_EPSILON * std::abs(bed[i]))
            level.values[i] = bed[i];
}

// The water surface per step (lazily, one step at a time) and the further per-cell layers the options name.
void attachSteps(const MdFile& f, const Areas& areas, const MeshReadOptions& opt, double toM, ModelMesh& m) {
    const size_t steps = m.timesS.size(), faces = m.faceCount();
    const std::string levelVar = opt.waterSurfaceVar.empty() ? kLevelVar : opt.waterSurfaceVar;
    auto levels = cellSeries(f, *areas, levelVar, steps, opt.waterSurfaceVar.empty() ? "" : " (--water-surface-var)");
    auto bed = std::make_shared<const std::vector<double>>(m.bed.values);
    m.level = [f, areas, levels, bed, faces, steps, toM](size_t k) {
        if (k >= steps) f.fail("no step " + std::to_string(k) + " (" + std::to_string(steps) + " steps)");
        MeshField level = readStep(f, *areas, levels, faces, k, toM);
        snapDry(level, *bed);
        return level;
    };
    for (const std::string& name : opt.layerVars) {
        auto arrays = cellSeries(f, *areas, name, steps, " (--face-layers)");
        std::string units = trim(textAttr(arrays[0], "Units"));
        if (units.empty()) units = trim(textAttr(arrays[0], name));  // HEC-RAS 5: an attribute named as the result
        m.layers.push_back({name, units, [f, areas, arrays, faces, steps](size_t k) {
                                if (k >= steps)
                                    f.fail("no step " + std::to_string(k) + " (" + std::to_string(steps) + " steps)");
                                return readStep(f, *areas, arrays, faces, k, 1);
                            }});
    }
}

// What the file holds beside the 2-D areas, not drawn.
void noteSkipped(const MdFile& f, const MeshReadOptions& opt, ModelMesh& m) {
    size_t sections = rowsOf(f, "/Geometry/Cross Sections/Attributes");
    if (!sections) sections = rowsOf(f, "/Results/Unsteady/Geometry Info/Cross Section Only");
    if (sections) m.notes.push_back(std::to_string(sections) + " 1-D cross sections (not drawn: 2-D flow areas only)");
    size_t storage = rowsOf(f, "/Geometry/Storage Areas/Attributes");
    if (!storage) storage = rowsOf(f, "/Geometry/Storage Areas/Names");
    if (storage) m.notes.push_back(std::to_string(storage) + " storage areas (not drawn)");
    size_t links = rowsOf(f, "/Geometry/Connections/Attributes");
    if (!links) links = rowsOf(f, "/Geometry/Connections/Names");
    if (links) m.notes.push_back(std::to_string(links) + " SA/2D connections (not drawn)");
    if (!m.bed.values.empty() && opt.terrainVar.empty())
        m.notes.push_back("the bed of a cell is its lowest terrain ('" + kBedVar +
                          "'): give the plan's terrain as a DEM for the ground's detail");
}

std::string meshKind(const ModelMesh& m) {
    size_t lo = SIZE_MAX, hi = 0;
    for (size_t c = 0; c < m.faceCount(); ++c) lo = std::min(lo, m.nodesOf(c)), hi = std::max(hi, m.nodesOf(c));
    if (lo == hi)
        return lo == 3 ? "triangles" : lo == 4 ? "quadrilaterals" : "polygons of " + std::to_string(lo) + " nodes";
    return "polygons of " + std::to_string(lo) + "-" + std::to_string(hi) + " nodes";
}

}  // namespace

std::string hecRasFormat(const std::shared_ptr<GDALGroup>& root) {
    try {
        const MdFile f{"", nullptr, root};
        const std::string version = rootText(f, "File Version"), type = rootText(f, "File Type");
        if (version.rfind("HEC-RAS", 0) != 0 && type.rfind("HEC-RAS", 0) != 0) return "";
        // "HEC-RAS 6.1.0 September 2021" -> "HEC-RAS 6.1.0"
        const size_t end = version.find(' ', 8);
        const std::string v = version.empty() ? "HEC-RAS, version unknown" : version.substr(0, end);
        auto areas = group(root, kGeometry);
        if (!areas || areas->GetGroupNames().empty()) return "HEC-RAS file without 2-D flow areas (HDF5, " + v + ")";
        if (group(root, kSeries + "/2D Flow Areas")) return "HEC-RAS 2D plan results (HDF5, " + v + ")";
        return "HEC-RAS 2D geometry without results (HDF5, " + v + ")";
    } catch (...) {
        return "";
    }
}

ModelMesh readHecRas(const std::string& path, std::shared_ptr<GDALDataset> keep, const MeshReadOptions& opt) {
    MdFile f{path, keep, keep ? keep->GetRootGroup() : nullptr};
    if (!f.root) f.fail("cannot be read as HDF5 through GDAL: " + lastGdalError());
    ModelMesh m;
    m.source = path;
    m.format = hecRasFormat(f.root);
    if (m.format.empty())
        f.fail("not a HEC-RAS HDF5 file (no root attribute 'File Version' or 'File Type' naming HEC-RAS)");
    // Stage 1: the frame and the units of the elevations.
    OGRSpatialReference srs;
    m.crs = readCrs(f, srs, m);
    const double toM = elevationUnit(f, m.crs.empty() ? nullptr : &srs, m);
    // Stage 2: the 2-D flow areas, one after the other.
    const std::vector<AreaRef> refs = listAreas(f);
    if (refs.empty())
        f.fail("lists no 2-D flow areas ('" + kGeometry + "' missing or empty): nothing to draw (1-D only?)");
    auto areas = std::make_shared<std::vector<Area>>();
    for (const AreaRef& ref : refs) areas->push_back(readArea(f, ref, opt, toM, m));
    if (m.bed.values.size() != m.faceCount()) {
        if (!m.bed.values.empty()) f.fail("some 2-D flow areas have a bed ('" + kBedVar + "') and some not");
        m.warnings.push_back(f.path + ": no bed ('" + kBedVar +
                             "', --terrain-var names another): a DEM must give the terrain");
    }
    // Stage 3: the steps, where the file has results and the options ask for them.
    const bool results = group(f.root, kSeries + "/2D Flow Areas") != nullptr;
    if (results && opt.waterSurfaceVar != "-") {
        m.timesS = readTimes(f, m);
        attachSteps(f, areas, opt, toM, m);
    } else if (!results) {
        const bool plan = rootText(f, "File Type").find("Results") != std::string::npos;
        const std::string none = "no 2-D results ('" + kSeries + "/2D Flow Areas'): read as terrain only";
        if (plan)
            m.warnings.push_back(f.path + ": " + none);
        else
            m.notes.push_back(none);
    }
    // Stage 4: names, kind, what is left out.
    m.faceName = [areas, faces = m.faceCount()](size_t face) {
        if (face >= faces) return "face " + std::to_string(face);
        auto it = std::upper_bound(areas->begin(), areas->end(), face,
                                   [](size_t v, const Area& a) { return v < a.firstFace; });
        const Area& a = *std::prev(it);
        return "cell " + std::to_string(a.cells[face - a.firstFace]) + " of 2-D area '" + a.name + "'";
    };
    m.kind = m.faceCount() ? meshKind(m) : "";
    noteSkipped(f, opt, m);
    checkModelMesh(m);
    return m;
}

}  // namespace hc::ingest::detail
