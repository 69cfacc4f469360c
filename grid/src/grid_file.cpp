#include "heightcast/grid/grid_file.h"

#include <algorithm>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstring>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <vector>

#include "heightcast/core/sectioned_file.h"
#include "heightcast/core/checksum.h"
#include "heightcast/core/bytes.h"
#include "heightcast/core/error.h"
#include "quadtree_walk.h"

namespace hc {
namespace {

enum SectionKind : uint32_t { kMeta = 1, kCells = 2, kLayer = 3, kSteps = 4, kStep = 5 };

const FileFormat kFormat{{'\x89', 'H', 'C', 'G', 'R', 'I', 'D', '\n'}, kGridFileMajor, kGridFileMinor,
                         "heightcast grid (.hcg)", {kMeta, kCells, kLayer, kSteps, kStep}, /*blockChecksumsSince=*/2};
constexpr uint16_t kSummarySince = 2;  // the minor from which META holds the summary (GridSummary)
constexpr uint16_t kStepsSince = 3;    // the minor from which water is stored as steps (STEP, STEPS)

// The grid's own header fields (grid_file.h); pinned by the golden-bytes test.
namespace off {
constexpr size_t cellCount = 24, originX = 32, originY = 40, finestCell = 48, rootLevel = 56, minLevel = 57,
                 maxLevel = 58, layerCount = 59, contentHash = 64, structureHash = 72, rotation = 80, reserved = 80, reservedEnd = 120;
}
constexpr uint16_t kRotationSince = 3;  // from 1.3 on bytes 80..87 hold the rotation (f64 degrees); before, zero
static_assert(kGridHeaderBytes == kFileHeaderBytes);


std::string fmtDouble(double v) {
    char buf[32];
    auto r = std::to_chars(buf, buf + sizeof buf, v);  // shortest exact round trip
    return std::string(buf, r.ptr);
}

std::string fmtFloat(float v) {
    char buf[32];
    auto r = std::to_chars(buf, buf + sizeof buf, v);  // shortest decimal that reads back as this float
    return std::string(buf, r.ptr);
}

void appendString(std::vector<std::byte>& out, const std::string& s) {
    auto n = static_cast<uint32_t>(s.size());
    auto* p = reinterpret_cast<const std::byte*>(&n);
    out.insert(out.end(), p, p + 4);
    auto* q = reinterpret_cast<const std::byte*>(s.data());
    out.insert(out.end(), q, q + s.size());
}

std::string joinNumbers(std::span<const uint64_t> v) {
    std::string out;
    for (uint64_t x : v) {
        if (!out.empty()) out += ' ';
        out += std::to_string(x);
    }
    return out;
}

std::vector<std::byte> encodeMeta(const Grid& g, const GridSummary& summary) {
    std::vector<std::pair<std::string, std::string>> kv{{"crs_wkt", g.crsWkt}, {"crs_name", g.crsName}};
    const size_t firstStep = g.firstStepLayer();
    if (firstStep < g.layers.size()) {
        kv.emplace_back("step_layers", std::to_string(g.layers.size() - firstStep));
        for (size_t l = firstStep; l < g.layers.size(); ++l) {
            kv.emplace_back("step_layer." + std::to_string(l - firstStep) + ".name", g.layers[l].name);
            kv.emplace_back("step_layer." + std::to_string(l - firstStep) + ".units", g.layers[l].units);
        }
    }
    for (size_t l = 0; l < firstStep; ++l) {
        kv.emplace_back("layer." + std::to_string(l) + ".name", g.layers[l].name);
        kv.emplace_back("layer." + std::to_string(l) + ".units", g.layers[l].units);
        if (l < summary.layerMin.size()) {  // an empty grid has no values, so no range
            kv.emplace_back("layer." + std::to_string(l) + ".min", fmtFloat(summary.layerMin[l]));
            kv.emplace_back("layer." + std::to_string(l) + ".max", fmtFloat(summary.layerMax[l]));
        }
    }
    kv.emplace_back("summary.cells_per_level", joinNumbers(summary.cellsPerLevel));
    kv.emplace_back("summary.bounds_finest", joinNumbers(summary.boundsFinest));
    const IngestStats& s = g.stats;
    kv.emplace_back("ingest.source", s.sourcePath);
    kv.emplace_back("ingest.source_crs", s.sourceCrsName);
    if (!s.sourceKind.empty()) kv.emplace_back("ingest.source_kind", s.sourceKind);  // absent for rasters (older files too)
    if (!s.sourceFormat.empty()) kv.emplace_back("ingest.source_format", s.sourceFormat);  // flood model results only
    if (s.latticeResidualM >= 0) kv.emplace_back("ingest.lattice_residual_m", fmtDouble(s.latticeResidualM));
    kv.emplace_back("ingest.source_width", std::to_string(s.sourceWidth));
    kv.emplace_back("ingest.source_height", std::to_string(s.sourceHeight));
    kv.emplace_back("ingest.valid_pixels", std::to_string(s.validPixels));
    kv.emplace_back("ingest.tolerance_m", fmtDouble(s.toleranceM));
    kv.emplace_back("ingest.max_dev_m", fmtDouble(s.maxDevM));
    kv.emplace_back("ingest.rms_dev_m", fmtDouble(s.rmsDevM));
    // No wall time (ingest.seconds, written up to this change, still read): a grid's bytes depend on its inputs only,
    // so a run under mpirun, or a rerun, gives the same file (DESIGN.md section 13).
    std::vector<std::byte> out;
    for (auto& [k, v] : kv) {
        appendString(out, k);
        appendString(out, v);
    }
    return out;
}

// Parses META (checked on this first touch); for a file of a minor with a summary, fills `summary` and
// checks it against the header: counts per level add up to the cell count, only at levels in range, a
// bounding box inside the domain, a finite min <= max per layer. Whether it matches the cells is left to
// checkSummary() (a full pass).
void parseMeta(const SectionedFileReader& file, const FileSection& s, Grid& g, uint64_t cellCount, GridSummary* summary) {
    auto fail = [&](uint64_t at, const std::string& what) { file.fail(at, what); };
    const std::byte* d = file.data(s).data() - s.offset;  // file bytes, so offsets stay absolute (checked: data())
    std::map<std::string, std::string> kv;
    uint64_t p = s.offset, end = s.offset + s.bytes;
    auto readString = [&](std::string& out) {
        if (end - p < 4) fail(p, "META record is truncated");
        uint32_t n = bytes::load<uint32_t>(d + p);
        p += 4;
        if (n > end - p) fail(p - 4, "META string of " + std::to_string(n) + " bytes runs past its section");
        out.assign(reinterpret_cast<const char*>(d + p), n);
        p += n;
    };
    while (p < end) {
        uint64_t at = p;
        std::string k, v;
        readString(k);
        readString(v);
        if (!kv.emplace(k, v).second) fail(at, "META key '" + k + "' appears twice");
    }
    auto need = [&](const std::string& k) -> const std::string& {
        auto it = kv.find(k);
        if (it == kv.end()) fail(s.offset, "META lacks the key '" + k + "'");
        return it->second;
    };
    auto number = [&](const std::string& k, auto& out) {
        auto it = kv.find(k);
        if (it == kv.end()) return;  // ingest statistics are optional
        auto r = std::from_chars(it->second.data(), it->second.data() + it->second.size(), out);
        if (r.ec != std::errc() || r.ptr != it->second.data() + it->second.size())
            fail(s.offset, "META value of '" + k + "' is not a number: '" + it->second + "'");
    };
    g.crsWkt = need("crs_wkt");
    if (file.minor() >= 1) g.crsName = need("crs_name");  // 1.0 files have none: ""
    const size_t staticLayers = g.layers.size();
    for (size_t l = 0; l < staticLayers; ++l) {
        g.layers[l].name = need("layer." + std::to_string(l) + ".name");
        g.layers[l].units = need("layer." + std::to_string(l) + ".units");
        if (file.minor() >= kStepsSince && g.layers[l].name == "water_depth")
            fail(s.offset, "META layer " + std::to_string(l) + " is water_depth: from format 1.3 on water is stored as steps");
    }
    if (file.minor() >= kStepsSince && kv.count("step_layers")) {
        size_t n = 0;
        number("step_layers", n);
        if (n < 1 || n > 255 - staticLayers) fail(s.offset, "META step_layers is " + std::to_string(n) + ", not 1.." + std::to_string(255 - staticLayers));
        for (size_t l = 0; l < n; ++l)
            g.layers.push_back({need("step_layer." + std::to_string(l) + ".name"), need("step_layer." + std::to_string(l) + ".units")});
        if (g.layers[staticLayers].name != "water_depth")
            fail(s.offset, "META step_layer.0.name is '" + g.layers[staticLayers].name + "', not water_depth");
    }
    if (kv.count("ingest.source")) g.stats.sourcePath = kv["ingest.source"];
    if (kv.count("ingest.source_crs")) g.stats.sourceCrsName = kv["ingest.source_crs"];
    if (kv.count("ingest.source_kind")) g.stats.sourceKind = kv["ingest.source_kind"];
    if (kv.count("ingest.source_format")) g.stats.sourceFormat = kv["ingest.source_format"];
    number("ingest.lattice_residual_m", g.stats.latticeResidualM);
    number("ingest.source_width", g.stats.sourceWidth);
    number("ingest.source_height", g.stats.sourceHeight);
    number("ingest.valid_pixels", g.stats.validPixels);
    number("ingest.tolerance_m", g.stats.toleranceM);
    number("ingest.max_dev_m", g.stats.maxDevM);
    number("ingest.rms_dev_m", g.stats.rmsDevM);
    number("ingest.seconds", g.stats.seconds);
    if (file.minor() < kSummarySince || !summary) return;
    auto numbers = [&](const std::string& k, size_t count) {
        std::vector<uint64_t> out;
        const std::string& v = need(k);
        const char* c = v.data();
        const char* e = v.data() + v.size();
        while (c < e && out.size() <= count) {
            uint64_t x = 0;
            auto r = std::from_chars(c, e, x);
            if (r.ec != std::errc()) break;
            out.push_back(x);
            c = r.ptr;
            if (c < e && *c == ' ') ++c;
            else if (c < e) break;
        }
        if (out.size() != count || c != e)
            fail(s.offset, "META value of '" + k + "' is not " + std::to_string(count) + " numbers: '" + v + "'");
        return out;
    };
    summary->cellsPerLevel = numbers("summary.cells_per_level", static_cast<size_t>(g.maxLevel) + 1);
    uint64_t sum = 0;
    for (size_t l = 0; l < summary->cellsPerLevel.size(); ++l) {
        const uint64_t n = summary->cellsPerLevel[l];
        if (n > cellCount - sum || (n > 0 && static_cast<int>(l) < g.minLevel))
            fail(s.offset, "META summary.cells_per_level does not fit the header's " + std::to_string(cellCount) + " cells and levels");
        sum += n;
    }
    if (sum != cellCount) fail(s.offset, "META summary.cells_per_level adds up to " + std::to_string(sum) + " cells, the header declares " + std::to_string(cellCount));
    const auto b = numbers("summary.bounds_finest", 4);
    const uint64_t side = uint64_t{1} << g.rootLevel;
    if (b[0] > b[2] || b[1] > b[3] || b[2] > side || b[3] > side || (cellCount > 0 && (b[0] == b[2] || b[1] == b[3])))
        fail(s.offset, "META summary.bounds_finest is not a box in the domain of " + std::to_string(side) + " finest cells");
    std::copy(b.begin(), b.end(), summary->boundsFinest.begin());
    summary->layerMin.clear();
    summary->layerMax.clear();
    if (cellCount == 0) return;
    for (size_t l = 0; l < staticLayers; ++l) {
        float lo = 0, hi = 0;
        number("layer." + std::to_string(l) + ".min", lo);
        number("layer." + std::to_string(l) + ".max", hi);
        need("layer." + std::to_string(l) + ".min");
        need("layer." + std::to_string(l) + ".max");
        if (!std::isfinite(lo) || !std::isfinite(hi) || lo > hi)
            fail(s.offset, "META range of layer " + std::to_string(l) + " is not finite min <= max");
        summary->layerMin.push_back(lo);
        summary->layerMax.push_back(hi);
    }
}

// The summary of cells in memory (what the writer computes as they stream past).
class SummaryBuilder {
public:
    SummaryBuilder(int maxLevel, size_t layers) : layers_(layers) { s_.cellsPerLevel.assign(static_cast<size_t>(maxLevel) + 1, 0); }
    // Cells already checked (CellStreamCheck or Grid::validate): levels in range, values finite.
    void add(std::span<const uint64_t> codes, const std::vector<std::span<const float>>& values) {
        for (uint64_t c : codes) {
            const int level = codeLevel(c);
            ++s_.cellsPerLevel[static_cast<size_t>(level)];
            const uint64_t key = codeKey(c), x = mortonX(key), y = mortonY(key), span = uint64_t{1} << level;
            if (first_) s_.boundsFinest = {x, y, x + span, y + span};
            s_.boundsFinest = {std::min(s_.boundsFinest[0], x), std::min(s_.boundsFinest[1], y), std::max(s_.boundsFinest[2], x + span),
                               std::max(s_.boundsFinest[3], y + span)};
            first_ = false;
        }
        if (codes.empty()) return;
        if (s_.layerMin.empty()) {
            s_.layerMin.assign(layers_, HUGE_VALF);
            s_.layerMax.assign(layers_, -HUGE_VALF);
        }
        for (size_t l = 0; l < layers_; ++l)
            for (float v : values[l]) {
                s_.layerMin[l] = std::min(s_.layerMin[l], v);
                s_.layerMax[l] = std::max(s_.layerMax[l], v);
            }
    }
    const GridSummary& summary() const { return s_; }

