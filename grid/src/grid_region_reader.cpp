// grid/src/grid_region_reader.cpp: GridRegionReader, a .hcg file read in regions without holding its cells: binary
// searches over the file's codes (cellSquareAt, cellsInNode, codesInNode) and the cells of a box grown by margins
// (region: the quadtree walk of quadtree_walk.h over the file). The file's summary comes from grid_file.cpp (infoOf).
#include "heightcast/grid/grid_file.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>
#include <optional>
#include <vector>

#include "grid_file_internal.h"
#include "heightcast/core/bytes.h"
#include "heightcast/core/sectioned_file.h"
#include "quadtree_walk.h"

namespace hc {
using namespace detail;

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
            if (codeAt(mid) < code)
                lo = mid + 1;
            else
                hi = mid;
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
            if (bytes::load<uint32_t>(file.read(sec, 4 * mid, 4).data()) < cell)
                lo = mid + 1;
            else
                hi = mid;
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
    const uint64_t lo = impl_->lowerBound(makeCellCode(key, 0)),
                   hi = impl_->lowerBound(makeCellCode(key + mortonSpan(level), 0));
    if (lo > 0) {
        // A cell coarser than the node, starting before it, may contain it.
        const uint64_t code = impl_->codeAt(lo - 1);
        if (codeKey(code) + mortonSpan(std::min(codeLevel(code), impl_->info.shape.rootLevel)) > key)
            return hi - lo + 1;
    }
    return hi - lo;
}

void GridRegionReader::codesInNode(uint64_t key, int level, std::vector<uint64_t>& out) const {
    const uint64_t lo = impl_->lowerBound(makeCellCode(key, 0)),
                   hi = impl_->lowerBound(makeCellCode(key + mortonSpan(level), 0));
    for (uint64_t k = lo; k < hi; ++k) out.push_back(impl_->codeAt(k));
}

Grid GridRegionReader::region(const Grid::Square& box, std::span<const double> marginM,
                              std::vector<std::pair<uint64_t, uint64_t>>* runsOut) const {
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
        return Grid::Square{double(ix) * shape.finestCellM, double(iy) * shape.finestCellM,
                            double(ix + span) * shape.finestCellM, double(iy + span) * shape.finestCellM};
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
        if (!runs.empty() && runs.back().second == lo)
            runs.back().second = hi;
        else
            runs.push_back({lo, hi});
    };
    auto takeCell = [&](size_t i) {
        const uint64_t code = r.codeAt(i);
        const int level = codeLevel(code);
        if (level >= levels || meets(square(codeKey(code), level), margin[size_t(level)]) != 0)
            take(i, i + 1);  // bad level: validate() names it
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
        const uint64_t lo = r.lowerBound(makeCellCode(key, 0)),
                       hi = r.lowerBound(makeCellCode(key + mortonSpan(start), 0));
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
                if (cell < lo || cell >= hi || (j > 0 && cell <= bytes::load<uint32_t>(idx.data() + 4 * (j - 1))) ||
                    !std::isfinite(v) || (l == 0 && !(v > 0)))
                    r.file.fail(sec.offset + 4 * (j0 + j),
                                "step " + std::to_string(shape.step) + ": wet cell " + std::to_string(j0 + j) +
                                    " is out of order or its value is not finite (water_depth > 0)");
                g.values[first + l][at + (cell - lo)] = v;
            }
        }
    }
    if (std::string problem = g.validate(); !problem.empty())
        r.file.fail(r.at.cells->offset, "invalid grid: " + problem);
    return g;
}

}  // namespace hc
