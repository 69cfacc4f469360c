// ingest/src/model/xmdf.cpp: TUFLOW (classic, HPC, quadtree) and SMS results as an XMDF file (HDF5) over a .2dm mesh,
// read into a ModelMesh (mesh.h).
//
// The .2dm (SMS's text mesh) gives the nodes (ND, ids with gaps mapped to 0-based indexes), the 2-D elements (E3T, E4Q,
// and the corner nodes of E6T, E8Q, E9Q) and the bed (the nodes' z). The XMDF holds datasets as groups of "Values"
// (times, nodes or elements), "Times" and optionally "Active" (times, elements); a dataset is named by its group.
#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <unordered_map>

#include <ogr_spatialref.h>

#include "../gdal_util.h"
#include "heightcast/core/error.h"
#include "md_util.h"
#include "readers.h"

namespace hc::ingest::detail {
namespace {

namespace fs = std::filesystem;
using std::to_string;

// ---- the .2dm mesh ----

// One line's whitespace-separated fields.
std::vector<std::string_view> fieldsOf(std::string_view line) {
    std::vector<std::string_view> out;
    size_t i = 0;
    while (i < line.size()) {
        while (i < line.size() && std::isspace(static_cast<unsigned char>(line[i]))) ++i;
        const size_t start = i;
        while (i < line.size() && !std::isspace(static_cast<unsigned char>(line[i]))) ++i;
        if (i > start) out.push_back(line.substr(start, i - start));
    }
    return out;
}

template <class T>
bool parse(std::string_view s, T& v) {
    if (!s.empty() && s[0] == '+') s.remove_prefix(1);
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
    return ec == std::errc() && end == s.data() + s.size();
}

// Which fields of an element card are its corner nodes (1-based after the id): SMS lists the nodes of E6T, E8Q and
// E9Q counterclockwise from a corner, corners and mid-side nodes alternating (E9Q's centre node last).
std::vector<size_t> cornersOf(std::string_view card) {
    if (card == "E3T") return {1, 2, 3};
    if (card == "E4Q") return {1, 2, 3, 4};
    if (card == "E6T") return {1, 3, 5};
    if (card == "E8Q" || card == "E9Q") return {1, 3, 5, 7};
    return {};
}
size_t nodeFieldsOf(std::string_view card) { return card.size() == 3 ? size_t(card[1] - '0') : 0; }

struct Element {
    uint64_t id = 0, line = 0;
    std::vector<uint64_t> nodeIds;  // the corners
};

// What the .2dm's lines hold before the element's node ids are resolved (elements may come before the nodes).
struct TwoDmLines {
    std::unordered_map<uint64_t, uint32_t> index;  // node id -> index
    std::vector<Element> elements;
    size_t lines1d = 0, nodestrings = 0;
};

void readNode(const std::string& path, uint64_t line, const std::vector<std::string_view>& f, ModelMesh& m,
              TwoDmLines& t) {
    uint64_t id = 0;
    double x = 0, y = 0, z = 0;
    if (f.size() < 5 || !parse(f[1], id) || !parse(f[2], x) || !parse(f[3], y) || !parse(f[4], z) ||
        !std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z))
        throw Error(path + ": line " + to_string(line) + ": not an 'ND id x y z' node line of finite numbers");
    if (m.nodeX.size() >= uint64_t(UINT32_MAX)) throw Error(path + ": line " + to_string(line) + ": too many nodes");
    if (!t.index.emplace(id, uint32_t(m.nodeX.size())).second)
        throw Error(path + ": line " + to_string(line) + ": node id " + to_string(id) + " is defined twice (ND lines)");
    m.nodeX.push_back(x), m.nodeY.push_back(y), m.bed.values.push_back(z);
}

void readElement(const std::string& path, uint64_t line, const std::vector<std::string_view>& f, TwoDmLines& t) {
    const size_t fields = nodeFieldsOf(f[0]);
    Element e{0, line, {}};
    if (f.size() < fields + 2 || !parse(f[1], e.id))
        throw Error(path + ": line " + to_string(line) + ": not an '" + std::string(f[0]) + " id n1 .. n" +
                    to_string(fields) + " [material]' element line");
    for (size_t k : cornersOf(f[0])) {
        uint64_t n = 0;
        if (!parse(f[1 + k], n))
            throw Error(path + ": line " + to_string(line) + ": element " + to_string(e.id) + ": node field " +
                        to_string(k) + " '" + std::string(f[1 + k]) + "' is not a node id");
        e.nodeIds.push_back(n);
    }
    t.elements.push_back(std::move(e));
}

// Stage 1: the lines, one card each; cards not read here (MAT, BEGPARAMDEF blocks, boundary conditions) are skipped.
TwoDmLines readLines(const std::string& path, ModelMesh& m) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw Error(path + ": cannot open the .2dm mesh");
    TwoDmLines t;
    std::string text;
    uint64_t line = 0;
    while (std::getline(in, text)) {
        ++line;
        const std::vector<std::string_view> f = fieldsOf(text);
        if (line == 1 && (f.empty() || f[0].find("MESH2D") == std::string_view::npos))
            throw Error(path + ": line 1: no MESH2D header line: not an SMS .2dm mesh");
        if (f.empty()) continue;
        if (f[0] == "ND")
            readNode(path, line, f, m, t);
        else if (!cornersOf(f[0]).empty())
            readElement(path, line, f, t);
        else if (f[0] == "E2L" || f[0] == "E3L")
            ++t.lines1d;
        else if (f[0] == "NS")
            ++t.nodestrings;
    }
    if (line == 0) throw Error(path + ": empty file: not an SMS .2dm mesh");
    return t;
}