    // The summary so far as words, and back (a rank's run goes on from the runs before it: GridFilePart).
    void save(std::vector<uint64_t>& out) const {
        out.push_back(first_);
        out.insert(out.end(), s_.cellsPerLevel.begin(), s_.cellsPerLevel.end());
        out.insert(out.end(), s_.boundsFinest.begin(), s_.boundsFinest.end());
        out.push_back(!s_.layerMin.empty());
        for (size_t l = 0; l < layers_; ++l) {
            out.push_back(s_.layerMin.empty() ? 0 : std::bit_cast<uint32_t>(s_.layerMin[l]));
            out.push_back(s_.layerMax.empty() ? 0 : std::bit_cast<uint32_t>(s_.layerMax[l]));
        }
    }
    // Adds the summary of the cells after these (another rank's run, GridFilePart).
    void merge(const SummaryBuilder& o) {
        if (o.first_) return;
        if (first_) {
            *this = o;
            return;
        }
        for (size_t l = 0; l < s_.cellsPerLevel.size(); ++l) s_.cellsPerLevel[l] += o.s_.cellsPerLevel[l];
        const auto &a = s_.boundsFinest, &b = o.s_.boundsFinest;
        s_.boundsFinest = {std::min(a[0], b[0]), std::min(a[1], b[1]), std::max(a[2], b[2]), std::max(a[3], b[3])};
        for (size_t l = 0; l < layers_; ++l) {
            s_.layerMin[l] = std::min(s_.layerMin[l], o.s_.layerMin[l]);
            s_.layerMax[l] = std::max(s_.layerMax[l], o.s_.layerMax[l]);
        }
    }
    // Words [at, ...) as save() wrote them; returns the index after them, or 0 where the words run short.
    size_t resume(std::span<const uint64_t> in, size_t at) {
        const size_t levels = s_.cellsPerLevel.size();
        if (in.size() < at + 1 + levels + 4 + 1 + 2 * layers_) return 0;
        first_ = in[at++] != 0;
        for (size_t l = 0; l < levels; ++l) s_.cellsPerLevel[l] = in[at++];
        for (size_t k = 0; k < 4; ++k) s_.boundsFinest[k] = in[at++];
        const bool ranges = in[at++] != 0;
        s_.layerMin.clear(), s_.layerMax.clear();
        for (size_t l = 0; l < layers_; ++l, at += 2)
            if (ranges) {
                s_.layerMin.push_back(std::bit_cast<float>(uint32_t(in[at])));
                s_.layerMax.push_back(std::bit_cast<float>(uint32_t(in[at + 1])));
            }
        return at;
    }

private:
    size_t layers_;
    bool first_ = true;
    GridSummary s_;
};

// Where one run of cells leaves the order check and the hashes for the next (GridFileWriter::streamState,
// GridFilePart::state): 64-bit words, little-endian: a tag, the static layers L, the order check (the first key not
// covered, the cells so far), the hashes ((1 + L) x 4 words: Hash64::State).
constexpr uint64_t kStreamStateTag = 0x4554415453474348ull;  // "HCGSTATE"

std::vector<std::byte> saveStream(CellStreamCheck::State check, const GridHasher& hasher, size_t layers) {
    std::vector<uint64_t> w{kStreamStateTag, layers, check.nextFree, check.count};
    for (const Hash64::State& h : hasher.save()) w.insert(w.end(), {h.state, h.length, h.pending, h.pendingBytes});
    std::vector<std::byte> out(w.size() * 8);
    std::memcpy(out.data(), w.data(), out.size());
    return out;
}

std::vector<uint64_t> words(std::span<const std::byte> bytes, const std::string& what) {
    if (bytes.size() % 8 != 0) throw Error(what + " is no whole number of words");
    std::vector<uint64_t> w(bytes.size() / 8);
    if (!w.empty()) std::memcpy(w.data(), bytes.data(), bytes.size());
    return w;
}

CellStreamCheck::State resumeStream(std::span<const std::byte> bytes, GridHasher& hasher, size_t layers, const std::string& what) {
    const std::vector<uint64_t> w = words(bytes, what + ": the cells' running state from the ranks before");
    if (w.size() != 4 + 4 * (1 + layers) || w[0] != kStreamStateTag || w[1] != layers)
        throw Error(what + ": the cells' running state from the ranks before is not one of this grid");
    std::vector<Hash64::State> h(1 + layers);
    for (size_t k = 0; k < h.size(); ++k) h[k] = {w[4 + 4 * k], w[5 + 4 * k], w[6 + 4 * k], w[7 + 4 * k]};
    hasher.resume(h);
    return {w[2], w[3]};
}

GridSummary summarise(const Grid& g) {
    SummaryBuilder b(g.maxLevel, g.layers.size());
    std::vector<std::span<const float>> values(g.values.begin(), g.values.end());
    b.add(g.codes, values);
    return b.summary();
}

bool operator==(const GridSummary& a, const GridSummary& b) {
    return a.cellsPerLevel == b.cellsPerLevel && a.boundsFinest == b.boundsFinest && a.layerMin == b.layerMin && a.layerMax == b.layerMax;
}

// A grid's geometry, CRS, layers and statistics, never its cells.
Grid shapeOf(const Grid& g) {
    Grid bare;
    bare.originWorldX = g.originWorldX;
    bare.originWorldY = g.originWorldY;
    bare.finestCellM = g.finestCellM;
    bare.rotationDeg = g.rotationDeg;
    bare.rootLevel = g.rootLevel;
    bare.minLevel = g.minLevel;
    bare.maxLevel = g.maxLevel;
    bare.crsWkt = g.crsWkt;
    bare.crsName = g.crsName;
    bare.layers = g.layers;
    bare.values.assign(g.layers.size(), {});
    bare.stats = g.stats;
    bare.steps = g.steps;
    bare.step = g.step;
    return bare;
}

struct Located {
    uint64_t cellCount = 0;
    const FileSection* meta = nullptr;
    const FileSection* cells = nullptr;
    std::vector<const FileSection*> layers;  // the static LAYER sections
    const FileSection* stepsTable = nullptr;  // STEPS (1.3 files with water)
    std::vector<const FileSection*> steps;    // STEP sections by step index (sized by parseSteps)
};

// The header's fields into `g` (no cells) and the sections located and sized: no section data read.
Located parseHeader(const SectionedFileReader& file, Grid& g) {
    const std::byte* h = file.header();
    auto fail = [&](uint64_t at, const std::string& what) { file.fail(at, what); };
    const size_t reservedFrom = file.minor() >= kRotationSince ? off::rotation + 8 : off::reserved;
    for (size_t i = reservedFrom; i < off::reservedEnd; ++i)
        if (h[i] != std::byte{0}) fail(i, "reserved header byte is not zero");
    if (file.minor() >= kRotationSince) {
        g.rotationDeg = bytes::load<double>(h + off::rotation);
        if (!(g.rotationDeg > -180 && g.rotationDeg <= 180)) fail(off::rotation, "rotation is not a number of degrees in (-180, 180]");
    }
    const uint64_t cellCount = bytes::load<uint64_t>(h + off::cellCount);
    g.originWorldX = bytes::load<double>(h + off::originX);
    g.originWorldY = bytes::load<double>(h + off::originY);
    g.finestCellM = bytes::load<double>(h + off::finestCell);
    g.rootLevel = static_cast<int>(bytes::load<uint8_t>(h + off::rootLevel));
    g.minLevel = static_cast<int>(bytes::load<uint8_t>(h + off::minLevel));
    g.maxLevel = static_cast<int>(bytes::load<uint8_t>(h + off::maxLevel));
    const unsigned layerCount = bytes::load<uint8_t>(h + off::layerCount);
    if (!std::isfinite(g.originWorldX) || !std::isfinite(g.originWorldY)) fail(off::originX, "origin is not finite");
    if (!(g.finestCellM > 0) || !std::isfinite(g.finestCellM)) fail(off::finestCell, "finest cell size is not a positive number");
    if (g.rootLevel > kMaxRootLevel) fail(off::rootLevel, "root level " + std::to_string(g.rootLevel) + " exceeds " + std::to_string(kMaxRootLevel));
    if (g.minLevel > g.maxLevel || g.maxLevel > g.rootLevel) fail(off::minLevel, "level range is inconsistent with the root level");
    if (layerCount < 1) fail(off::layerCount, "no layers (elevation is required)");
    // Every cell takes 8 bytes of CELLS and 4 of each LAYER: a count the file cannot hold is refused here,
    // before any size is computed from it (issue 11: 2^62 cells times 8 wrapped to 0 and passed the checks).
    const uint64_t fileBytes = file.mapping()->bytes().size();
    if (cellCount > fileBytes / (8 + 4 * uint64_t{layerCount}))
        fail(off::cellCount, "header declares " + std::to_string(cellCount) + " cells of " + std::to_string(8 + 4 * layerCount) +
                                 " bytes each, more than the " + std::to_string(fileBytes) + "-byte file holds");

    const FileSection* meta = nullptr;
    const FileSection* cells = nullptr;
    const FileSection* stepsTable = nullptr;
    std::vector<const FileSection*> stepSec;
    std::vector<const FileSection*> layerSec(layerCount, nullptr);
    const auto& sections = file.sections();
    for (size_t s = 0; s < sections.size(); ++s) {
        const FileSection& e = sections[s];
        const uint64_t at = SectionedFileReader::entryOffset(s);
        if (e.kind == kMeta) {
            if (meta) fail(at, "two META sections");
            meta = &e;
        } else if (e.kind == kCells) {
            if (cells) fail(at, "two CELLS sections");
            // Divide, never multiply a declared count: no product can wrap around.
            if (e.bytes % 8 != 0 || e.bytes / 8 != cellCount)
                fail(at + 16, "CELLS section holds " + std::to_string(e.bytes) + " bytes, expected 8 for each of " +
                                  std::to_string(cellCount) + " cells");
            cells = &e;
        } else if (e.kind == kLayer) {
            if (e.index >= layerCount || layerSec[e.index]) fail(at + 4, "LAYER section index " + std::to_string(e.index) + " is out of range or repeated");
            if (e.bytes % 4 != 0 || e.bytes / 4 != cellCount)
                fail(at + 16, "LAYER section holds " + std::to_string(e.bytes) + " bytes, expected 4 for each of " +
                                  std::to_string(cellCount) + " cells");
            layerSec[e.index] = &e;
        } else if (e.kind == kSteps) {
            if (stepsTable) fail(at, "two STEPS sections");
            stepsTable = &e;
        } else if (e.kind == kStep) {
            if (e.index >= stepSec.size()) stepSec.resize(size_t(e.index) + 1, nullptr);
            if (stepSec[e.index]) fail(at + 4, "STEP section index " + std::to_string(e.index) + " is repeated");
            stepSec[e.index] = &e;
        }
    }
    if (!meta) file.failFile("no META section");
    if (!cells) file.failFile("no CELLS section");
    for (unsigned l = 0; l < layerCount; ++l)
        if (!layerSec[l]) file.failFile("no LAYER section for layer " + std::to_string(l));

    g.layers.assign(layerCount, LayerInfo{});
    return {cellCount, meta, cells, std::move(layerSec), stepsTable, std::move(stepSec)};
}

// The STEPS table into g.steps, checked against the header, META's step layers and the STEP sections' sizes (after
// parseMeta). Reads STEPS only.
void parseSteps(const SectionedFileReader& file, Located& at, Grid& g) {
    auto fail = [&](uint64_t off, const std::string& what) { file.fail(off, what); };
    const size_t firstStep = g.firstStepLayer();
    const size_t L = g.layers.size() - firstStep;
    g.steps.clear();
    g.step = 0;
    if (L == 0) {
        if (at.stepsTable) fail(at.stepsTable->offset, "STEPS section in a grid without step layers (META step_layers)");
        if (!at.steps.empty()) file.failFile("STEP section in a grid without step layers (META step_layers)");
        return;
    }
    if (file.minor() < kStepsSince) return;  // a 1.2 water LAYER: one step at time 0, no table
    if (!at.stepsTable) file.failFile("META declares step layers but there is no STEPS section");
    const FileSection& t = *at.stepsTable;
    const uint64_t record = 24 + 8 * uint64_t(L);
    if (t.bytes == 0 || t.bytes % record != 0)
        fail(t.offset, "STEPS section holds " + std::to_string(t.bytes) + " bytes, not a positive multiple of " + std::to_string(record));
    const uint64_t count = t.bytes / record;
    if (at.cellCount > UINT32_MAX) fail(t.offset, "a grid with water steps holds at most 2^32 - 1 cells");
    if (at.steps.size() != count) file.failFile("STEPS lists " + std::to_string(count) + " steps, the file has " + std::to_string(at.steps.size()) + " STEP sections");
    const std::byte* d = file.data(t).data();
    for (uint64_t k = 0; k < count; ++k) {
        const std::byte* r = d + k * record;
        const uint64_t where = t.offset + k * record;
        StepInfo s;
        s.timeS = bytes::load<double>(r);
        s.wetCells = bytes::load<uint64_t>(r + 8);
        s.contentHash = bytes::load<uint64_t>(r + 16);
        const std::string name = "step " + std::to_string(k);
        if (!std::isfinite(s.timeS)) fail(where, name + ": time is not finite");
        if (k > 0 && !(s.timeS > g.steps.back().timeS)) fail(where, name + ": time " + fmtDouble(s.timeS) + " s does not follow " + fmtDouble(g.steps.back().timeS) + " s");
        if (s.wetCells > at.cellCount) fail(where + 8, name + ": " + std::to_string(s.wetCells) + " wet cells of " + std::to_string(at.cellCount));
        if (!at.steps[k]) file.failFile("no STEP section for " + name);
        const FileSection& sec = *at.steps[k];
        if (sec.bytes % (4 * (1 + L)) != 0 || sec.bytes / (4 * (1 + L)) != s.wetCells)
            fail(sec.offset, "STEP section of " + name + " holds " + std::to_string(sec.bytes) + " bytes, expected " + std::to_string(4 * (1 + L)) +
                                 " for each of " + std::to_string(s.wetCells) + " wet cells");
        for (size_t l = 0; l < L; ++l) {
            const float lo = bytes::load<float>(r + 24 + 8 * l), hi = bytes::load<float>(r + 28 + 8 * l);
            const bool ok = s.wetCells == 0 ? (lo == 0 && hi == 0) : (std::isfinite(lo) && std::isfinite(hi) && lo <= hi && (l > 0 || lo > 0));
            if (!ok) fail(where + 24 + 8 * l, name + ": range of " + g.layers[firstStep + l].name + " is not finite min <= max (min > 0 for water_depth)");
            if (s.wetCells > 0) {
                s.layerMin.push_back(lo);
                s.layerMax.push_back(hi);
            }
        }
        g.steps.push_back(std::move(s));
    }
}

// Step k's STEP section, read whole (its blocks checked) and validated against its STEPS record.
WaterStepData loadStep(const SectionedFileReader& file, const Located& at, const Grid& g, size_t k) {
    const StepInfo& info = g.steps[k];
    const FileSection& sec = *at.steps[k];
    const size_t L = g.layers.size() - g.firstStepLayer();
    const uint64_t w = info.wetCells;
    const std::byte* d = file.data(sec).data();
    WaterStepData out;
    out.timeS = info.timeS;
    out.wet.resize(w);
    out.values.assign(L, std::vector<float>(w));
    if (w > 0) {  // a dry step (none wet: a simulation's first time) has empty vectors, whose data() memcpy must not see
        std::memcpy(out.wet.data(), d, 4 * w);
        for (size_t l = 0; l < L; ++l) std::memcpy(out.values[l].data(), d + 4 * w * (1 + l), 4 * w);
    }
    const std::string name = "step " + std::to_string(k);
    for (uint64_t j = 0; j < w; ++j)
        if (out.wet[j] >= at.cellCount || (j > 0 && out.wet[j] <= out.wet[j - 1]))
            file.fail(sec.offset + 4 * j, name + ": wet cell index " + std::to_string(out.wet[j]) + " is not ascending below the cell count");
    for (size_t l = 0; l < L; ++l) {
        float lo = HUGE_VALF, hi = -HUGE_VALF;
        for (uint64_t j = 0; j < w; ++j) {
            const float v = out.values[l][j];
            if (!std::isfinite(v) || (l == 0 && !(v > 0)))
                file.fail(sec.offset + 4 * w * (1 + l) + 4 * j, name + ": " + g.layers[g.firstStepLayer() + l].name + " value is not finite" +
                                                                  (l == 0 ? " and > 0" : ""));
            lo = std::min(lo, v);
            hi = std::max(hi, v);
        }
        if (w > 0 && (lo != info.layerMin[l] || hi != info.layerMax[l]))
            file.fail(sec.offset, name + ": the range of " + g.layers[g.firstStepLayer() + l].name + " does not match STEPS");
    }
    return out;
}

// The selected step's ranges appended to the static layers' summary: what summarise() of the grid with that
// step selected gives (dry cells read as 0).
void addStepRanges(GridSummary& s, const Grid& g, uint64_t cellCount) {
    if (g.steps.empty() || cellCount == 0) return;
    const StepInfo& info = g.steps[g.step];
    const size_t L = g.layers.size() - g.firstStepLayer();
    s.layerMin.resize(g.firstStepLayer());
    s.layerMax.resize(g.firstStepLayer());
    for (size_t l = 0; l < L; ++l) {
        float lo = info.wetCells ? info.layerMin[l] : HUGE_VALF, hi = info.wetCells ? info.layerMax[l] : -HUGE_VALF;
        if (info.wetCells < cellCount) lo = std::min(lo, 0.0f), hi = std::max(hi, 0.0f);
        s.layerMin.push_back(lo);
        s.layerMax.push_back(hi);
    }
}

// The header's content hash of a file with steps: the static grid's content hash and every step's (time, hash).
uint64_t scenarioHash(uint64_t staticContentHash, const std::vector<StepInfo>& steps) {
    Hash64 h(0x6863737465707321ull);
    h.updateValue(staticContentHash);
    for (const StepInfo& s : steps) {
        h.updateValue(s.timeS);
        h.updateValue(s.contentHash);
    }
    return h.digest();
}

// Name and digest of each static layer (combineContentHash's parts).
std::vector<std::pair<std::string, uint64_t>> staticDigests(const Grid& g) {
    std::vector<std::pair<std::string, uint64_t>> parts;
    for (size_t l = 0; l < g.firstStepLayer(); ++l) {
        Hash64 h;
        h.update(std::as_bytes(std::span<const float>(g.values[l])));
        parts.emplace_back(g.layers[l].name, h.digest());
    }
    return parts;
}

// Grid::contentHash of the grid's static layers alone.
uint64_t staticContentHash(const Grid& g) { return combineContentHash(g.structureHash(), staticDigests(g)); }

// Grid::contentHash of the grid with `data` as its step, without filling its step layers; from `known` digests
// of the grid when given.
uint64_t stepContentHash(const Grid& g, const WaterStepData& data, const StaticDigests* known = nullptr) {
    auto parts = known ? known->layers : staticDigests(g);
    for (size_t l = 0; l < data.values.size(); ++l)
        parts.emplace_back(g.layers[g.firstStepLayer() + l].name, sparseLayerDigest(g.cellCount(), data.wet, data.values[l]));
    return combineContentHash(known ? known->structureHash : g.structureHash(), parts);
}

// Fails unless `step` is one of the file's steps (a grid without `steps` has only step 0).
void checkStepIndex(const SectionedFileReader& file, const Grid& g, size_t step) {
    const size_t n = g.steps.empty() ? 1 : g.steps.size();
    if (step >= n)
        file.failFile("has no step " + std::to_string(step) + ": it holds " + std::to_string(g.stepCount()) + " water step" +
                      (g.stepCount() == 1 ? "" : "s") + (g.stepCount() ? " (0.." + std::to_string(g.stepCount() - 1) + ")" : ""));
}

Grid parseGrid(const SectionedFileReader& file, size_t step, Located* located = nullptr) {
    const std::byte* h = file.header();
    auto fail = [&](uint64_t at, const std::string& what) { file.fail(at, what); };
    Grid g;
    Located at = parseHeader(file, g);
    const uint64_t cellCount = at.cellCount;
    const FileSection* cells = at.cells;
    const auto& layerSec = at.layers;
    const size_t staticLayers = layerSec.size();
    GridSummary stored;
    parseMeta(file, *at.meta, g, cellCount, &stored);
    parseSteps(file, at, g);
    checkStepIndex(file, g, step);
    g.codes.resize(cellCount);
    std::memcpy(g.codes.data(), file.data(*cells).data(), cells->bytes);
    g.values.assign(g.layers.size(), {});
    for (size_t l = 0; l < staticLayers; ++l) {
        g.values[l].resize(cellCount);
        std::memcpy(g.values[l].data(), file.data(*layerSec[l]).data(), layerSec[l]->bytes);
    }
    if (!g.steps.empty()) selectStep(g, loadStep(file, at, g, step), step);
    std::string problem = g.validate();
    if (!problem.empty()) fail(cells->offset, "invalid grid: " + problem);
    if (g.structureHash() != bytes::load<uint64_t>(h + off::structureHash)) fail(off::structureHash, "structure hash does not match the cells");
    if (g.steps.empty()) {
        if (g.contentHash() != bytes::load<uint64_t>(h + off::contentHash)) fail(off::contentHash, "content hash does not match the cells and values");
    } else {
        if (g.contentHash() != g.steps[step].contentHash)
            fail(at.stepsTable->offset, "step " + std::to_string(step) + ": content hash does not match the cells and values");
        if (scenarioHash(staticContentHash(g), g.steps) != bytes::load<uint64_t>(h + off::contentHash))
            fail(off::contentHash, "content hash does not match the cells, values and steps");
    }
    addStepRanges(stored, g, cellCount);
    if (file.minor() >= kSummarySince && !(summarise(g) == stored))
        fail(at.meta->offset, "META summary (cells per level, bounds, value ranges) does not match the cells");
    if (located) *located = std::move(at);
    return g;
}

}  // namespace

// The grid's static part: its layers before the step layers, as the writer's hasher and summary see it.
Grid staticShapeOf(const Grid& g) {
    Grid bare = shapeOf(g);
    bare.layers.resize(g.firstStepLayer());
    bare.values.resize(g.firstStepLayer());
    bare.steps.clear();
    bare.step = 0;
    return bare;
}

WaterStepData sparseStep(const Grid& g) {
    WaterStepData out;
    out.timeS = g.stepTimeS();
    const size_t first = g.firstStepLayer();
    if (first >= g.layers.size()) return out;
    const auto& depth = g.values[first];
    out.values.resize(g.layers.size() - first);
    for (size_t i = 0; i < depth.size(); ++i) {
        if (depth[i] > 0) {
            out.wet.push_back(static_cast<uint32_t>(i));
            for (size_t l = first; l < g.layers.size(); ++l) out.values[l - first].push_back(g.values[l][i]);
            continue;
        }
        // A step stores its wet cells only: a value on a dry cell would be lost, so it is refused.
        if (depth[i] < 0)
            throw Error("cell " + std::to_string(i) + " has water_depth " + fmtFloat(depth[i]) + ": depths are >= 0 (0 = dry)");
        for (size_t l = first + 1; l < g.layers.size(); ++l)
            if (g.values[l][i] != 0)
                throw Error("cell " + std::to_string(i) + " is dry (water_depth " + fmtFloat(depth[i]) + ") but its step layer " + g.layers[l].name +
                            " is " + fmtFloat(g.values[l][i]) + ": step layers (water_depth and the layers after it) are stored on wet cells "
                            "only; put a layer that does not change with the water before water_depth");
    }
    return out;
}

void selectStep(Grid& g, const WaterStepData& data, size_t step) {
    const size_t first = g.firstStepLayer();
    for (size_t l = first; l < g.layers.size(); ++l) {
        auto& v = g.values[l];
        v.assign(g.codes.size(), 0.0f);
        const auto& src = data.values.at(l - first);
        for (size_t j = 0; j < data.wet.size(); ++j) v.at(data.wet[j]) = src.at(j);
    }
    g.step = step;
}

struct GridFileWriter::Impl {
    Impl(const std::string& path, const Grid& gridShape, uint64_t cells, std::vector<FileSection> layout, size_t stepsAnnounced)
        : out(path, kFormat, std::move(layout), 1 + (stepsAnnounced ? stepsAnnounced + 1 : 0)), shape(gridShape), staticShape(staticShapeOf(gridShape)),
          cellCount(cells), stepCount(stepsAnnounced), check(staticShape), hasher(staticShape, cells),
          summary(staticShape.maxLevel, staticShape.layers.size()) {}
    SectionedFileWriter out;
    Grid shape;        // geometry, CRS and layers (step layers too); no cells
    Grid staticShape;  // the same without the step layers
    uint64_t cellCount;
    size_t stepCount;
    CellStreamCheck check;
    GridHasher hasher;
    SummaryBuilder summary;
    uint64_t written = 0;
    std::vector<StepInfo> steps;  // those appended so far
};

GridFileWriter::GridFileWriter(const std::string& path, const Grid& shape, uint64_t cellCount, size_t stepCount) {
    std::string problem = shape.validateShape();
    if (!problem.empty()) throw Error(path + ": refusing to write an invalid grid: " + problem);
    const bool water = shape.firstStepLayer() < shape.layers.size();
    if (water && stepCount == 0) throw Error(path + ": a grid with water needs at least one water step");
    if (!water && stepCount > 0) throw Error(path + ": water steps need a water_depth layer");
    if (water && cellCount > UINT32_MAX) throw Error(path + ": a grid with water steps holds at most 2^32 - 1 cells");
    Grid bare = shapeOf(shape);
    bare.steps.clear();
    bare.step = 0;
    // Layout: CELLS, static LAYER..., then the STEP sections, STEPS and META as they become known.
    std::vector<FileSection> layout{{kCells, 0, 0, cellCount * 8, 0}};
    for (size_t l = 0; l < shape.firstStepLayer(); ++l) layout.push_back({kLayer, static_cast<uint32_t>(l), 0, cellCount * 4, 0});
    impl_ = std::make_unique<Impl>(path, bare, cellCount, std::move(layout), stepCount);
}

GridFileWriter::~GridFileWriter() = default;

namespace {

// The shape of a batch of cells: a value array per static layer, each as long as the codes.
void checkBatchShape(const std::string& path, std::span<const uint64_t> codes, const std::vector<std::span<const float>>& layerValues, size_t layers) {
    if (layerValues.size() != layers)
        throw Error(path + ": " + std::to_string(layerValues.size()) + " value arrays for " + std::to_string(layers) + " static layers");
    for (const auto& v : layerValues)
        if (v.size() != codes.size()) throw Error(path + ": layer values and cells differ in number");
}

// Every cell's rules (CellStreamCheck), then the cells into the summary.
void checkCells(const std::string& path, std::span<const uint64_t> codes, const std::vector<std::span<const float>>& layerValues,
                CellStreamCheck& check, SummaryBuilder& summary) {
    const size_t layers = layerValues.size();
    float v[256];
    for (size_t i = 0; i < codes.size(); ++i) {
        for (size_t l = 0; l < layers; ++l) v[l] = layerValues[l][i];
        std::string problem = check.next(codes[i], v);
        if (!problem.empty()) throw Error(path + ": refusing to write an invalid grid: " + problem);
    }
    summary.add(codes, layerValues);
}

void hashCells(std::span<const uint64_t> codes, const std::vector<std::span<const float>>& layerValues, GridHasher& hasher) {
    hasher.addCodes(codes);
    for (size_t l = 0; l < layerValues.size(); ++l) hasher.addValues(l, layerValues[l]);
}

}  // namespace

void GridFileWriter::append(std::span<const uint64_t> codes, const std::vector<std::span<const float>>& layerValues) {
    Impl& w = *impl_;
    const size_t layers = w.staticShape.layers.size();
    const std::string& path = w.out.path();
    checkBatchShape(path, codes, layerValues, layers);
    if (codes.size() > w.cellCount - w.written) throw Error(path + ": more cells than the " + std::to_string(w.cellCount) + " announced");
    checkCells(path, codes, layerValues, w.check, w.summary);
    hashCells(codes, layerValues, w.hasher);
    w.out.append(0, std::as_bytes(codes));
    for (size_t l = 0; l < layers; ++l) w.out.append(1 + l, std::as_bytes(layerValues[l]));
    w.written += codes.size();
}

// A part for addPart: 64-bit words: first cell, cells, the state's bytes, the pieces' count; then the state, then the
// pieces (FilePiece, 32 bytes each).
std::vector<std::byte> GridFileWriter::placement() const {
    const Impl& w = *impl_;
    std::vector<std::byte> out(8);
    bytes::store(out, 0, w.cellCount);
    const std::vector<std::byte> p = w.out.placement().encode();
    out.insert(out.end(), p.begin(), p.end());
    return out;
}

std::vector<std::byte> GridFileWriter::streamState() const {
    const Impl& w = *impl_;
    return saveStream(w.check.save(), w.hasher, w.staticShape.layers.size());
}

// A part for addPart: five 64-bit words (first cell, cells, the bytes of its state, of its summary, the pieces' count),
// then the state after its cells (saveStream), its cells' summary (SummaryBuilder::save), the pieces (FilePiece, 32 bytes
// each).
void GridFileWriter::addPart(std::span<const std::byte> part) {
    Impl& w = *impl_;
    const std::string& path = w.out.path();
    if (part.size() < 40) throw Error(path + ": a rank's part of " + std::to_string(part.size()) + " bytes is cut short");
    uint64_t head[5];
    std::memcpy(head, part.data(), sizeof head);
    const auto [first, cells, stateBytes, summaryBytes, pieces] = head;
    if (stateBytes > part.size() - 40 || summaryBytes > part.size() - 40 - stateBytes ||
        pieces > (part.size() - 40 - stateBytes - summaryBytes) / sizeof(FilePiece) ||
        40 + stateBytes + summaryBytes + pieces * sizeof(FilePiece) != part.size())
        throw Error(path + ": a rank's part is malformed");
    if (first != w.written || cells > w.cellCount - w.written)
        throw Error(path + ": a rank's part holds cells " + std::to_string(first) + ".." + std::to_string(first + cells) + " where cell " +
                    std::to_string(w.written) + " comes next of " + std::to_string(w.cellCount));
    std::vector<FilePiece> table(pieces);
    if (pieces) std::memcpy(table.data(), part.data() + 40 + stateBytes + summaryBytes, pieces * sizeof(FilePiece));
    w.out.addPieces(table);
    const CellStreamCheck::State after = resumeStream(part.subspan(40, stateBytes), w.hasher, w.staticShape.layers.size(), path);
    w.check.resume(after);
    SummaryBuilder theirs(w.staticShape.maxLevel, w.staticShape.layers.size());
    const std::vector<uint64_t> sw = words(part.subspan(40 + stateBytes, summaryBytes), path + ": a rank's summary");
    if (theirs.resume(sw, 0) != sw.size() || sw.empty()) throw Error(path + ": a rank's summary is malformed");
    w.summary.merge(theirs);
    w.written += cells;
    if (after.count != w.written)
        throw Error(path + ": a rank's part ends at cell " + std::to_string(after.count) + ", not at the " + std::to_string(w.written) + " written");
}

struct GridFilePart::Impl {
    Impl(FilePlacement placement, const Grid& gridShape, uint64_t cells, uint64_t firstCell)
        : out(std::move(placement)), staticShape(staticShapeOf(gridShape)), cellCount(cells), first(firstCell), check(staticShape),
          hasher(staticShape, cells), summary(staticShape.maxLevel, staticShape.layers.size()) {
        check.resume({0, first});  // cells are numbered as in the file; the first one's order is checked by resume()
    }
    SectionedFilePart out;
    Grid staticShape;
    uint64_t cellCount, first;
    CellStreamCheck check;  // this run's cells among themselves, as they are appended
    GridHasher hasher;
    SummaryBuilder summary;
    uint64_t written = 0, followed = 0;  // cells of this run written, and hashed
    uint64_t firstKey = 0;               // of the run's first cell
    std::optional<CellStreamCheck::State> before;  // where the runs before leave the order check (resume)
    std::string path;

