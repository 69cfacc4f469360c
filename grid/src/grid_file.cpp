// grid/src/grid_file.cpp: reading the .hcg format (docs/formats/hcg.md): the header, META, the STEPS table and a
// step's section parsed and checked, and the whole grid, one step of it, or the file's summary read (readGrid,
// readGridStep, readGridInfo, verifyGridFile). Writing is grid_file_write.cpp's, reading regions of a file that is not
// held grid_region_reader.cpp's; what they share is in grid_file_internal.h.
#include "heightcast/grid/grid_file.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <map>
#include <memory>
#include <optional>
#include <vector>

#include "grid_file_internal.h"
#include "heightcast/core/bytes.h"
#include "heightcast/core/checksum.h"
#include "heightcast/core/error.h"
#include "heightcast/core/sectioned_file.h"

namespace hc {
using namespace detail;
namespace {

// Parses META (checked on this first touch); for a file of a minor with a summary, fills `summary` and
// checks it against the header: counts per level add up to the cell count, only at levels in range, a
// bounding box inside the domain, a finite min <= max per layer. Whether it matches the cells is left to
// checkSummary() (a full pass).
void parseMeta(const SectionedFileReader& file, const FileSection& s, Grid& g, uint64_t cellCount,
               GridSummary* summary) {
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
            fail(s.offset,
                 "META layer " + std::to_string(l) + " is water_depth: from format 1.3 on water is stored as steps");
    }
    if (file.minor() >= kStepsSince && kv.count("step_layers")) {
        size_t n = 0;
        number("step_layers", n);
        if (n < 1 || n > 255 - staticLayers)
            fail(s.offset,
                 "META step_layers is " + std::to_string(n) + ", not 1.." + std::to_string(255 - staticLayers));
        for (size_t l = 0; l < n; ++l)
            g.layers.push_back({need("step_layer." + std::to_string(l) + ".name"),
                                need("step_layer." + std::to_string(l) + ".units")});
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
            if (c < e && *c == ' ')
                ++c;
            else if (c < e)
                break;
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
            fail(s.offset, "META summary.cells_per_level does not fit the header's " + std::to_string(cellCount) +
                               " cells and levels");
        sum += n;
    }
    if (sum != cellCount)
        fail(s.offset, "META summary.cells_per_level adds up to " + std::to_string(sum) +
                           " cells, the header declares " + std::to_string(cellCount));
    const auto b = numbers("summary.bounds_finest", 4);
    const uint64_t side = uint64_t{1} << g.rootLevel;
    if (b[0] > b[2] || b[1] > b[3] || b[2] > side || b[3] > side || (cellCount > 0 && (b[0] == b[2] || b[1] == b[3])))
        fail(s.offset,
             "META summary.bounds_finest is not a box in the domain of " + std::to_string(side) + " finest cells");
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

GridSummary summarise(const Grid& g) {
    SummaryBuilder b(g.maxLevel, g.layers.size());
    std::vector<std::span<const float>> values(g.values.begin(), g.values.end());
    b.add(g.codes, values);
    return b.summary();
}

bool operator==(const GridSummary& a, const GridSummary& b) {
    return a.cellsPerLevel == b.cellsPerLevel && a.boundsFinest == b.boundsFinest && a.layerMin == b.layerMin &&
           a.layerMax == b.layerMax;
}

// The header's fields into `g` (no cells) and the sections located and sized: no section data read.
Located parseHeader(const SectionedFileReader& file, Grid& g) {
    const std::byte* h = file.header();
    auto fail = [&](uint64_t at, const std::string& what) { file.fail(at, what); };
    const size_t reservedFrom = file.minor() >= kRotationSince ? off::rotation + 8 : off::reserved;
    for (size_t i = reservedFrom; i < off::reservedEnd; ++i)
        if (h[i] != std::byte{0}) fail(i, "reserved header byte is not zero");
    if (file.minor() >= kRotationSince) {
        g.rotationDeg = bytes::load<double>(h + off::rotation);
        if (!(g.rotationDeg > -180 && g.rotationDeg <= 180))
            fail(off::rotation, "rotation is not a number of degrees in (-180, 180]");
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
    if (!(g.finestCellM > 0) || !std::isfinite(g.finestCellM))
        fail(off::finestCell, "finest cell size is not a positive number");
    if (g.rootLevel > kMaxRootLevel)
        fail(off::rootLevel, "root level " + std::to_string(g.rootLevel) + " exceeds " + std::to_string(kMaxRootLevel));
    if (g.minLevel > g.maxLevel || g.maxLevel > g.rootLevel)
        fail(off::minLevel, "level range is inconsistent with the root level");
    if (layerCount < 1) fail(off::layerCount, "no layers (elevation is required)");
    // Every cell takes 8 bytes of CELLS and 4 of each LAYER: a count the file cannot hold is refused here,
    // before any size is computed from it (issue 11: 2^62 cells times 8 wrapped to 0 and passed the checks).
    const uint64_t fileBytes = file.mapping()->bytes().size();
    if (cellCount > fileBytes / (8 + 4 * uint64_t{layerCount}))
        fail(off::cellCount, "header declares " + std::to_string(cellCount) + " cells of " +
                                 std::to_string(8 + 4 * layerCount) + " bytes each, more than the " +
                                 std::to_string(fileBytes) + "-byte file holds");

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
            if (e.index >= layerCount || layerSec[e.index])
                fail(at + 4, "LAYER section index " + std::to_string(e.index) + " is out of range or repeated");
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
        if (at.stepsTable)
            fail(at.stepsTable->offset, "STEPS section in a grid without step layers (META step_layers)");
        if (!at.steps.empty()) file.failFile("STEP section in a grid without step layers (META step_layers)");
        return;
    }
    if (file.minor() < kStepsSince) return;  // a 1.2 water LAYER: one step at time 0, no table
    if (!at.stepsTable) file.failFile("META declares step layers but there is no STEPS section");
    const FileSection& t = *at.stepsTable;
    const uint64_t record = 24 + 8 * uint64_t(L);
    if (t.bytes == 0 || t.bytes % record != 0)
        fail(t.offset, "STEPS section holds " + std::to_string(t.bytes) + " bytes, not a positive multiple of " +
                           std::to_string(record));
    const uint64_t count = t.bytes / record;
    if (at.cellCount > UINT32_MAX) fail(t.offset, "a grid with water steps holds at most 2^32 - 1 cells");
    if (at.steps.size() != count)
        file.failFile("STEPS lists " + std::to_string(count) + " steps, the file has " +
                      std::to_string(at.steps.size()) + " STEP sections");
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
        if (k > 0 && !(s.timeS > g.steps.back().timeS))
            fail(where, name + ": time " + fmtDouble(s.timeS) + " s does not follow " +
                            fmtDouble(g.steps.back().timeS) + " s");
        if (s.wetCells > at.cellCount)
            fail(where + 8, name + ": " + std::to_string(s.wetCells) + " wet cells of " + std::to_string(at.cellCount));
        if (!at.steps[k]) file.failFile("no STEP section for " + name);
        const FileSection& sec = *at.steps[k];
        if (sec.bytes % (4 * (1 + L)) != 0 || sec.bytes / (4 * (1 + L)) != s.wetCells)
            fail(sec.offset, "STEP section of " + name + " holds " + std::to_string(sec.bytes) + " bytes, expected " +
                                 std::to_string(4 * (1 + L)) + " for each of " + std::to_string(s.wetCells) +
                                 " wet cells");
        for (size_t l = 0; l < L; ++l) {
            const float lo = bytes::load<float>(r + 24 + 8 * l), hi = bytes::load<float>(r + 28 + 8 * l);
            const bool ok = s.wetCells == 0 ? (lo == 0 && hi == 0)
                                            : (std::isfinite(lo) && std::isfinite(hi) && lo <= hi && (l > 0 || lo > 0));
            if (!ok)
                fail(where + 24 + 8 * l, name + ": range of " + g.layers[firstStep + l].name +
                                             " is not finite min <= max (min > 0 for water_depth)");
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
    if (w >
        0) {  // a dry step (none wet: a simulation's first time) has empty vectors, whose data() memcpy must not see
        std::memcpy(out.wet.data(), d, 4 * w);
        for (size_t l = 0; l < L; ++l) std::memcpy(out.values[l].data(), d + 4 * w * (1 + l), 4 * w);
    }
    const std::string name = "step " + std::to_string(k);
    for (uint64_t j = 0; j < w; ++j)
        if (out.wet[j] >= at.cellCount || (j > 0 && out.wet[j] <= out.wet[j - 1]))
            file.fail(sec.offset + 4 * j, name + ": wet cell index " + std::to_string(out.wet[j]) +
                                              " is not ascending below the cell count");
    for (size_t l = 0; l < L; ++l) {
        float lo = HUGE_VALF, hi = -HUGE_VALF;
        for (uint64_t j = 0; j < w; ++j) {
            const float v = out.values[l][j];
            if (!std::isfinite(v) || (l == 0 && !(v > 0)))
                file.fail(sec.offset + 4 * w * (1 + l) + 4 * j, name + ": " + g.layers[g.firstStepLayer() + l].name +
                                                                    " value is not finite" +
                                                                    (l == 0 ? " and > 0" : ""));
            lo = std::min(lo, v);
            hi = std::max(hi, v);
        }
        if (w > 0 && (lo != info.layerMin[l] || hi != info.layerMax[l]))
            file.fail(sec.offset,
                      name + ": the range of " + g.layers[g.firstStepLayer() + l].name + " does not match STEPS");
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
        parts.emplace_back(g.layers[g.firstStepLayer() + l].name,
                           sparseLayerDigest(g.cellCount(), data.wet, data.values[l]));
    return combineContentHash(known ? known->structureHash : g.structureHash(), parts);
}

// Fails unless `step` is one of the file's steps (a grid without `steps` has only step 0).
void checkStepIndex(const SectionedFileReader& file, const Grid& g, size_t step) {
    const size_t n = g.steps.empty() ? 1 : g.steps.size();
    if (step >= n)
        file.failFile("has no step " + std::to_string(step) + ": it holds " + std::to_string(g.stepCount()) +
                      " water step" + (g.stepCount() == 1 ? "" : "s") +
                      (g.stepCount() ? " (0.." + std::to_string(g.stepCount() - 1) + ")" : ""));
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
    if (g.structureHash() != bytes::load<uint64_t>(h + off::structureHash))
        fail(off::structureHash, "structure hash does not match the cells");
    if (g.steps.empty()) {
        if (g.contentHash() != bytes::load<uint64_t>(h + off::contentHash))
            fail(off::contentHash, "content hash does not match the cells and values");
    } else {
        if (g.contentHash() != g.steps[step].contentHash)
            fail(at.stepsTable->offset,
                 "step " + std::to_string(step) + ": content hash does not match the cells and values");
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

Grid detail::shapeOf(const Grid& g) {
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

uint64_t detail::scenarioHash(uint64_t staticContentHash, const std::vector<StepInfo>& steps) {
    Hash64 h(0x6863737465707321ull);
    h.updateValue(staticContentHash);
    for (const StepInfo& s : steps) {
        h.updateValue(s.timeS);
        h.updateValue(s.contentHash);
    }
    return h.digest();
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
        bytes::load<uint64_t>(reader.header() + off::structureHash) !=
            (known ? known->structureHash : grid.structureHash()) ||
        g.layers.size() != grid.layers.size())
        reader.failFile("is not the grid in memory (its cells or layers differ): cannot switch its step");
    if (g.steps.empty()) {  // one step only: the grid already holds it
        grid.step = 0;
        return;
    }
    const WaterStepData data = loadStep(reader, at, g, step);
    if (stepContentHash(grid, data, known) != g.steps[step].contentHash)  // checked before `grid` changes
        reader.fail(at.steps[step]->offset,
                    "step " + std::to_string(step) + ": content hash does not match the cells and values");
    grid.steps = g.steps;
    selectStep(grid, data, step);
}

GridFileInfo detail::infoOf(const SectionedFileReader& reader, Located& at, size_t step) {
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
            reader.fail(at.steps[k]->offset,
                        "step " + std::to_string(k) + ": content hash does not match the cells and values");
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
