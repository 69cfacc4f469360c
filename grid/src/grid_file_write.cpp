// grid/src/grid_file_write.cpp: writing the .hcg format (docs/formats/hcg.md): GridFileWriter (a grid's cells
// streamed in, its water steps, then META, STEPS and the header), GridFilePart (one rank's run of cells, written in
// place and handed on: the order check, hashes and summary go on across ranks) and writeGrid. The container's
// parameters and the summary are in grid_file_internal.h; reading is grid_file.cpp's.
#include "heightcast/grid/grid_file.h"

#include <algorithm>
#include <cmath>
#include <cstring>
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
    if (!s.sourceKind.empty())
        kv.emplace_back("ingest.source_kind", s.sourceKind);  // absent for rasters (older files too)
    if (!s.sourceFormat.empty()) kv.emplace_back("ingest.source_format", s.sourceFormat);  // flood model results only
    if (s.latticeResidualM >= 0) kv.emplace_back("ingest.lattice_residual_m", fmtDouble(s.latticeResidualM));
    kv.emplace_back("ingest.source_width", std::to_string(s.sourceWidth));
    kv.emplace_back("ingest.source_height", std::to_string(s.sourceHeight));
    kv.emplace_back("ingest.valid_pixels", std::to_string(s.validPixels));
    kv.emplace_back("ingest.tolerance_m", fmtDouble(s.toleranceM));
    kv.emplace_back("ingest.max_dev_m", fmtDouble(s.maxDevM));
    kv.emplace_back("ingest.rms_dev_m", fmtDouble(s.rmsDevM));
    // No wall time (ingest.seconds, written up to this change, still read): a grid's bytes depend on its inputs only,
    // so a run under mpirun, or a rerun, gives the same file (docs/design.md section 7).
    std::vector<std::byte> out;
    for (auto& [k, v] : kv) {
        appendString(out, k);
        appendString(out, v);
    }
    return out;
}

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

CellStreamCheck::State resumeStream(std::span<const std::byte> bytes, GridHasher& hasher, size_t layers,
                                    const std::string& what) {
    const std::vector<uint64_t> w = words(bytes, what + ": the cells' running state from the ranks before");
    if (w.size() != 4 + 4 * (1 + layers) || w[0] != kStreamStateTag || w[1] != layers)
        throw Error(what + ": the cells' running state from the ranks before is not one of this grid");
    std::vector<Hash64::State> h(1 + layers);
    for (size_t k = 0; k < h.size(); ++k) h[k] = {w[4 + 4 * k], w[5 + 4 * k], w[6 + 4 * k], w[7 + 4 * k]};
    hasher.resume(h);
    return {w[2], w[3]};
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
            throw Error("cell " + std::to_string(i) + " has water_depth " + fmtFloat(depth[i]) +
                        ": depths are >= 0 (0 = dry)");
        for (size_t l = first + 1; l < g.layers.size(); ++l)
            if (g.values[l][i] != 0)
                throw Error("cell " + std::to_string(i) + " is dry (water_depth " + fmtFloat(depth[i]) +
                            ") but its step layer " + g.layers[l].name + " is " + fmtFloat(g.values[l][i]) +
                            ": step layers (water_depth and the layers after it) are stored on wet cells "
                            "only; put a layer that does not change with the water before water_depth");
    }
    return out;
}

struct GridFileWriter::Impl {
    Impl(const std::string& path, const Grid& gridShape, uint64_t cells, std::vector<FileSection> layout,
         size_t stepsAnnounced)
        : out(path, kFormat, std::move(layout), 1 + (stepsAnnounced ? stepsAnnounced + 1 : 0)),
          shape(gridShape),
          staticShape(staticShapeOf(gridShape)),
          cellCount(cells),
          stepCount(stepsAnnounced),
          check(staticShape),
          hasher(staticShape, cells),
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
    for (size_t l = 0; l < shape.firstStepLayer(); ++l)
        layout.push_back({kLayer, static_cast<uint32_t>(l), 0, cellCount * 4, 0});
    impl_ = std::make_unique<Impl>(path, bare, cellCount, std::move(layout), stepCount);
}

