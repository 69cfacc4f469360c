// grid/src/grid_file_internal.h: what the .hcg reader (grid_file.cpp), writer (grid_file_write.cpp) and region
// reader (grid_region_reader.cpp) share: the container's parameters and the grid's own header fields, number
// formatting for META and messages, the summary of cells (SummaryBuilder), the located sections (Located), and the few
// functions more than one of them calls. Private to grid/src/.
#pragma once

#include <algorithm>
#include <array>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "heightcast/core/sectioned_file.h"
#include "heightcast/grid/grid.h"
#include "heightcast/grid/grid_file.h"

namespace hc::detail {

enum SectionKind : uint32_t { kMeta = 1, kCells = 2, kLayer = 3, kSteps = 4, kStep = 5 };

const FileFormat kFormat{
    {'\x89', 'H', 'C', 'G', 'R', 'I', 'D', '\n'}, kGridFileMajor,           kGridFileMinor, "heightcast grid (.hcg)",
    {kMeta, kCells, kLayer, kSteps, kStep},       /*blockChecksumsSince=*/2};
constexpr uint16_t kSummarySince = 2;  // the minor from which META holds the summary (GridSummary)
constexpr uint16_t kStepsSince = 3;    // the minor from which water is stored as steps (STEP, STEPS)

// The grid's own header fields (grid_file.h); pinned by the golden-bytes test.
namespace off {
constexpr size_t cellCount = 24, originX = 32, originY = 40, finestCell = 48, rootLevel = 56, minLevel = 57,
                 maxLevel = 58, layerCount = 59, contentHash = 64, structureHash = 72, rotation = 80, reserved = 80,
                 reservedEnd = 120;
}
constexpr uint16_t kRotationSince = 3;  // from 1.3 on bytes 80..87 hold the rotation (f64 degrees); before, zero
static_assert(kGridHeaderBytes == kFileHeaderBytes);

inline std::string fmtDouble(double v) {
    char buf[32];
    auto r = std::to_chars(buf, buf + sizeof buf, v);  // shortest exact round trip
    return std::string(buf, r.ptr);
}

inline std::string fmtFloat(float v) {
    char buf[32];
    auto r = std::to_chars(buf, buf + sizeof buf, v);  // shortest decimal that reads back as this float
    return std::string(buf, r.ptr);
}

// The summary of cells in memory (what the writer computes as they stream past).
class SummaryBuilder {
public:
    SummaryBuilder(int maxLevel, size_t layers) : layers_(layers) {
        s_.cellsPerLevel.assign(static_cast<size_t>(maxLevel) + 1, 0);
    }
    // Cells already checked (CellStreamCheck or Grid::validate): levels in range, values finite.
    void add(std::span<const uint64_t> codes, const std::vector<std::span<const float>>& values) {
        if (codes.empty()) return;
        if (first_) {
            const uint64_t key = codeKey(codes[0]), x = mortonX(key), y = mortonY(key);
            s_.boundsFinest = {x, y, x, y};
            s_.layerMin.assign(layers_, HUGE_VALF);
            s_.layerMax.assign(layers_, -HUGE_VALF);
            first_ = false;
        }
        // In locals, so the loops keep them in registers.
        // The bounds in Morton space: a key's even bits are its x spread out, and spreading keeps the order, so the
        // least x is that of the least even bits; a cell's last finest key (its key with the level's span - 1 set)
        // holds its last x and y. Four min/max a cell and no decoding, in a loop of their own so that it vectorises;
        // the levels counted in four interleaved tallies, so that cells of one level do not wait on each other's
        // increments.
        constexpr uint64_t kEven = 0x5555555555555555ull, kOdd = kEven << 1;
        std::array<uint64_t, 8> loX, loY, hiX{}, hiY{};
        loX.fill(~uint64_t{0}), loY.fill(~uint64_t{0});
        auto bound = [&](size_t k, uint64_t c) {
            const uint64_t key = codeKey(c), last = key | (mortonSpan(codeLevel(c)) - 1);
            loX[k] = std::min(loX[k], key & kEven), loY[k] = std::min(loY[k], key & kOdd);
            hiX[k] = std::max(hiX[k], last & kEven), hiY[k] = std::max(hiY[k], last & kOdd);
        };
        size_t i = 0;
        for (; i + 8 <= codes.size(); i += 8)
            for (size_t k = 0; k < 8; ++k) bound(k, codes[i + k]);
        for (; i < codes.size(); ++i) bound(0, codes[i]);
        std::array<std::array<uint64_t, 64>, 4> tally{};
        for (i = 0; i < codes.size(); ++i) ++tally[i & 3][size_t(codeLevel(codes[i]))];
        for (size_t l = 0; l < s_.cellsPerLevel.size(); ++l)
            s_.cellsPerLevel[l] += tally[0][l] + tally[1][l] + tally[2][l] + tally[3][l];
        auto& b = s_.boundsFinest;
        const uint64_t lx = *std::min_element(loX.begin(), loX.end()), ly = *std::min_element(loY.begin(), loY.end());
        const uint64_t hx = *std::max_element(hiX.begin(), hiX.end()), hy = *std::max_element(hiY.begin(), hiY.end());
        b = {std::min<uint64_t>(b[0], mortonX(lx)), std::min<uint64_t>(b[1], mortonY(ly)),
             std::max<uint64_t>(b[2], uint64_t{mortonX(hx)} + 1), std::max<uint64_t>(b[3], uint64_t{mortonY(hy)} + 1)};
        for (size_t l = 0; l < layers_; ++l) {
            // Eight lanes: independent minima and maxima, not one chain of dependent comparisons.
            std::array<float, 8> lo, hi;
            lo.fill(s_.layerMin[l]), hi.fill(s_.layerMax[l]);
            const std::span<const float> v = values[l];
            size_t j = 0;
            for (; j + 8 <= v.size(); j += 8)
                for (size_t k = 0; k < 8; ++k) lo[k] = std::min(lo[k], v[j + k]), hi[k] = std::max(hi[k], v[j + k]);
            for (; j < v.size(); ++j) lo[0] = std::min(lo[0], v[j]), hi[0] = std::max(hi[0], v[j]);
            s_.layerMin[l] = *std::min_element(lo.begin(), lo.end());
            s_.layerMax[l] = *std::max_element(hi.begin(), hi.end());
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

struct Located {
    uint64_t cellCount = 0;
    const FileSection* meta = nullptr;
    const FileSection* cells = nullptr;
    std::vector<const FileSection*> layers;   // the static LAYER sections
    const FileSection* stepsTable = nullptr;  // STEPS (1.3 files with water)
    std::vector<const FileSection*> steps;    // STEP sections by step index (sized by parseSteps)
};

// A grid's geometry, CRS, layers and statistics, never its cells (grid_file.cpp).
Grid shapeOf(const Grid& g);

// The header's content hash of a file with steps: the static grid's content hash and every step's (time, hash)
// (grid_file.cpp).
uint64_t scenarioHash(uint64_t staticContentHash, const std::vector<StepInfo>& steps);

// readGridInfo's work on an open file; `at` receives the located sections (1.2 files: not read; older ones:
// read and validated whole, as they store no summary) (grid_file.cpp).
GridFileInfo infoOf(const SectionedFileReader& reader, Located& at, size_t step);

}  // namespace hc::detail