    // The run's first cell after the cells before it (CellStreamCheck's rule across the seam).
    void checkSeam() const {
        if (before && written > 0 && first > 0 && firstKey < before->nextFree)
            throw Error(path + ": refusing to write an invalid grid: cell " + std::to_string(first) + " overlaps or precedes cell " +
                        std::to_string(first - 1));
    }
};

GridFilePart::GridFilePart(std::span<const std::byte> placement, const Grid& shape, uint64_t firstCell) {
    if (placement.size() < 8) throw Error("a grid file's placement is cut short");
    const uint64_t cells = bytes::load<uint64_t>(placement.data());
    FilePlacement p = FilePlacement::decode(placement.subspan(8));
    const std::string path = p.path;
    if (p.sections.size() < 1 + shape.firstStepLayer() || p.sections[0].bytes != 8 * cells || firstCell > cells)
        throw Error(path + ": the placement does not match this grid (" + std::to_string(cells) + " cells)");
    impl_ = std::make_unique<Impl>(std::move(p), shape, cells, firstCell);
    impl_->path = path;
}

GridFilePart::~GridFilePart() = default;

void GridFilePart::append(std::span<const uint64_t> codes, const std::vector<std::span<const float>>& layerValues) {
    Impl& w = *impl_;
    const size_t layers = w.staticShape.layers.size();
    checkBatchShape(w.path, codes, layerValues, layers);
    const uint64_t at = w.first + w.written;
    if (codes.size() > w.cellCount - at) throw Error(w.path + ": more cells than the " + std::to_string(w.cellCount) + " announced");
    if (codes.empty()) return;
    // Checked and summarised here, each rank its own run at once; only the seam and the hashes wait for the ranks before.
    checkCells(w.path, codes, layerValues, w.check, w.summary);
    if (w.written == 0) w.firstKey = codeKey(codes[0]);
    w.out.writeAt(0, 8 * at, std::as_bytes(codes));
    for (size_t l = 0; l < layers; ++l) w.out.writeAt(1 + l, 4 * at, std::as_bytes(layerValues[l]));
    w.written += codes.size();
    w.checkSeam();
}

void GridFilePart::resume(std::span<const std::byte> state) {
    Impl& w = *impl_;
    const CellStreamCheck::State before = resumeStream(state, w.hasher, w.staticShape.layers.size(), w.path);
    if (before.count != w.first)
        throw Error(w.path + ": the ranks before this one wrote " + std::to_string(before.count) + " cells, but its own begin at cell " +
                    std::to_string(w.first));
    w.before = before;
    w.checkSeam();
}

void GridFilePart::follow() {
    Impl& w = *impl_;
    if (!w.before) throw Error(w.path + ": a rank's cells hashed before the state of the ranks before it arrived");
    const size_t layers = w.staticShape.layers.size();
    constexpr uint64_t kChunk = uint64_t{1} << 17;  // 1 MiB of codes at a time
    std::vector<uint64_t> codes;
    std::vector<std::vector<float>> values(layers);
    while (w.followed < w.written) {
        const uint64_t at = w.first + w.followed, n = std::min(kChunk, w.written - w.followed);
        codes.resize(n);
        w.out.readAt(0, 8 * at, std::as_writable_bytes(std::span<uint64_t>(codes)));
        for (size_t l = 0; l < layers; ++l) {
            values[l].resize(n);
            w.out.readAt(1 + l, 4 * at, std::as_writable_bytes(std::span<float>(values[l])));
        }
        hashCells(codes, std::vector<std::span<const float>>(values.begin(), values.end()), w.hasher);
        w.followed += n;
    }
}

std::vector<std::byte> GridFilePart::state() const {
    const Impl& w = *impl_;
    if (!w.before || w.followed != w.written)
        throw Error(w.path + ": a rank's state asked for with " + std::to_string(w.followed) + " of its " + std::to_string(w.written) + " cells hashed");
    // The order check goes on from this run's last cell, or from the runs before where this one is empty.
    const CellStreamCheck::State after{w.written > 0 ? w.check.save().nextFree : w.before->nextFree, w.first + w.written};
    return saveStream(after, w.hasher, w.staticShape.layers.size());
}

std::vector<std::byte> GridFilePart::finish() {
    Impl& w = *impl_;
    const std::vector<std::byte> s = state();
    const std::vector<FilePiece> pieces = w.out.finish();
    std::vector<uint64_t> summary;
    w.summary.save(summary);
    const size_t summaryBytes = 8 * summary.size();
    std::vector<std::byte> out(40 + s.size() + summaryBytes + pieces.size() * sizeof(FilePiece));
    const uint64_t head[5] = {w.first, w.written, s.size(), summaryBytes, pieces.size()};
    std::memcpy(out.data(), head, sizeof head);
    std::memcpy(out.data() + 40, s.data(), s.size());
    std::memcpy(out.data() + 40 + s.size(), summary.data(), summaryBytes);
    if (!pieces.empty()) std::memcpy(out.data() + 40 + s.size() + summaryBytes, pieces.data(), pieces.size() * sizeof(FilePiece));
    return out;
}

void GridFileWriter::appendStep(const WaterStepData& step) {
    Impl& w = *impl_;
    const std::string& path = w.out.path();
    const size_t k = w.steps.size();
    const std::string name = path + ": step " + std::to_string(k);
    if (w.written != w.cellCount) throw Error(name + " comes before all " + std::to_string(w.cellCount) + " cells");
    if (k >= w.stepCount) throw Error(name + ": more steps than the " + std::to_string(w.stepCount) + " announced");
    const size_t first = w.shape.firstStepLayer(), L = w.shape.layers.size() - first;
    if (step.values.size() != L) throw Error(name + ": " + std::to_string(step.values.size()) + " value arrays for " + std::to_string(L) + " step layers");
    for (const auto& v : step.values)
        if (v.size() != step.wet.size()) throw Error(name + ": step values and wet cells differ in number");
    if (!std::isfinite(step.timeS)) throw Error(name + ": time is not finite");
    if (k > 0 && !(step.timeS > w.steps.back().timeS))
        throw Error(name + ": times must increase strictly, " + fmtDouble(step.timeS) + " s follows " + fmtDouble(w.steps.back().timeS) + " s");
    const size_t n = step.wet.size();
    for (size_t j = 0; j < n; ++j)
        if (step.wet[j] >= w.cellCount || (j > 0 && step.wet[j] <= step.wet[j - 1]))
            throw Error(name + ": wet cell indices must ascend below the cell count");
    StepInfo info;
    info.timeS = step.timeS;
    info.wetCells = n;
    std::vector<std::pair<std::string, uint64_t>> parts;
    for (size_t l = 0; l < first; ++l) parts.emplace_back(w.shape.layers[l].name, w.hasher.layerDigest(l));
    for (size_t l = 0; l < L; ++l) {
        float lo = HUGE_VALF, hi = -HUGE_VALF;
        for (float v : step.values[l]) {
            if (!std::isfinite(v) || (l == 0 && !(v > 0)))
                throw Error(name + ": " + w.shape.layers[first + l].name + " values must be finite" + (l == 0 ? " and > 0 (only wet cells are stored)" : ""));
            lo = std::min(lo, v);
            hi = std::max(hi, v);
        }
        if (n > 0) info.layerMin.push_back(lo), info.layerMax.push_back(hi);
        parts.emplace_back(w.shape.layers[first + l].name, sparseLayerDigest(w.cellCount, step.wet, step.values[l]));
    }
    info.contentHash = combineContentHash(w.hasher.structureHash(), parts);
    std::vector<std::byte> data(4 * n * (1 + L));
    if (n > 0) {
        std::memcpy(data.data(), step.wet.data(), 4 * n);
        for (size_t l = 0; l < L; ++l) std::memcpy(data.data() + 4 * n * (1 + l), step.values[l].data(), 4 * n);
    }
    w.out.addSection(kStep, static_cast<uint32_t>(k), data);
    w.steps.push_back(std::move(info));
}

void GridFileWriter::commit(const IngestStats& stats) {
    Impl& w = *impl_;
    if (w.written != w.cellCount)
        throw Error(w.out.path() + ": " + std::to_string(w.written) + " cells written of " + std::to_string(w.cellCount) + " announced");
    if (w.steps.size() != w.stepCount)
        throw Error(w.out.path() + ": " + std::to_string(w.steps.size()) + " water steps written of " + std::to_string(w.stepCount) + " announced");
    w.shape.stats = stats;
    uint64_t contentHash = w.hasher.contentHash();
    if (w.stepCount > 0) {
        const size_t L = w.shape.layers.size() - w.shape.firstStepLayer();
        std::vector<std::byte> table(w.steps.size() * (24 + 8 * L));
        for (size_t k = 0; k < w.steps.size(); ++k) {
            const StepInfo& s = w.steps[k];
            const size_t at = k * (24 + 8 * L);
            bytes::store(table, at, s.timeS);
            bytes::store(table, at + 8, s.wetCells);
            bytes::store(table, at + 16, s.contentHash);
            for (size_t l = 0; l < L; ++l) {
                bytes::store(table, at + 24 + 8 * l, s.wetCells ? s.layerMin[l] : 0.0f);
                bytes::store(table, at + 28 + 8 * l, s.wetCells ? s.layerMax[l] : 0.0f);
            }
        }
        w.out.addSection(kSteps, 0, table);
        contentHash = scenarioHash(contentHash, w.steps);
    }
    w.out.addSection(kMeta, 0, encodeMeta(w.shape, w.summary.summary()));
    const Grid& g = w.shape;
    std::vector<std::byte> head(kFileHeaderBytes, std::byte{0});
    bytes::store(head, off::cellCount, w.cellCount);
    bytes::store(head, off::originX, g.originWorldX);
    bytes::store(head, off::originY, g.originWorldY);
    bytes::store(head, off::finestCell, g.finestCellM);
    bytes::store(head, off::rotation, g.rotationDeg == 0 ? 0.0 : g.rotationDeg);  // never -0: its sign bit is a byte
    bytes::store(head, off::rootLevel, static_cast<uint8_t>(g.rootLevel));
    bytes::store(head, off::minLevel, static_cast<uint8_t>(g.minLevel));
    bytes::store(head, off::maxLevel, static_cast<uint8_t>(g.maxLevel));
    bytes::store(head, off::layerCount, static_cast<uint8_t>(g.firstStepLayer()));
    bytes::store(head, off::contentHash, contentHash);
    bytes::store(head, off::structureHash, w.hasher.structureHash());
    w.out.commit(std::move(head));
}

void writeGrid(const Grid& g, const std::string& path) {
    std::string problem = g.validate();
    if (!problem.empty()) throw Error(path + ": refusing to write an invalid grid: " + problem);
    const bool water = g.firstStepLayer() < g.layers.size();
    GridFileWriter w(path, g, g.cellCount(), water ? 1 : 0);
    std::vector<std::span<const float>> values;
    for (size_t l = 0; l < g.firstStepLayer(); ++l) values.emplace_back(g.values[l]);
    w.append(g.codes, values);
    if (water) w.appendStep(sparseStep(g));
    w.commit(g.stats);
}

Grid readGrid(const std::string& path, uint16_t* fileMinor, size_t step) {
    const SectionedFileReader reader(path, kFormat);
    if (fileMinor) *fileMinor = reader.minor();
    // Every checksum before any content check, as the error order always was; other steps' sections are not read.
    for (const FileSection& s : reader.sections())
        if (s.kind != kStep || s.index == step) reader.data(s);
    return parseGrid(reader, step);
}

StaticDigests staticDigestsOf(const Grid& grid) { return {grid.structureHash(), staticDigests(grid)}; }

void readGridStep(const std::string& path, Grid& grid, size_t step, const StaticDigests* known) {
    const SectionedFileReader reader(path, kFormat);
    Grid g;
    Located at = parseHeader(reader, g);
    parseMeta(reader, *at.meta, g, at.cellCount, nullptr);
    parseSteps(reader, at, g);
    checkStepIndex(reader, g, step);
    if (at.cellCount != grid.cellCount() ||
        bytes::load<uint64_t>(reader.header() + off::structureHash) != (known ? known->structureHash : grid.structureHash()) ||
        g.layers.size() != grid.layers.size())
        reader.failFile("is not the grid in memory (its cells or layers differ): cannot switch its step");
    if (g.steps.empty()) {  // one step only: the grid already holds it
        grid.step = 0;
        return;
    }
    const WaterStepData data = loadStep(reader, at, g, step);
    if (stepContentHash(grid, data, known) != g.steps[step].contentHash)  // checked before `grid` changes
        reader.fail(at.steps[step]->offset, "step " + std::to_string(step) + ": content hash does not match the cells and values");
    grid.steps = g.steps;
    selectStep(grid, data, step);
}

namespace {

// readGridInfo's work on an open file; `at` receives the located sections (1.2 files: not read; older ones:
// read and validated whole, as they store no summary).
GridFileInfo infoOf(const SectionedFileReader& reader, Located& at, size_t step) {
    GridFileInfo info;
    info.fileMinor = reader.minor();
    info.fileBytes = reader.mapping()->bytes().size();
    info.blockBytes = reader.blockBytes();
    const std::byte* h = reader.header();
    info.structureHash = bytes::load<uint64_t>(h + off::structureHash);
    info.contentHash = bytes::load<uint64_t>(h + off::contentHash);
    if (reader.minor() < kSummarySince) {
        // No stored summary: the full pass, with the full validation that comes with reading everything.
        reader.verifyAll();
        const Grid g = parseGrid(reader, step);
        info.cellCount = g.cellCount();
        info.summary = summarise(g);
        info.shape = shapeOf(g);
        info.verified = true;
        Grid scratch;
        at = parseHeader(reader, scratch);
    } else {
        at = parseHeader(reader, info.shape);
        info.cellCount = at.cellCount;
        parseMeta(reader, *at.meta, info.shape, at.cellCount, &info.summary);
        parseSteps(reader, at, info.shape);
        checkStepIndex(reader, info.shape, step);
        info.shape.step = step;
        if (!info.shape.steps.empty()) info.contentHash = info.shape.steps[step].contentHash;
        addStepRanges(info.summary, info.shape, info.cellCount);
        info.shape.values.assign(info.shape.layers.size(), {});
    }
    info.bytesChecked = reader.bytesChecked();
    return info;
}

}  // namespace

GridFileInfo readGridInfo(const std::string& path, size_t step) {
    const SectionedFileReader reader(path, kFormat);
    Located at;
    return infoOf(reader, at, step);
}

GridFileInfo verifyGridFile(const std::string& path, size_t step) {
    const SectionedFileReader reader(path, kFormat);
    reader.verifyAll();
    Located at;
    Grid g = parseGrid(reader, step, &at);
    // Every other step: its section against its STEPS record and its content hash.
    for (size_t k = 0; k < g.steps.size(); ++k) {
        if (k == step) continue;
        if (stepContentHash(g, loadStep(reader, at, g, k)) != g.steps[k].contentHash)
            reader.fail(at.steps[k]->offset, "step " + std::to_string(k) + ": content hash does not match the cells and values");
    }
    GridFileInfo info;
    info.fileMinor = reader.minor();
    info.fileBytes = reader.mapping()->bytes().size();
    info.blockBytes = reader.blockBytes();
    info.structureHash = g.structureHash();
    info.contentHash = g.contentHash();
    info.cellCount = g.cellCount();
    info.summary = summarise(g);
    info.bytesChecked = reader.bytesChecked();
    info.verified = true;
    info.shape = shapeOf(g);
    info.grid = std::make_shared<const Grid>(std::move(g));
    return info;
}

}  // namespace hc

