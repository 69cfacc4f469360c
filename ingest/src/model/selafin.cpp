// ingest/src/model/selafin.cpp: TELEMAC Selafin files (.slf, .res, .ser, .geo) read into a ModelMesh (mesh.h).
#include <algorithm>
#include <array>
#include <bit>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <optional>

#include "heightcast/core/error.h"
#include "readers.h"

namespace hc::ingest::detail {
namespace {

constexpr uint64_t kTitleBytes = 80, kNameBytes = 32;
constexpr double kFootM = 0.3048;

std::string str(uint64_t v) { return std::to_string(v); }
std::string num(double v) {
    char b[32];
    std::snprintf(b, sizeof b, "%.10g", v);
    return b;
}

// Fixed-width text of the file, trimmed; bytes that are not printable ASCII shown as '?'.
std::string text(const unsigned char* p, size_t n) {
    std::string s;
    for (size_t i = 0; i < n; ++i) s += (p[i] >= 32 && p[i] < 127) ? char(p[i]) : '?';
    const size_t a = s.find_first_not_of(' '), b = s.find_last_not_of(' ');
    return a == std::string::npos ? "" : s.substr(a, b - a + 1);
}

std::string upper(std::string s) {
    for (char& c : s) c = char(std::toupper(static_cast<unsigned char>(c)));
    return s;
}

// The byte order of the file's numbers.
struct Endian {
    bool little = false;
    uint32_t u32(const unsigned char* p) const {
        return little ? uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24
                      : uint32_t(p[3]) | uint32_t(p[2]) << 8 | uint32_t(p[1]) << 16 | uint32_t(p[0]) << 24;
    }
    int32_t i32(const unsigned char* p) const { return std::bit_cast<int32_t>(u32(p)); }
    double real(const unsigned char* p, size_t bytes) const {
        if (bytes == 4) return double(std::bit_cast<float>(u32(p)));
        const uint64_t a = u32(p), b = u32(p + 4);
        return std::bit_cast<double>(little ? b << 32 | a : a << 32 | b);
    }
};

// The file as Fortran unformatted records: a 4-byte length, the bytes, the same length again. TELEMAC writes them
// big-endian, some mesh generators (Janet) little-endian: the title record's opening length, 80 either way, tells
// which. Every record is checked against the file's size before anything is allocated or read; every failure names
// the file, the record and its byte offset.
class RecordFile {
public:
    RecordFile(const std::string& path, Endian order) : endian(order), path_(path), in_(path, std::ios::binary) {
        std::error_code ec;
        size_ = std::filesystem::file_size(path, ec);
        if (!in_ || ec) throw Error(path + ": cannot be opened");
    }
    [[noreturn]] void fail(const std::string& where, uint64_t at, const std::string& what) const {
        throw Error(path_ + ": " + where + " at byte " + str(at) + ": " + what);
    }
    uint64_t size() const { return size_; }
    const std::string& path() const { return path_; }

    void read(uint64_t at, unsigned char* dst, uint64_t n, const std::string& where) {
        in_.clear();
        in_.seekg(std::streamoff(at));
        in_.read(reinterpret_cast<char*>(dst), std::streamsize(n));
        if (uint64_t(in_.gcount()) != n) fail(where, at, "cannot read " + str(n) + " bytes (did the file change?)");
    }
    // Checks the record at `at`: inside the file, both lengths agree, and of length `expect` when given. Returns
    // its length.
    uint64_t check(uint64_t at, const std::string& where, std::optional<uint64_t> expect) {
        if (at >= size_) fail(where, at, "the file ends there: the record is missing");
        if (size_ - at < 4) fail(where, at, "the file ends " + str(size_ - at) + " bytes on: the record is cut short");
        unsigned char m[4];
        read(at, m, 4, where);
        const uint64_t len = endian.u32(m);
        if (expect && len != *expect) fail(where, at, "a record of " + str(len) + " bytes, not " + str(*expect));
        if (size_ - at - 4 < len + 4)
            fail(where, at, "its " + str(len) + " bytes run past the end of the file (byte " + str(size_) + ")");
        read(at + 4 + len, m, 4, where);
        if (endian.u32(m) != len)
            fail(where, at, "its closing length " + str(endian.u32(m)) + " differs from its opening " + str(len));
        return len;
    }
    // The bytes of the record at `at` (checked as check() does); moves `at` past it.
    std::vector<unsigned char> record(uint64_t& at, const std::string& where, std::optional<uint64_t> expect) {
        const uint64_t len = check(at, where, expect);
        std::vector<unsigned char> b(len);
        if (len) read(at + 4, b.data(), len, where);
        at += len + 8;
        return b;
    }