GridFileWriter::~GridFileWriter() = default;

namespace {

// The shape of a batch of cells: a value array per static layer, each as long as the codes.
void checkBatchShape(const std::string& path, std::span<const uint64_t> codes,
                     const std::vector<std::span<const float>>& layerValues, size_t layers) {
    if (layerValues.size() != layers)
        throw Error(path + ": " + std::to_string(layerValues.size()) + " value arrays for " + std::to_string(layers) +
                    " static layers");
    for (const auto& v : layerValues)
        if (v.size() != codes.size()) throw Error(path + ": layer values and cells differ in number");
}

// Every cell's rules (CellStreamCheck), then the cells into the summary.
void checkCells(const std::string& path, std::span<const uint64_t> codes,
                const std::vector<std::span<const float>>& layerValues, CellStreamCheck& check,
                SummaryBuilder& summary) {
    std::string problem = check.nextBatch(codes, layerValues);
    if (!problem.empty()) throw Error(path + ": refusing to write an invalid grid: " + problem);
    summary.add(codes, layerValues);
}

void hashCells(std::span<const uint64_t> codes, const std::vector<std::span<const float>>& layerValues,
               GridHasher& hasher) {
    hasher.addCodes(codes);
    for (size_t l = 0; l < layerValues.size(); ++l) hasher.addValues(l, layerValues[l]);
}

}  // namespace