// Stage 2: node ids to indexes, elements to faces.
void resolveElements(const std::string& path, const TwoDmLines& t, ModelMesh& m) {
    if (t.elements.empty()) throw Error(path + ": no 2-D elements (E3T, E4Q, E6T, E8Q, E9Q lines)");
    auto ids = std::make_shared<std::vector<uint64_t>>();
    m.faceStart.assign(1, 0);
    for (const Element& e : t.elements) {
        for (uint64_t n : e.nodeIds) {
            const auto it = t.index.find(n);
            if (it == t.index.end())
                throw Error(path + ": line " + to_string(e.line) + ": element " + to_string(e.id) + " names node " +
                            to_string(n) + ", which no ND line defines");
            m.faceNodes.push_back(it->second);
        }
        m.faceStart.push_back(m.faceNodes.size());
        ids->push_back(e.id);
    }
    m.faceName = [ids](size_t face) { return "element " + to_string((*ids)[face]); };
}

std::string meshKind(const ModelMesh& m) {
    size_t tri = 0;
    for (size_t f = 0; f < m.faceCount(); ++f) tri += m.nodesOf(f) == 3;
    const size_t quad = m.faceCount() - tri;
    if (quad == 0) return "triangles";
    if (tri == 0) return "quadrilaterals";
    return "mixed faces of 3-4 nodes (" + to_string(tri) + " triangles, " + to_string(quad) + " quadrilaterals)";
}