namespace hc {

struct GridRegionReader::Impl {
    Impl(const std::string& path, size_t step) : file(path, kFormat) { info = infoOf(file, at, step); }
    SectionedFileReader file;
    Located at;
    GridFileInfo info;
    uint64_t codeAt(size_t i) const { return bytes::load<uint64_t>(file.read(*at.cells, uint64_t{8} * i, 8).data()); }
    // The first cell in [lo, hi) whose code is not below `code` (hi if none).
    uint64_t lowerBound(uint64_t code, uint64_t lo, uint64_t hi) const {
        while (lo < hi) {
            const uint64_t mid = lo + (hi - lo) / 2;
            if (codeAt(mid) < code) lo = mid + 1;
            else hi = mid;
        }
        return lo;
    }
    uint64_t lowerBound(uint64_t code) const { return lowerBound(code, 0, info.cellCount); }
    // The selected step's wet entries whose cell index is below `cell` (a binary search over its STEP section).
    uint64_t wetBelow(uint64_t cell) const {
        const FileSection& sec = *at.steps[info.shape.step];
        uint64_t lo = 0, hi = info.shape.steps[info.shape.step].wetCells;
        while (lo < hi) {
            const uint64_t mid = lo + (hi - lo) / 2;
            if (bytes::load<uint32_t>(file.read(sec, 4 * mid, 4).data()) < cell) lo = mid + 1;
            else hi = mid;
        }
        return lo;
    }
};

GridRegionReader::GridRegionReader(const std::string& path, size_t step) : impl_(std::make_unique<Impl>(path, step)) {}
GridRegionReader::~GridRegionReader() = default;
const std::string& GridRegionReader::path() const { return impl_->file.path(); }
const GridFileInfo& GridRegionReader::info() const { return impl_->info; }
uint64_t GridRegionReader::bytesChecked() const { return impl_->file.bytesChecked(); }
void GridRegionReader::releasePages() const { impl_->file.releasePages(); }

std::optional<Grid::Square> GridRegionReader::cellSquareAt(double xLocal, double yLocal) const {
    const Grid& shape = impl_->info.shape;
    const std::optional<uint64_t> key = shape.finestKeyAt(xLocal, yLocal);
    if (!key) return std::nullopt;
    // The last cell whose corner key is <= key is the only one that can contain it.
    const uint64_t after = impl_->lowerBound(makeCellCode(*key + 1, 0));
    if (after == 0) return std::nullopt;
    const uint64_t code = impl_->codeAt(after - 1);
    const int level = codeLevel(code);
    if (level > shape.rootLevel || *key - codeKey(code) >= mortonSpan(level)) return std::nullopt;
    const uint64_t ix = mortonX(codeKey(code)), iy = mortonY(codeKey(code)), span = uint64_t{1} << level;
    const double f = shape.finestCellM;
    return Grid::Square{double(ix) * f, double(iy) * f, double(ix + span) * f, double(iy + span) * f};
}

uint64_t GridRegionReader::cellsInNode(uint64_t key, int level) const {
    const uint64_t lo = impl_->lowerBound(makeCellCode(key, 0)), hi = impl_->lowerBound(makeCellCode(key + mortonSpan(level), 0));
    if (lo > 0) {
        // A cell coarser than the node, starting before it, may contain it.
        const uint64_t code = impl_->codeAt(lo - 1);
        if (codeKey(code) + mortonSpan(std::min(codeLevel(code), impl_->info.shape.rootLevel)) > key) return hi - lo + 1;
    }
    return hi - lo;
}

void GridRegionReader::codesInNode(uint64_t key, int level, std::vector<uint64_t>& out) const {
    const uint64_t lo = impl_->lowerBound(makeCellCode(key, 0)), hi = impl_->lowerBound(makeCellCode(key + mortonSpan(level), 0));
    for (uint64_t k = lo; k < hi; ++k) out.push_back(impl_->codeAt(k));
}

Grid GridRegionReader::region(const Grid::Square& box, std::span<const double> marginM, std::vector<std::pair<uint64_t, uint64_t>>* runsOut) const {
    const Impl& r = *impl_;
    const Grid& shape = r.info.shape;
    Grid g = shapeOf(shape);
    if (runsOut) runsOut->clear();
    if (!(box.x0 <= box.x1 && box.y0 <= box.y1)) return g;
    // A node of level L holds cells of levels <= L: it is searched with the largest margin of those levels.
    const int levels = shape.rootLevel + 1;
    std::vector<double> margin(size_t(levels), 0.0), upTo(size_t(levels), 0.0);
    for (int l = 0; l < levels; ++l) {
        margin[size_t(l)] = marginM.empty() ? 0.0 : marginM[std::min(size_t(l), marginM.size() - 1)];
        upTo[size_t(l)] = std::max(margin[size_t(l)], l > 0 ? upTo[size_t(l - 1)] : 0.0);
    }
    auto square = [&](uint64_t key, int level) {
        const uint64_t ix = mortonX(key), iy = mortonY(key), span = uint64_t{1} << level;
        return Grid::Square{double(ix) * shape.finestCellM, double(iy) * shape.finestCellM, double(ix + span) * shape.finestCellM,
                            double(iy + span) * shape.finestCellM};
    };
    auto meets = [&](const Grid::Square& q, double m) {
        if (q.x1 < box.x0 - m || q.x0 > box.x1 + m || q.y1 < box.y0 - m || q.y0 > box.y1 + m) return 0;
        if (q.x0 >= box.x0 && q.x1 <= box.x1 && q.y0 >= box.y0 && q.y1 <= box.y1) return 2;
        return 1;
    };
    std::vector<std::pair<uint64_t, uint64_t>> runs;  // [lo, hi) cell index ranges, ascending
    auto take = [&](uint64_t lo, uint64_t hi) {
        if (!runs.empty()) lo = std::max(lo, runs.back().second);  // a coarse cell over two start nodes comes once
        if (lo >= hi) return;
        if (!runs.empty() && runs.back().second == lo) runs.back().second = hi;
        else runs.push_back({lo, hi});
    };
    auto takeCell = [&](size_t i) {
        const uint64_t code = r.codeAt(i);
        const int level = codeLevel(code);
        if (level >= levels || meets(square(codeKey(code), level), margin[size_t(level)]) != 0) take(i, i + 1);  // bad level: validate() names it
    };
    // The walk starts at the few nodes that cover the box grown by the largest margin, not at the root: a binary search
    // over all cells for each child boundary of the root's descendants would check blocks all over the file (647 MB of
    // a 1.26 GB file for one point), while the start nodes' bounds lie next to the box in Morton order (a few MB).
    const double side = shape.domainSizeM(), grow = upTo[size_t(std::min(shape.maxLevel, levels - 1))];
    const double gx0 = std::max(0.0, box.x0 - grow), gy0 = std::max(0.0, box.y0 - grow);
    const double gx1 = std::min(side, box.x1 + grow), gy1 = std::min(side, box.y1 + grow);
    if (gx0 > gx1 || gy0 > gy1) return g;
    int start = 0;
    while (start < shape.rootLevel && shape.levelSizeM(start) < std::max(gx1 - gx0, gy1 - gy0)) ++start;
    const double node = shape.levelSizeM(start);
    const uint64_t last = (uint64_t{1} << (shape.rootLevel - start)) - 1;
    auto nodeIndex = [&](double v) { return std::min(last, uint64_t(std::max(0.0, std::floor(v / node)))); };
    std::vector<uint64_t> starts;  // corner keys of the start nodes (at most 2 x 2)
    for (uint64_t iy = nodeIndex(gy0); iy <= nodeIndex(gy1); ++iy)
        for (uint64_t ix = nodeIndex(gx0); ix <= nodeIndex(gx1); ++ix)
            starts.push_back(mortonEncode(uint32_t(ix << start), uint32_t(iy << start)));
    std::sort(starts.begin(), starts.end());
    for (const uint64_t key : starts) {
        const uint64_t lo = r.lowerBound(makeCellCode(key, 0)), hi = r.lowerBound(makeCellCode(key + mortonSpan(start), 0));
        if (lo > 0) {
            // A cell before the node may contain it (a cell coarser than the node).
            const uint64_t code = r.codeAt(lo - 1);
            if (codeKey(code) + mortonSpan(std::min(codeLevel(code), shape.rootLevel)) > key) takeCell(lo - 1);
        }
        detail::walkQuadtree(
            key, start, lo, hi, [&](size_t i) { return r.codeAt(i); },
            [&](size_t a, size_t b, uint64_t code) { return size_t(r.lowerBound(code, a, b)); },
            [&](uint64_t k, int level) { return meets(square(k, level), upTo[size_t(level)]); }, take, takeCell);
    }
    if (runsOut) *runsOut = runs;
    uint64_t total = 0;
    for (auto [lo, hi] : runs) total += hi - lo;
    g.codes.reserve(total);
    for (auto& v : g.values) v.reserve(total);
    for (auto [lo, hi] : runs) {
        const auto codes = r.file.read(*r.at.cells, 8 * lo, 8 * (hi - lo));
        const size_t at = g.codes.size();
        g.codes.resize(at + (hi - lo));
        std::memcpy(g.codes.data() + at, codes.data(), codes.size());
        for (size_t l = 0; l < r.at.layers.size(); ++l) {
            const auto values = r.file.read(*r.at.layers[l], 4 * lo, 4 * (hi - lo));
            g.values[l].resize(at + (hi - lo));
            std::memcpy(g.values[l].data() + at, values.data(), values.size());
        }
        if (shape.steps.empty()) continue;
        // The step layers: 0 where dry, the stored values at the run's wet cells.
        const size_t first = shape.firstStepLayer(), L = shape.layers.size() - first;
        for (size_t l = first; l < shape.layers.size(); ++l) g.values[l].resize(at + (hi - lo), 0.0f);
        const FileSection& sec = *r.at.steps[shape.step];
        const uint64_t w = shape.steps[shape.step].wetCells, j0 = r.wetBelow(lo), j1 = r.wetBelow(hi);
        if (j1 == j0) continue;
        const auto idx = r.file.read(sec, 4 * j0, 4 * (j1 - j0));
        for (size_t l = 0; l < L; ++l) {
            const auto vals = r.file.read(sec, 4 * w * (1 + l) + 4 * j0, 4 * (j1 - j0));
            for (uint64_t j = 0; j < j1 - j0; ++j) {
                const uint32_t cell = bytes::load<uint32_t>(idx.data() + 4 * j);
                const float v = bytes::load<float>(vals.data() + 4 * j);
                if (cell < lo || cell >= hi || (j > 0 && cell <= bytes::load<uint32_t>(idx.data() + 4 * (j - 1))) || !std::isfinite(v) ||
                    (l == 0 && !(v > 0)))
                    r.file.fail(sec.offset + 4 * (j0 + j), "step " + std::to_string(shape.step) + ": wet cell " + std::to_string(j0 + j) +
                                                               " is out of order or its value is not finite (water_depth > 0)");
                g.values[first + l][at + (cell - lo)] = v;
            }
        }
    }
    if (std::string problem = g.validate(); !problem.empty()) r.file.fail(r.at.cells->offset, "invalid grid: " + problem);
    return g;
}

}  // namespace hc
