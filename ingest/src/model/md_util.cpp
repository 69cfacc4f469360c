// Reading variables of multidimensional files (md_util.h).
#include "md_util.h"

#include <cmath>

#include "../gdal_util.h"
#include "heightcast/core/error.h"

namespace hc::ingest::detail {

void MdFile::fail(const std::string& what) const { throw Error(path + ": " + what); }

ArrayPtr MdFile::find(const std::string& name) const {
    if (!root) return nullptr;
    CPLErrorStateBackuper quiet;
    if (!name.empty() && name[0] == '/') return root->OpenMDArrayFromFullname(name);
    return root->OpenMDArray(name);
}

ArrayPtr MdFile::open(const std::string& name, const std::string& role) const {
    ArrayPtr a = find(name);
    if (!a) fail("no variable '" + name + "' (" + role + ")");
    return a;
}

std::vector<std::string> MdFile::names() const {
    const char* const show[] = {"SHOW_ZERO_DIM=YES", nullptr};
    return root ? root->GetMDArrayNames(show) : std::vector<std::string>{};
}

namespace {
std::vector<double> readBox(const MdFile& f, const ArrayPtr& a, std::vector<GUInt64> start, std::vector<size_t> count) {
    size_t total = 1;
    for (size_t c : count) total *= c;
    std::vector<double> v(total);
    if (total &&
        !a->Read(start.data(), count.data(), nullptr, nullptr, GDALExtendedDataType::Create(GDT_Float64), v.data()))
        f.fail("cannot read the variable '" + a->GetFullName() + "': " + lastGdalError());
    return v;
}
}  // namespace

std::vector<double> MdFile::read(const ArrayPtr& a) const {
    const std::vector<size_t> shape = shapeOf(a);
    return readBox(*this, a, std::vector<GUInt64>(shape.size(), 0), shape);
}

std::vector<double> MdFile::readSlice(const ArrayPtr& a, size_t first) const {
    std::vector<size_t> shape = shapeOf(a);
    if (shape.empty() || first >= shape[0])
        fail("the variable '" + a->GetFullName() + "' has no index " + std::to_string(first));
    std::vector<GUInt64> start(shape.size(), 0);
    start[0] = first;
    shape[0] = 1;
    return readBox(*this, a, start, shape);
}

bool holds(const std::shared_ptr<GDALGroup>& root, std::initializer_list<const char*> all,
           std::initializer_list<const char*> any) {
    if (!root) return false;
    const MdFile f{"", nullptr, root};
    try {
        for (const char* n : all)
            if (!f.find(n)) return false;
        if (any.size() == 0) return true;
        for (const char* n : any)
            if (f.find(n)) return true;
    } catch (...) {
    }
    return false;
}

std::string textAttr(const ArrayPtr& a, const std::string& name) {
    if (!a) return "";
    auto at = a->GetAttribute(name);
    if (!at) return "";
    const char* v = at->ReadAsString();
    return v ? v : "";
}

std::optional<double> numAttr(const ArrayPtr& a, const std::string& name) {
    if (!a) return std::nullopt;
    auto at = a->GetAttribute(name);
    if (!at) return std::nullopt;
    return at->ReadAsDouble();
}

std::string trim(const std::string& s) {
    const size_t b = s.find_first_not_of(" \t\r\n"), e = s.find_last_not_of(" \t\r\n");
    return b == std::string::npos ? "" : s.substr(b, e - b + 1);
}

std::string rootText(const MdFile& f, const std::string& name) {
    auto at = f.root ? f.root->GetAttribute(name) : nullptr;
    const char* v = at ? at->ReadAsString() : nullptr;
    return v ? trim(v) : "";
}

ArrayPtr readNodes(const MdFile& f, const std::string& xName, const std::string& yName, ModelMesh& m) {
    ArrayPtr xv = f.open(xName, "node x"), yv = f.open(yName, "node y");
    m.nodeX = f.read(xv), m.nodeY = f.read(yv);
    if (m.nodeX.size() != m.nodeY.size()) f.fail(xName + " and " + yName + " differ in length");
    m.coordsFloat32 = xv->GetDataType().GetNumericDataType() == GDT_Float32;
    return xv;
}

std::optional<double> rootNum(const MdFile& f, const std::string& name) {
    auto at = f.root ? f.root->GetAttribute(name) : nullptr;
    if (!at) return std::nullopt;
    return at->ReadAsDouble();
}

std::optional<double> fillOf(const ArrayPtr& a) {
    bool has = false;
    const double f = a->GetNoDataValueAsDouble(&has);
    if (has) return f;
    if (auto m = numAttr(a, "missing_value")) return m;
    return std::nullopt;
}

size_t fillToNaN(std::vector<double>& v, std::optional<double> fill) {
    size_t n = 0;
    for (double& x : v)
        if (!std::isnan(x) && ((fill && x == *fill) || std::abs(x) >= 1e30)) x = NAN, ++n;
    return n;
}

std::vector<size_t> shapeOf(const ArrayPtr& a) {
    std::vector<size_t> s;
    for (const auto& d : a->GetDimensions()) s.push_back(size_t(d->GetSize()));
    return s;
}

std::vector<double> cfTimesS(const MdFile& f, const ArrayPtr& time) {
    const std::string units = time->GetUnit().empty() ? textAttr(time, "units") : time->GetUnit();
    const double unit = cfSecondsPerUnit(units);
    if (unit == 0)
        f.fail("the time variable '" + time->GetName() + "' has units '" + units +
               "', not CF time units ('seconds|minutes|hours|days since ...')");
    std::vector<double> t = f.read(time);
    for (double& v : t) v *= unit;
    checkIncreasing(f, t, time->GetName());
    return t;
}

void checkIncreasing(const MdFile& f, const std::vector<double>& t, const std::string& what) {
    for (size_t k = 0; k < t.size(); ++k) {
        if (!std::isfinite(t[k])) f.fail("the time of step " + std::to_string(k) + " (" + what + ") is not a number");
        if (k > 0 && !(t[k] > t[k - 1]))
            f.fail("the times (" + what + ") do not increase: step " + std::to_string(k) + " at " + fmt(t[k], 9) +
                   " s follows " + fmt(t[k - 1], 9) + " s");
    }
}

}  // namespace hc::ingest::detail