    Endian endian;

private:
    std::string path_;
    std::ifstream in_;
    uint64_t size_ = 0;
};

struct Var {
    std::string name, unit;
    double scale = 1;  // to metres: kFootM for a unit in feet
};

// The header, record by record: title, NBV1 NBV2, a name per variable, IPARAM, the date (when IPARAM[9] is 1),
// NELEM NPOIN NDP 1, IKLE, IPOBO, X, Y. The steps follow: a record holding the time, then one record of NPOIN values
// per variable; they are checked once at opening and their values read when asked for.
struct Header {
    std::string title;
    std::vector<Var> vars;
    std::array<int32_t, 10> iparam{};
    std::optional<std::array<int32_t, 6>> date;
    uint64_t elems = 0, nodes = 0, perElem = 0;
    uint64_t at = 0;  // where IKLE starts
};

// What the step functions share: where each step lies and how to read its values.
struct Layout {
    std::string path;
    Endian endian;
    uint64_t realBytes = 4, nodes = 0;
    std::vector<Var> vars;
    std::vector<uint64_t> stepAt;  // each step's time record
    uint64_t recordAt(size_t step, size_t var) const {
        return stepAt[step] + 8 + realBytes + var * (8 + nodes * realBytes);
    }
};

// Title, variable names, IPARAM, the date, the sizes; refuses what is not a 2-D mesh.
Header readHeader(RecordFile& f) {
    Header h;
    uint64_t at = 0;
    const auto title = f.record(at, "the title record", kTitleBytes);
    h.title = text(title.data(), 72);  // the last 8 characters say the precision, read from the X record instead
    const auto counts = f.record(at, "the record of variable counts (NBV1, NBV2)", 8);
    const int32_t nbv1 = f.endian.i32(&counts[0]), nbv2 = f.endian.i32(&counts[4]);
    if (nbv1 < 0 || nbv2 < 0) f.fail("the variable counts", 88, "NBV1 " + num(nbv1) + ", NBV2 " + num(nbv2) + " < 0");
    const uint64_t nv = uint64_t(nbv1) + uint64_t(nbv2);
    if (nv > (f.size() - at) / (kNameBytes + 8))
        f.fail("the variable counts", 88, str(nv) + " variables: more names than the rest of the file holds");
    for (uint64_t v = 0; v < nv; ++v) {
        const auto name = f.record(at, "the name of variable " + str(v + 1), kNameBytes);
        Var var{text(name.data(), 16), text(name.data() + 16, 16)};
        const std::string unit = upper(var.unit);
        if (unit == "FT" || unit == "FEET") var.scale = kFootM;
        h.vars.push_back(var);
    }
    const uint64_t iparamAt = at;
    const auto iparam = f.record(at, "the IPARAM record", 40);
    for (size_t i = 0; i < 10; ++i) h.iparam[i] = f.endian.i32(&iparam[4 * i]);
    if (h.iparam[9] == 1) {
        const auto date = f.record(at, "the date record", 24);
        h.date.emplace();
        for (size_t i = 0; i < 6; ++i) (*h.date)[i] = f.endian.i32(&date[4 * i]);
    }
    const uint64_t sizesAt = at;
    const auto sizes = f.record(at, "the sizes record (NELEM, NPOIN, NDP)", 16);
    const int32_t elems = f.endian.i32(&sizes[0]), nodes = f.endian.i32(&sizes[4]), ndp = f.endian.i32(&sizes[8]);
    if (h.iparam[6] > 1 || ndp == 6)
        f.fail("the IPARAM record", iparamAt,
               "a 3-D result (" + num(h.iparam[6]) + " planes, NDP " + num(ndp) +
                   "): 3-D results are not read; use "
                   "the 2-D result file TELEMAC-3D writes (2D RESULT FILE) or extract the free surface with TELEMAC "
                   "tools");
    if (elems < 1 || nodes < 3 || (ndp != 3 && ndp != 4))
        f.fail("the sizes record", sizesAt,
               "NELEM " + num(elems) + ", NPOIN " + num(nodes) + ", NDP " + num(ndp) +
                   ": not a 2-D mesh of triangles (NDP 3) or quadrilaterals (NDP 4)");
    h.elems = uint64_t(elems), h.nodes = uint64_t(nodes), h.perElem = uint64_t(ndp), h.at = at;
    return h;
}

// A record of `count` reals of `bytes` each, as doubles.
std::vector<double> reals(RecordFile& f, uint64_t& at, const std::string& where, uint64_t count, uint64_t bytes) {
    const auto b = f.record(at, where, count * bytes);
    std::vector<double> v(count);
    for (uint64_t i = 0; i < count; ++i) v[i] = f.endian.real(&b[i * bytes], bytes);
    return v;
}

// IKLE, IPOBO, X and Y into `mesh`; returns the size of the file's reals: 4, or 8 in "SERAFIND" files, told by the
// length of the X record (some writers leave the title's last 8 characters blank).
uint64_t readGeometry(RecordFile& f, Header& h, ModelMesh& mesh) {
    const uint64_t ikleAt = h.at;
    const auto ikle = f.record(h.at, "the connectivity record IKLE", h.elems * h.perElem * 4);
    mesh.faceNodes.resize(h.elems * h.perElem);
    mesh.faceStart.resize(h.elems + 1);
    for (uint64_t e = 0; e < h.elems; ++e) {
        mesh.faceStart[e + 1] = (e + 1) * h.perElem;
        for (uint64_t j = 0; j < h.perElem; ++j) {
            const uint64_t i = e * h.perElem + j;
            const int32_t n = f.endian.i32(&ikle[4 * i]);
            if (n < 1 || uint64_t(n) > h.nodes)
                f.fail("the connectivity record IKLE", ikleAt + 4 + 4 * i,
                       "element " + str(e + 1) + " names node " + num(n) + ", not one of 1 .. " + str(h.nodes));
            mesh.faceNodes[i] = uint32_t(n - 1);
        }
    }
    h.at += f.check(h.at, "the boundary record IPOBO", h.nodes * 4) + 8;  // boundary numbering: not needed
    const uint64_t len = f.check(h.at, "the X record", std::nullopt);
    if (len != h.nodes * 4 && len != h.nodes * 8)
        f.fail("the X record", h.at, str(len) + " bytes: not " + str(h.nodes) + " float32 or float64 values");
    const uint64_t bytes = len / h.nodes;
    for (const char* axis : {"X", "Y"}) {
        const uint64_t at = h.at;
        const std::string where = std::string("the ") + axis + " record";
        std::vector<double> v = reals(f, h.at, where, h.nodes, bytes);
        for (uint64_t i = 0; i < h.nodes; ++i)
            if (!std::isfinite(v[i])) f.fail(where, at + 4 + i * bytes, "node " + str(i + 1) + " is not finite");
        (axis[0] == 'X' ? mesh.nodeX : mesh.nodeY) = std::move(v);
    }
    return bytes;
}

// Walks the steps: every record of every step present and whole, the times increasing.
std::vector<double> scanSteps(RecordFile& f, uint64_t at, Layout& layout) {
    std::vector<double> times;
    while (at < f.size()) {
        const size_t k = times.size();
        const std::string step = "step " + str(k);
        const uint64_t timeAt = at;
        layout.stepAt.push_back(at);
        const auto t = f.record(at, step + "'s time record", layout.realBytes);
        const double time = f.endian.real(t.data(), layout.realBytes);
        if (!std::isfinite(time)) f.fail(step + "'s time record", timeAt, "the time is not finite");
        if (k > 0 && !(time > times.back()))
            f.fail(step + "'s time record", timeAt,
                   "time " + num(time) + " s does not follow step " + str(k - 1) + "'s " + num(times.back()) +
                       " s: times must increase");
        for (const Var& v : layout.vars)
            at += f.check(at, step + ", the values of " + v.name, layout.nodes * layout.realBytes) + 8;
        times.push_back(time);
    }
    return times;
}

// Step `step`'s values of variable `var` [m where the unit is a length], non-finite ones as NaN.
std::vector<double> readValues(const Layout& L, size_t step, size_t var) {
    if (step >= L.stepAt.size())
        throw Error(L.path + ": no step " + str(step) + " (the file holds " + str(L.stepAt.size()) + ")");
    RecordFile f(L.path, L.endian);
    uint64_t at = L.recordAt(step, var);
    std::vector<double> v =
        reals(f, at, "step " + str(step) + ", the values of " + L.vars[var].name, L.nodes, L.realBytes);
    for (double& x : v) x = std::isfinite(x) ? x * L.vars[var].scale : std::numeric_limits<double>::quiet_NaN();
    return v;
}

struct Roles {
    std::optional<size_t> bed, surface, depth;
    std::vector<size_t> layers;
};

std::optional<size_t> findVar(const std::vector<Var>& vars, std::initializer_list<std::string> names) {
    for (size_t v = 0; v < vars.size(); ++v)
        for (const std::string& n : names)
            if (upper(vars[v].name) == upper(n)) return v;
    return std::nullopt;
}

std::string listVars(const std::vector<Var>& vars) {
    std::string s;
    for (const Var& v : vars) s += (s.empty() ? "" : ", ") + v.name + (v.unit.empty() ? "" : " [" + v.unit + "]");
    return s.empty() ? "none" : s;
}

// The variable an option names (trimmed, any case), or throws listing the file's variables.
size_t namedVar(const std::string& path, const std::vector<Var>& vars, const std::string& name, const char* option) {
    std::string want = name;
    want.erase(0, want.find_first_not_of(' '));
    want.erase(want.find_last_not_of(' ') + 1);
    if (auto v = findVar(vars, {want})) return *v;
    throw Error(path + ": no variable '" + name + "' (" + option + "); its variables: " + listVars(vars));
}

// The variables of each role: the options' names, else TELEMAC's English or French ones.
Roles chooseVariables(const std::string& path, const std::vector<Var>& vars, const MeshReadOptions& opt) {
    Roles r;
    r.bed = opt.terrainVar.empty() ? findVar(vars, {"BOTTOM", "FOND"})
                                   : namedVar(path, vars, opt.terrainVar, "--terrain-var");
    if (opt.waterSurfaceVar != "-") {  // "-": none asked for, terrain only
        r.surface = opt.waterSurfaceVar.empty() ? findVar(vars, {"FREE SURFACE", "SURFACE LIBRE"})
                                                : namedVar(path, vars, opt.waterSurfaceVar, "--water-surface-var");
        if (!r.surface) r.depth = findVar(vars, {"WATER DEPTH", "HAUTEUR D'EAU"});
    }
    for (const std::string& name : opt.layerVars) r.layers.push_back(namedVar(path, vars, name, "a layer asked for"));
    return r;
}

// The bed from the first step (with a warning when a later one differs: a morphodynamic run).
void readBed(ModelMesh& mesh, const std::shared_ptr<const Layout>& L, const Roles& r) {
    if (!r.bed) {
        mesh.warnings.push_back(
            "no bed variable (BOTTOM / FOND; --terrain-var names another): the mesh has no "
            "terrain, a DEM must be given");
        return;
    }
    const std::string name = L->vars[*r.bed].name;
    if (L->stepAt.empty()) {
        mesh.warnings.push_back("the bed variable " + name +
                                " has no values (the file holds no step): a DEM must be "
                                "given");
        return;
    }
    mesh.bed = {MeshAt::Node, readValues(*L, 0, *r.bed)};
    if (L->stepAt.size() > 1) {
        const std::vector<double> last = readValues(*L, L->stepAt.size() - 1, *r.bed);
        for (size_t i = 0; i < last.size(); ++i)
            if (std::abs(last[i] - mesh.bed.values[i]) > 1e-6) {  // an unchanged bed is stored bit for bit
                mesh.warnings.push_back(name +
                                        " changes over the steps (a morphodynamic run?): the first step's bed "
                                        "is used");
                break;
            }
    }
}

// The water level per step (FREE SURFACE, else BOTTOM + WATER DEPTH) and the layers, read lazily.
void bindSteps(ModelMesh& mesh, const std::shared_ptr<const Layout>& L, const Roles& r, std::vector<double> times) {
    const std::vector<Var>& vars = L->vars;
    const bool derived = !r.surface && r.depth && r.bed;
    if (!r.surface && !derived) {
        if (!r.bed)
            throw Error(mesh.source +
                        ": neither a bed nor a water level to read (BOTTOM / FOND, FREE SURFACE "
                        "/ SURFACE LIBRE, WATER DEPTH / HAUTEUR D'EAU); its variables: " +
                        listVars(vars));
        mesh.notes.push_back(
            "no water level (FREE SURFACE / SURFACE LIBRE, or BOTTOM + WATER DEPTH / HAUTEUR D'EAU; "
            "--water-surface-var names another): read as terrain only (the file holds " +
            str(times.size()) + " step(s))");
        if (!r.layers.empty()) throw Error(mesh.source + ": layers need a water level: they are stored on wet cells");
        return;
    }
    if (times.empty()) {
        mesh.notes.push_back("the water level variable has no values (the file holds no step): read as terrain only");
        if (!r.layers.empty()) throw Error(mesh.source + ": layers asked for, but the file holds no step");
        return;
    }
    if (derived)
        mesh.warnings.push_back(
            "no FREE SURFACE / SURFACE LIBRE (--water-surface-var names another): the water level "
            "is derived as " +
            vars[*r.bed].name + " + " + vars[*r.depth].name + " per step");
    mesh.timesS = std::move(times);
    const size_t level = derived ? *r.depth : *r.surface, bed = r.bed.value_or(0);
    mesh.level = [L, level, bed, derived](size_t step) {
        MeshField f{MeshAt::Node, readValues(*L, step, level)};
        if (derived) {
            const std::vector<double> b = readValues(*L, step, bed);
            for (size_t i = 0; i < b.size(); ++i) f.values[i] += b[i];
        }
        return f;
    };
    for (size_t v : r.layers) {
        const Var& var = vars[v];
        mesh.layers.push_back({var.name, var.scale != 1 ? "M" : var.unit, [L, v](size_t step) {
                                   return MeshField{MeshAt::Node, readValues(*L, step, v)};
                               }});
    }
}

// What the reader assumed or skipped: CRS, origin, precision, feet, date, unread variables.
void describe(ModelMesh& mesh, const Header& h, const Layout& L, const Roles& r) {
    // No CRS in the format: meshToMetric says so, and how to name one.
    if (L.realBytes == 4) {  // float32 coordinates: far from the origin they lie on a coarse lattice
        double far = 0;
        for (size_t i = 0; i < mesh.nodeX.size(); ++i)
            far = std::max({far, std::abs(mesh.nodeX[i]), std::abs(mesh.nodeY[i])});
        const float f = float(far), step = std::nextafter(f, std::numeric_limits<float>::infinity()) - f;
        if (step >= 0.01f)
            mesh.warnings.push_back("X and Y are single precision: at coordinates up to " + num(far) + " nodes lie " +
                                    "on steps of " + num(step) + " (a SERAFIND file or IPARAM's origin avoids this)");
    }
    if (h.iparam[2] != 0 || h.iparam[3] != 0) {
        for (double& x : mesh.nodeX) x += h.iparam[2];
        for (double& y : mesh.nodeY) y += h.iparam[3];
        mesh.notes.push_back("coordinates shifted by the origin in IPARAM (" + num(h.iparam[2]) + ", " +
                             num(h.iparam[3]) + ")");
    }
    if (h.iparam[7] != 0 || h.iparam[8] != 0)  // the numbers of boundary and interface points of a subdomain
        mesh.warnings.push_back("IPARAM's 8th and 9th values (" + num(h.iparam[7]) + ", " + num(h.iparam[8]) +
                                ") say one subdomain of a parallel run: merge them with TELEMAC's gretel");
    std::vector<size_t> used = r.layers;
    for (auto v : {r.bed, r.surface, mesh.level && !r.surface ? r.depth : std::nullopt})
        if (v) used.push_back(*v);
    std::string unread;
    for (size_t v = 0; v < L.vars.size(); ++v) {
        if (std::find(used.begin(), used.end(), v) == used.end()) {
            unread += (unread.empty() ? "" : ", ") + L.vars[v].name;
        } else if (L.vars[v].scale != 1) {
            mesh.warnings.push_back(L.vars[v].name + " is in feet (unit " + L.vars[v].unit + "): converted to metres");
        }
    }
    if (!unread.empty()) mesh.notes.push_back("variables not read: " + unread);
    if (!h.title.empty()) mesh.notes.push_back("title: " + h.title);
    if (h.date) {
        const auto& d = *h.date;
        char b[80];
        std::snprintf(b, sizeof b, "%04d-%02d-%02d %02d:%02d:%02d", d[0], d[1], d[2], d[3], d[4], d[5]);
        const bool valid = d[1] >= 1 && d[1] <= 12 && d[2] >= 1 && d[2] <= 31 && d[3] >= 0 && d[3] < 24 && d[4] >= 0 &&
                           d[4] < 60 && d[5] >= 0 && d[5] < 60;
        mesh.notes.push_back(std::string("start date ") + b + (valid ? "" : " (as stored: not a valid date)") +
                             " in the date record (times are seconds from it)");
    }
}

}  // namespace

bool isSelafin(const std::string& path) {
    try {
        std::ifstream in(path, std::ios::binary);
        unsigned char b[kTitleBytes + 8];
        if (!in.read(reinterpret_cast<char*>(b), sizeof b)) return false;
        for (bool little : {false, true}) {
            const Endian e{little};
            if (e.u32(b) == kTitleBytes && e.u32(b + kTitleBytes + 4) == kTitleBytes) return true;
        }
    } catch (...) {
    }
    return false;
}

ModelMesh readSelafin(const std::string& path, const MeshReadOptions& opt) {
    RecordFile f(path, Endian{});
    unsigned char m[4];  // the byte order: the title record's opening length is 80 in one of them
    if (f.size() < 4) f.fail("the title record", 0, "the file is too short for a Selafin file");
    f.read(0, m, 4, "the title record");
    f.endian.little = f.endian.u32(m) != kTitleBytes;
    if (f.endian.u32(m) != kTitleBytes)
        f.fail("the title record", 0, "its length is not 80 in either byte order: not a Selafin file");
    Header h = readHeader(f);
    ModelMesh mesh;
    mesh.source = path;
    const uint64_t realBytes = readGeometry(f, h, mesh);
    mesh.kind = h.perElem == 3 ? "triangles" : "quadrilaterals";
    mesh.format = std::string("TELEMAC Selafin (") + (realBytes == 8 ? "double" : "single") + " precision" +
                  (f.endian.little ? ", little-endian)" : ")");
    mesh.faceName = [](size_t face) { return "element " + std::to_string(face + 1); };

    auto layout = std::make_shared<Layout>();
    layout->path = path, layout->endian = f.endian, layout->realBytes = realBytes, layout->nodes = h.nodes;
    layout->vars = h.vars;
    std::vector<double> times = scanSteps(f, h.at, *layout);
    const Roles roles = chooseVariables(path, h.vars, opt);
    readBed(mesh, layout, roles);
    bindSteps(mesh, layout, roles, std::move(times));
    describe(mesh, h, *layout, roles);
    checkModelMesh(mesh);
    return mesh;
}

}  // namespace hc::ingest::detail