void GridFileWriter::append(std::span<const uint64_t> codes, const std::vector<std::span<const float>>& layerValues) {
    Impl& w = *impl_;
    const size_t layers = w.staticShape.layers.size();
    const std::string& path = w.out.path();
    checkBatchShape(path, codes, layerValues, layers);
    if (codes.size() > w.cellCount - w.written)
        throw Error(path + ": more cells than the " + std::to_string(w.cellCount) + " announced");
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
// then the state after its cells (saveStream), its cells' summary (SummaryBuilder::save), the pieces (FilePiece, 32
// bytes each).
void GridFileWriter::addPart(std::span<const std::byte> part) {
    Impl& w = *impl_;
    const std::string& path = w.out.path();
    if (part.size() < 40)
        throw Error(path + ": a rank's part of " + std::to_string(part.size()) + " bytes is cut short");
    uint64_t head[5];
    std::memcpy(head, part.data(), sizeof head);
    const auto [first, cells, stateBytes, summaryBytes, pieces] = head;
    if (stateBytes > part.size() - 40 || summaryBytes > part.size() - 40 - stateBytes ||
        pieces > (part.size() - 40 - stateBytes - summaryBytes) / sizeof(FilePiece) ||
        40 + stateBytes + summaryBytes + pieces * sizeof(FilePiece) != part.size())
        throw Error(path + ": a rank's part is malformed");
    if (first != w.written || cells > w.cellCount - w.written)
        throw Error(path + ": a rank's part holds cells " + std::to_string(first) + ".." +
                    std::to_string(first + cells) + " where cell " + std::to_string(w.written) + " comes next of " +
                    std::to_string(w.cellCount));
    std::vector<FilePiece> table(pieces);
    if (pieces) std::memcpy(table.data(), part.data() + 40 + stateBytes + summaryBytes, pieces * sizeof(FilePiece));
    w.out.addPieces(table);
    const CellStreamCheck::State after =
        resumeStream(part.subspan(40, stateBytes), w.hasher, w.staticShape.layers.size(), path);
    w.check.resume(after);
    SummaryBuilder theirs(w.staticShape.maxLevel, w.staticShape.layers.size());
    const std::vector<uint64_t> sw = words(part.subspan(40 + stateBytes, summaryBytes), path + ": a rank's summary");
    if (theirs.resume(sw, 0) != sw.size() || sw.empty()) throw Error(path + ": a rank's summary is malformed");
    w.summary.merge(theirs);
    w.written += cells;
    if (after.count != w.written)
        throw Error(path + ": a rank's part ends at cell " + std::to_string(after.count) + ", not at the " +
                    std::to_string(w.written) + " written");
}

struct GridFilePart::Impl {
    Impl(FilePlacement placement, const Grid& gridShape, uint64_t cells, uint64_t firstCell)
        : out(std::move(placement)),
          staticShape(staticShapeOf(gridShape)),
          cellCount(cells),
          first(firstCell),
          check(staticShape),
          hasher(staticShape, cells),
          summary(staticShape.maxLevel, staticShape.layers.size()) {
        check.resume({0, first});  // cells are numbered as in the file; the first one's order is checked by resume()
    }
    SectionedFilePart out;
    Grid staticShape;
    uint64_t cellCount, first;
    CellStreamCheck check;  // this run's cells among themselves, as they are appended
    GridHasher hasher;
    SummaryBuilder summary;
    uint64_t written = 0, followed = 0;            // cells of this run written, and hashed
    uint64_t firstKey = 0;                         // of the run's first cell
    std::optional<CellStreamCheck::State> before;  // where the runs before leave the order check (resume)
    std::string path;

    // The run's first cell after the cells before it (CellStreamCheck's rule across the seam).
    void checkSeam() const {
        if (before && written > 0 && first > 0 && firstKey < before->nextFree)
            throw Error(path + ": refusing to write an invalid grid: cell " + std::to_string(first) +
                        " overlaps or precedes cell " + std::to_string(first - 1));
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
    if (codes.size() > w.cellCount - at)
        throw Error(w.path + ": more cells than the " + std::to_string(w.cellCount) + " announced");
    if (codes.empty()) return;
    // Checked and summarised here, each rank its own run at once; only the seam and the hashes wait for the ranks
    // before.
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
        throw Error(w.path + ": the ranks before this one wrote " + std::to_string(before.count) +
                    " cells, but its own begin at cell " + std::to_string(w.first));
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
        throw Error(w.path + ": a rank's state asked for with " + std::to_string(w.followed) + " of its " +
                    std::to_string(w.written) + " cells hashed");
    // The order check goes on from this run's last cell, or from the runs before where this one is empty.
    const CellStreamCheck::State after{w.written > 0 ? w.check.save().nextFree : w.before->nextFree,
                                       w.first + w.written};
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
    if (!pieces.empty())
        std::memcpy(out.data() + 40 + s.size() + summaryBytes, pieces.data(), pieces.size() * sizeof(FilePiece));
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
    if (step.values.size() != L)
        throw Error(name + ": " + std::to_string(step.values.size()) + " value arrays for " + std::to_string(L) +
                    " step layers");
    for (const auto& v : step.values)
        if (v.size() != step.wet.size()) throw Error(name + ": step values and wet cells differ in number");
    if (!std::isfinite(step.timeS)) throw Error(name + ": time is not finite");
    if (k > 0 && !(step.timeS > w.steps.back().timeS))
        throw Error(name + ": times must increase strictly, " + fmtDouble(step.timeS) + " s follows " +
                    fmtDouble(w.steps.back().timeS) + " s");
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
                throw Error(name + ": " + w.shape.layers[first + l].name + " values must be finite" +
                            (l == 0 ? " and > 0 (only wet cells are stored)" : ""));
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
        throw Error(w.out.path() + ": " + std::to_string(w.written) + " cells written of " +
                    std::to_string(w.cellCount) + " announced");
    if (w.steps.size() != w.stepCount)
        throw Error(w.out.path() + ": " + std::to_string(w.steps.size()) + " water steps written of " +
                    std::to_string(w.stepCount) + " announced");
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

}  // namespace hc