// A .prj (WKT) beside the .2dm names the CRS; else none, with a warning.
std::string prjCrs(const std::string& meshPath, ModelMesh& m) {
    const fs::path prj = fs::path(meshPath).replace_extension(".prj");
    std::ifstream in(prj, std::ios::binary);
    if (!in) {
        m.warnings.push_back(meshPath + ": no .prj beside the mesh: no CRS (--s_srs gives it)");
        return "";
    }
    std::string wkt((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    // Trimmed (a UTF-8 byte order mark and blank lines around the WKT stop SetFromUserInput).
    if (wkt.starts_with("\xEF\xBB\xBF")) wkt.erase(0, 3);
    while (!wkt.empty() && std::isspace(static_cast<unsigned char>(wkt.back()))) wkt.pop_back();
    wkt.erase(0, std::min(wkt.size(), wkt.find_first_not_of(" \t\r\n")));
    OGRSpatialReference srs;
    if (wkt.empty() || srs.SetFromUserInput(wkt.c_str()) != OGRERR_NONE) {
        m.warnings.push_back(prj.string() + ": not a CRS GDAL reads: no CRS (--s_srs gives it)");
        return "";
    }
    return wkt;
}

ModelMesh readTwoDm(const std::string& path) {
    ModelMesh m;
    m.source = path;
    m.format = "SMS .2dm mesh";
    m.bed.at = MeshAt::Node;
    const TwoDmLines t = readLines(path, m);
    resolveElements(path, t, m);
    m.kind = meshKind(m);
    if (t.lines1d) m.notes.push_back(to_string(t.lines1d) + " 1-D elements (E2L, E3L) not drawn");
    if (t.nodestrings) m.notes.push_back(to_string(t.nodestrings) + " nodestring lines (NS) skipped");
    return m;
}

// ---- the XMDF datasets ----

struct Dataset {
    std::string name, fullName;  // the group's name, its full path
    std::shared_ptr<GDALGroup> group;
    ArrayPtr values, times, active;
    size_t steps = 0;
};

// Every group holding "Values" and "Times", depth-first (at most a few levels deep and a few thousand groups).
void collectDatasets(const std::shared_ptr<GDALGroup>& g, const std::string& at, int depth, std::vector<Dataset>& out) {
    if (!g || depth > 8 || out.size() > 4096) return;
    CPLErrorStateBackuper quiet;
    const std::vector<std::string> arrays = g->GetMDArrayNames();
    const auto has = [&](const char* n) { return std::find(arrays.begin(), arrays.end(), n) != arrays.end(); };
    if (depth > 0 && has("Values") && has("Times")) {
        Dataset d{at.substr(at.rfind('/') + 1),
                  at,
                  g,
                  g->OpenMDArray("Values"),
                  g->OpenMDArray("Times"),
                  has("Active") ? g->OpenMDArray("Active") : nullptr,
                  0};
        if (d.values && d.times && !d.values->GetDimensions().empty()) {
            d.steps = size_t(d.values->GetDimensions()[0]->GetSize());
            out.push_back(std::move(d));
        }
    }
    for (const std::string& sub : g->GetGroupNames())
        collectDatasets(g->OpenGroup(sub), at + "/" + sub, depth + 1, out);
}

// The dataset named `name` (its group's name, any case, or its full path); of several, the one of most steps (a
// "Temporal" dataset rather than its "Maximums" or "Final" twin). Null when none.
const Dataset* findDataset(const std::vector<Dataset>& all, const std::string& name) {
    const Dataset* best = nullptr;
    for (const Dataset& d : all) {
        const bool named = name.starts_with('/') ? d.fullName == name : lower(d.name) == lower(name);
        if (named && (!best || d.steps > best->steps)) best = &d;
    }
    return best;
}

// Seconds per unit of the dataset's TimeUnits (hours where it names none, with a warning).
double secondsPerTimeUnit(const MdFile& f, const Dataset& d, ModelMesh& m) {
    auto attr = d.group->GetAttribute("TimeUnits");
    const char* text = attr ? attr->ReadAsString() : nullptr;
    const std::string units = lower(text ? text : "");
    if (units.empty()) {
        m.warnings.push_back(f.path + ": dataset '" + d.fullName + "' names no TimeUnits: its times taken as hours");
        return 3600;
    }
    if (units.starts_with("sec")) return 1;
    if (units.starts_with("min")) return 60;
    if (units.starts_with("hour")) return 3600;
    if (units.starts_with("day")) return 86400;
    f.fail("dataset '" + d.fullName + "': TimeUnits '" + units + "' is not seconds, minutes, hours or days");
}

// Nodes and faces a step's values and Active flags are checked against, shared by the step functions.
struct Topology {
    std::vector<uint64_t> faceStart;
    std::vector<uint32_t> faceNodes;
    size_t nodes = 0;
    std::vector<char> used;  // per node: some face uses it
};

// Step `k` of dataset `d` (values at nodes or faces; a vector dataset's magnitude); -9999 and values at or beyond
// +-1e30 become NaN, and so do a face flagged inactive and a node whose faces are all inactive.
MeshField readStep(const MdFile& f, const Dataset& d, const Topology& t, size_t k) {
    const std::vector<size_t> shape = shapeOf(d.values);
    const size_t faces = t.faceStart.size() - 1;
    const bool vec = shape.size() == 3 && shape[2] == 2;
    if ((shape.size() != 2 && !vec) || (shape[1] != t.nodes && shape[1] != faces))
        f.fail("dataset '" + d.fullName + "': Values is not (times, " + to_string(t.nodes) + " nodes) nor (times, " +
               to_string(faces) + " elements)");
    MeshField out{shape[1] == t.nodes ? MeshAt::Node : MeshAt::Face, f.readSlice(d.values, k)};
    if (vec) {
        for (size_t i = 0; i < shape[1]; ++i) out.values[i] = std::hypot(out.values[2 * i], out.values[2 * i + 1]);
        out.values.resize(shape[1]);
    }
    fillToNaN(out.values, -9999.0);
    if (!d.active || shapeOf(d.active) != std::vector<size_t>{shape[0], faces}) return out;
    const std::vector<double> active = f.readSlice(d.active, k);
    if (out.at == MeshAt::Face) {
        for (size_t e = 0; e < faces; ++e)
            if (active[e] == 0) out.values[e] = NAN;
        return out;
    }
    std::vector<char> wet(t.nodes, 0);
    for (size_t e = 0; e < faces; ++e)
        if (active[e] != 0)
            for (uint64_t i = t.faceStart[e]; i < t.faceStart[e + 1]; ++i) wet[t.faceNodes[i]] = 1;
    for (size_t n = 0; n < t.nodes; ++n)
        if (t.used[n] && !wet[n]) out.values[n] = NAN;
    return out;
}

std::function<MeshField(size_t)> stepsOf(const MdFile& f, const Dataset& d, std::shared_ptr<const Topology> t) {
    return [f, d, t](size_t k) { return readStep(f, d, *t, k); };
}

// Stage: the times of the water level, in seconds, increasing.
std::vector<double> timesOf(const MdFile& f, const Dataset& d, ModelMesh& m) {
    std::vector<double> t = f.read(d.times);
    if (t.size() != d.steps)
        f.fail("dataset '" + d.fullName + "': Times has " + to_string(t.size()) + " steps, Values " +
               to_string(d.steps));
    const double unit = secondsPerTimeUnit(f, d, m);
    for (double& v : t) v *= unit;
    checkIncreasing(f, t, "dataset '" + d.fullName + "' Times");
    // SMS writes a reference time (a Julian day) where the times count from a date rather than the run's start.
    if (auto ref = d.group->GetAttribute("Reftime"))
        m.notes.push_back("times are seconds after the reference time " + fmt(ref->ReadAsDouble(), 12) +
                          " (Julian day)");
    return t;
}

void noteActive(const Dataset& d, const Topology& t, ModelMesh& m) {
    if (d.active && shapeOf(d.active) != std::vector<size_t>{d.steps, t.faceStart.size() - 1})
        m.notes.push_back("dataset '" + d.fullName + "': Active flags not (times, elements): ignored");
}

// The water level: --water-surface-var, else the first of 'Water Level', 'WSE', 'H' (any case); null when none
// ("-": none asked for).
const Dataset* levelOf(const MdFile& f, const std::vector<Dataset>& all, const MeshReadOptions& opt) {
    if (opt.waterSurfaceVar == "-") return nullptr;
    if (!opt.waterSurfaceVar.empty()) {
        const Dataset* d = findDataset(all, opt.waterSurfaceVar);
        if (!d) f.fail("no dataset '" + opt.waterSurfaceVar + "' (--water-surface-var)");
        return d;
    }
    for (const char* name : {"Water Level", "WSE", "H"})
        if (const Dataset* d = findDataset(all, name)) return d;
    return nullptr;
}

// A note naming the datasets not read (each name once).
void noteOthers(const std::vector<Dataset>& all, const std::vector<std::string>& used, ModelMesh& m) {
    std::vector<std::string> others;
    for (const Dataset& d : all)
        if (std::find(used.begin(), used.end(), d.name) == used.end() &&
            std::find(others.begin(), others.end(), d.name) == others.end())
            others.push_back(d.name);
    std::string list;
    for (const std::string& o : others) list += (list.empty() ? "'" : ", '") + o + "'";
    if (!list.empty()) m.notes.push_back("datasets not read: " + list);
}

// The bed from --terrain-var (a dataset's first step), the water level and the step layers.
void readDatasets(const MdFile& f, const MeshReadOptions& opt, ModelMesh& m) {
    std::vector<Dataset> all;
    collectDatasets(f.root, "", 0, all);
    auto topo = std::make_shared<Topology>(Topology{m.faceStart, m.faceNodes, m.nodeX.size(), {}});
    topo->used.assign(topo->nodes, 0);
    for (uint32_t n : m.faceNodes) topo->used[n] = 1;
    std::vector<std::string> used;
    if (!opt.terrainVar.empty()) {
        const Dataset* bed = findDataset(all, opt.terrainVar);
        if (!bed) f.fail("no dataset '" + opt.terrainVar + "' (--terrain-var)");
        m.bed = readStep(f, *bed, *topo, 0);
        used.push_back(bed->name);
    }
    const Dataset* level = levelOf(f, all, opt);
    if (level) {
        m.timesS = timesOf(f, *level, m);
        m.level = stepsOf(f, *level, topo);
        noteActive(*level, *topo, m);
        used.push_back(level->name);
    } else {
        m.notes.push_back("no water level dataset ('Water Level', 'WSE', 'H'; --water-surface-var): a terrain mesh");
    }
    for (const std::string& name : opt.layerVars) {
        const Dataset* d = findDataset(all, name);
        if (!d) f.fail("no dataset '" + name + "' (--face-layers)");
        if (!level || d->steps != level->steps)
            f.fail("dataset '" + d->fullName + "' has not the water level's steps: a step layer must");
        auto units = d->group->GetAttribute("DatasetUnits");
        const char* u = units ? units->ReadAsString() : nullptr;
        m.layers.push_back({d->name, u ? u : "", stepsOf(f, *d, topo)});
        used.push_back(d->name);
    }
    noteOthers(all, used, m);
}

// The .2dm of an XMDF file: NAME.2dm for NAME.xmdf (or NAME.h5); else, in the same folder, the .2dm whose name
// followed by '_' starts the XMDF's name (TUFLOW's MODEL_results.xmdf beside MODEL.2dm; the longest of several);
// else the folder's only .2dm. "" when none.
std::string meshOf(const std::string& path) {
    std::error_code ec;
    const fs::path p(path);
    if (fs::path same = fs::path(p).replace_extension(".2dm"); fs::is_regular_file(same, ec)) return same.string();
    const std::string stem = p.stem().string();
    std::string best, only;
    size_t count = 0, seen = 0, bestLen = 0;
    const fs::path dir = p.has_parent_path() ? p.parent_path() : fs::path(".");
    for (fs::directory_iterator it(dir, ec), end; !ec && it != end && ++seen < 100000; it.increment(ec)) {
        if (lower(it->path().extension().string()) != ".2dm") continue;
        const std::string s = it->path().stem().string();
        ++count, only = it->path().string();
        if (stem.starts_with(s + "_") && s.size() >= bestLen) bestLen = s.size() + 1, best = it->path().string();
    }
    return !best.empty() ? best : count == 1 ? only : "";
}

}  // namespace

std::string xmdfFormat(const std::string& path) {
    try {
        std::shared_ptr<GDALDataset> keep;
        std::shared_ptr<GDALGroup> root = openMultidimRoot(path, keep);
        if (!root || meshOf(path).empty()) return "";
        const MdFile f{path, keep, root};
        std::string type;
        if (ArrayPtr a = f.find("File Type"); a && shapeOf(a) == std::vector<size_t>{1}) {
            const GUInt64 start = 0;
            const size_t count = 1;
            char* s = nullptr;
            if (a->Read(&start, &count, nullptr, nullptr, GDALExtendedDataType::CreateString(), &s) && s)
                type = lower(s);
            CPLFree(s);
        }
        std::vector<Dataset> all;
        if (type != "xmdf") collectDatasets(root, "", 0, all);
        return type == "xmdf" || !all.empty() ? "TUFLOW/SMS XMDF results with a .2dm mesh" : "";
    } catch (...) {
        return "";
    }
}

ModelMesh readXmdf(const std::string& path, const MeshReadOptions& opt) {
    const std::string meshPath = meshOf(path);
    if (meshPath.empty())
        throw Error(path +
                    ": no .2dm mesh found for the XMDF results (NAME.2dm beside NAME.xmdf, or the folder's only "
                    ".2dm)");
    std::shared_ptr<GDALDataset> keep;
    std::shared_ptr<GDALGroup> root = openMultidimRoot(path, keep);
    if (!root) throw Error(path + ": GDAL cannot open it as an HDF5 (XMDF) file: " + lastGdalError());
    const MdFile f{path, keep, root};
    ModelMesh m = readTwoDm(meshPath);
    m.source = path;
    m.format = "TUFLOW/SMS XMDF results on the .2dm mesh " + fs::path(meshPath).filename().string();
    m.crs = prjCrs(meshPath, m);
    readDatasets(f, opt, m);
    checkModelMesh(m);
    return m;
}

}  // namespace hc::ingest::detail

namespace hc::ingest {

ModelMesh readTwoDmMesh(const std::string& path) {
    ModelMesh m = detail::readTwoDm(path);
    checkModelMesh(m);
    return m;
}

}  // namespace hc::ingest
