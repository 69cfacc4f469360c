#include "heightcast/grid/grid.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <sstream>

#include "heightcast/core/checksum.h"
#include "heightcast/core/error.h"
#include "quadtree_walk.h"

namespace hc {

int Grid::findLayer(const std::string& name) const {
    for (size_t l = 0; l < layers.size(); ++l)
        if (layers[l].name == name) return static_cast<int>(l);
    return -1;
}

namespace {
// cos and sin of a rotation in degrees, exact at multiples of 90 (no 6e-17 residue at 90 degrees).
void cosSin(double deg, double& c, double& s) {
    const double q = deg / 90.0;
    if (q == std::round(q)) {
        const long k = ((long(std::round(q)) % 4) + 4) % 4;
        c = k == 0 ? 1 : k == 2 ? -1 : 0;
        s = k == 1 ? 1 : k == 3 ? -1 : 0;
        return;
    }
    c = std::cos(deg * M_PI / 180.0), s = std::sin(deg * M_PI / 180.0);
}
}  // namespace

void Grid::worldToLocal(double xWorld, double yWorld, double& xLocal, double& yLocal) const {
    const double dx = xWorld - originWorldX, dy = yWorld - originWorldY;
    if (rotationDeg == 0) {
        xLocal = dx, yLocal = dy;
        return;
    }
    worldToLocalDir(dx, dy, xLocal, yLocal);
}

void Grid::localToWorld(double xLocal, double yLocal, double& xWorld, double& yWorld) const {
    if (rotationDeg == 0) {
        xWorld = originWorldX + xLocal, yWorld = originWorldY + yLocal;
        return;
    }
    double wx = 0, wy = 0;
    localToWorldDir(xLocal, yLocal, wx, wy);
    xWorld = originWorldX + wx, yWorld = originWorldY + wy;
}

void Grid::localToWorldDir(double dx, double dy, double& wx, double& wy) const {
    if (rotationDeg == 0) {
        wx = dx, wy = dy;
        return;
    }
    double c = 1, s = 0;
    cosSin(rotationDeg, c, s);
    wx = c * dx - s * dy, wy = s * dx + c * dy;
}

void Grid::worldToLocalDir(double wx, double wy, double& dx, double& dy) const {
    if (rotationDeg == 0) {
        dx = wx, dy = wy;
        return;
    }
    double c = 1, s = 0;
    cosSin(rotationDeg, c, s);
    dx = c * wx + s * wy, dy = -s * wx + c * wy;
}

size_t Grid::firstStepLayer() const {
    const int w = findLayer("water_depth");
    return w < 0 ? layers.size() : static_cast<size_t>(w);
}

size_t Grid::stepCount() const {
    if (!steps.empty()) return steps.size();
    return firstStepLayer() < layers.size() ? 1 : 0;
}

void Grid::cellMinLocal(size_t i, double& x, double& y) const {
    uint64_t key = codeKey(codes[i]);
    x = static_cast<double>(mortonX(key)) * finestCellM;
    y = static_cast<double>(mortonY(key)) * finestCellM;
}

void Grid::cellCenterLocal(size_t i, double& x, double& y) const {
    cellMinLocal(i, x, y);
    double half = 0.5 * cellSizeM(i);
    x += half;
    y += half;
}

void Grid::appendCell(uint32_t ix, uint32_t iy, int cellLevel, const float* layerValues) {
    uint64_t code = makeCellCode(mortonEncode(ix, iy), cellLevel);
    assert(codes.empty() || codeKey(code) >= codeKey(codes.back()) + mortonSpan(codeLevel(codes.back())));
    codes.push_back(code);
    for (size_t l = 0; l < layers.size(); ++l) values[l].push_back(layerValues[l]);
}

std::optional<uint64_t> Grid::finestKeyAt(double xLocal, double yLocal) const {
    double side = domainSizeM();
    // Written so that NaN fails the test too.
    if (!(xLocal >= 0 && yLocal >= 0 && xLocal < side && yLocal < side)) return std::nullopt;
    uint64_t limit = (uint64_t{1} << rootLevel) - 1;
    // floor(x / c), corrected so it agrees exactly with the edges cellSquare() computes as ix * c.
    auto finest = [&](double v) {
        auto i = std::min(static_cast<uint64_t>(v / finestCellM), limit);
        if (i > 0 && v < static_cast<double>(i) * finestCellM) --i;
        if (i < limit && v >= static_cast<double>(i + 1) * finestCellM) ++i;
        return i;
    };
    return mortonEncode(static_cast<uint32_t>(finest(xLocal)), static_cast<uint32_t>(finest(yLocal)));
}

std::optional<uint32_t> Grid::locate(double xLocal, double yLocal) const {
    const std::optional<uint64_t> at = finestKeyAt(xLocal, yLocal);
    if (!at) return std::nullopt;
    const uint64_t key = *at;
    // The last cell whose corner key is <= key is the only one that can contain it.
    auto it = std::upper_bound(codes.begin(), codes.end(), makeCellCode(key, (1 << kLevelBits) - 1));
    if (it == codes.begin()) return std::nullopt;
    --it;
    uint64_t cellKey = codeKey(*it);
    if (key - cellKey >= mortonSpan(codeLevel(*it))) return std::nullopt;
    return static_cast<uint32_t>(it - codes.begin());
}

template <typename Pred, typename Emit>
void Grid::visitNodes(Pred&& nodeMeets, Emit&& emit, std::vector<uint32_t>& out) const {
    detail::walkQuadtree(
        0, rootLevel, 0, codes.size(), [&](size_t i) { return codes[i]; },
        [&](size_t lo, size_t hi, uint64_t code) {
            return size_t(
                std::lower_bound(codes.begin() + std::ptrdiff_t(lo), codes.begin() + std::ptrdiff_t(hi), code) -
                codes.begin());
        },
        [&](uint64_t key, int lv) { return nodeMeets(squareOf(key, lv)); },
        [&](size_t lo, size_t hi) {
            for (size_t i = lo; i < hi; ++i) out.push_back(static_cast<uint32_t>(i));
        },
        emit);
}

Grid::Square Grid::squareOf(uint64_t key, int lv) const {
    // Edges from integers, each with one rounding: a cell and a node sharing an edge get the very
    // same double, and containment in integers stays containment in doubles (rounding is monotonic).
    uint64_t ix = mortonX(key), iy = mortonY(key), span = uint64_t{1} << lv;
    return {static_cast<double>(ix) * finestCellM, static_cast<double>(iy) * finestCellM,
            static_cast<double>(ix + span) * finestCellM, static_cast<double>(iy + span) * finestCellM};
}

Grid::Square Grid::cellSquare(size_t i) const { return squareOf(codeKey(codes[i]), codeLevel(codes[i])); }

void Grid::cellsInBox(double xMin, double yMin, double xMax, double yMax, std::vector<uint32_t>& out) const {
    if (!(xMin <= xMax && yMin <= yMax)) return;
    auto meets = [&](const Square& q) {
        double x0 = q.x0, y0 = q.y0, x1 = q.x1, y1 = q.y1;
        if (x1 < xMin || x0 > xMax || y1 < yMin || y0 > yMax) return 0;
        if (x0 >= xMin && x1 <= xMax && y0 >= yMin && y1 <= yMax) return 2;
        return 1;
    };
    auto emit = [&](size_t i) {
        if (meets(cellSquare(i)) != 0) out.push_back(static_cast<uint32_t>(i));
    };
    visitNodes(meets, emit, out);
}

void Grid::cellsInDisk(double cx, double cy, double radius, std::vector<uint32_t>& out) const {
    if (!(radius >= 0)) return;
    double r2 = radius * radius;
    auto meets = [&](const Square& q) {
        double x0 = q.x0, y0 = q.y0, x1 = q.x1, y1 = q.y1;
        double dx = std::max({x0 - cx, 0.0, cx - x1});
        double dy = std::max({y0 - cy, 0.0, cy - y1});
        if (dx * dx + dy * dy > r2) return 0;
        // Inside when the farthest corner is within the radius.
        double fx = std::max(std::abs(cx - x0), std::abs(cx - x1));
        double fy = std::max(std::abs(cy - y0), std::abs(cy - y1));
        return fx * fx + fy * fy <= r2 ? 2 : 1;
    };
    auto emit = [&](size_t i) {
        if (meets(cellSquare(i)) != 0) out.push_back(static_cast<uint32_t>(i));
    };
    visitNodes(meets, emit, out);
}

void Grid::neighbours(uint32_t i, std::vector<uint32_t>& out) const {
    Square q = cellSquare(i);
    size_t first = out.size();
    cellsInBox(q.x0, q.y0, q.x1, q.y1, out);  // closed box: touching squares are included
    out.erase(std::remove(out.begin() + static_cast<std::ptrdiff_t>(first), out.end(), i), out.end());
}

std::vector<uint64_t> Grid::cellsPerLevel() const {
    std::vector<uint64_t> counts(static_cast<size_t>(maxLevel) + 1, 0);
    for (uint64_t c : codes) {
        auto l = static_cast<size_t>(codeLevel(c));
        if (l >= counts.size()) counts.resize(l + 1, 0);
        ++counts[l];
    }
    return counts;
}

void Grid::boundsLocal(double& xMin, double& yMin, double& xMax, double& yMax) const {
    xMin = yMin = xMax = yMax = 0;
    if (codes.empty()) return;
    xMin = yMin = HUGE_VAL;
    xMax = yMax = -HUGE_VAL;
    for (size_t i = 0; i < codes.size(); ++i) {
        Square q = cellSquare(i);
        xMin = std::min(xMin, q.x0);
        yMin = std::min(yMin, q.y0);
        xMax = std::max(xMax, q.x1);
        yMax = std::max(yMax, q.y1);
    }
}

GridHasher::GridHasher(const Grid& shape, uint64_t cellCount) : shape_(shape), layers_(shape.layers.size()) {
    structure_.updateValue(shape.finestCellM);
    structure_.updateValue(static_cast<int32_t>(shape.rootLevel));
    structure_.updateValue(cellCount);
}

void GridHasher::addCodes(std::span<const uint64_t> c) { structure_.update(std::as_bytes(c)); }
void GridHasher::addValues(size_t layer, std::span<const float> v) { layers_[layer].update(std::as_bytes(v)); }
uint64_t GridHasher::structureHash() const { return structure_.digest(); }

std::vector<Hash64::State> GridHasher::save() const {
    std::vector<Hash64::State> out{structure_.save()};
    for (const Hash64& h : layers_) out.push_back(h.save());
    return out;
}

void GridHasher::resume(const std::vector<Hash64::State>& states) {
    if (states.size() != 1 + layers_.size())
        throw Error("grid hashes: " + std::to_string(states.size()) + " states for " + std::to_string(layers_.size()) +
                    " layers");
    structure_ = Hash64::resume(states[0]);
    for (size_t l = 0; l < layers_.size(); ++l) layers_[l] = Hash64::resume(states[1 + l]);
}

uint64_t GridHasher::contentHash() const {
    std::vector<std::pair<std::string, uint64_t>> parts;
    for (size_t l = 0; l < layers_.size(); ++l) parts.emplace_back(shape_.layers[l].name, layers_[l].digest());
    return combineContentHash(structure_.digest(), parts);
}

uint64_t combineContentHash(uint64_t structureHash, std::span<const std::pair<std::string, uint64_t>> layerDigests) {
    Hash64 h(0x6863636f6e74656eull);
    h.updateValue(structureHash);
    for (const auto& [name, digest] : layerDigests) {
        h.update(std::as_bytes(std::span<const char>(name.data(), name.size() + 1)));
        h.updateValue(digest);
    }
    return h.digest();
}

uint64_t sparseLayerDigest(uint64_t cellCount, std::span<const uint32_t> at, std::span<const float> values) {
    Hash64 h;
    static const std::vector<float> zeros(4096, 0.0f);
    uint64_t next = 0;  // first cell not yet hashed
    auto zeroTo = [&](uint64_t end) {
        while (next < end) {
            const uint64_t n = std::min<uint64_t>(end - next, zeros.size());
            h.update(std::as_bytes(std::span<const float>(zeros.data(), n)));
            next += n;
        }
    };
    for (size_t j = 0; j < at.size(); ++j) {
        zeroTo(at[j]);
        h.updateValue(values[j]);
        ++next;
    }
    zeroTo(cellCount);
    return h.digest();
}

uint64_t Grid::structureHash() const {
    GridHasher h(*this, codes.size());
    h.addCodes(codes);
    return h.structureHash();
}

uint64_t Grid::contentHash() const {
    GridHasher h(*this, codes.size());
    h.addCodes(codes);
    for (size_t l = 0; l < layers.size(); ++l) h.addValues(l, values[l]);
    return h.contentHash();
}

std::string CellStreamCheck::next(uint64_t code, const float* layerValues) {
    // Hot path (every cell a writer streams): no allocation unless something is wrong.
    const uint64_t i = count_++;
    const uint64_t key = codeKey(code);
    const int lv = codeLevel(code);
    auto cell = [&](const std::string& what) { return "cell " + std::to_string(i) + " " + what; };
    if (lv < shape_.minLevel || lv > shape_.maxLevel)
        return cell("has level " + std::to_string(lv) + " outside " + std::to_string(shape_.minLevel) + ".." +
                    std::to_string(shape_.maxLevel));
    const uint64_t span = mortonSpan(lv), domainSpan = mortonSpan(shape_.rootLevel);
    if ((key & (span - 1)) != 0) return cell("is not aligned to its level " + std::to_string(lv));
    if (key >= domainSpan || span > domainSpan - key) return cell("lies outside the domain");
    if (i > 0 && key < nextFree_) return cell("overlaps or precedes cell " + std::to_string(i - 1));
    nextFree_ = key + span;
    for (size_t l = 0; l < shape_.layers.size(); ++l)
        if (!std::isfinite(layerValues[l])) return cell("has a non-finite " + shape_.layers[l].name + " value");
    return {};
}

std::string CellStreamCheck::nextBatch(std::span<const uint64_t> codes,
                                       const std::vector<std::span<const float>>& layerValues) {
    const uint64_t domainSpan = mortonSpan(shape_.rootLevel);
    size_t i = 0;
    for (; i < codes.size(); ++i) {  // next()'s rules, without the words
        const uint64_t key = codeKey(codes[i]);
        const int lv = codeLevel(codes[i]);
        if (lv < shape_.minLevel || lv > shape_.maxLevel) break;
        const uint64_t span = mortonSpan(lv);
        if ((key & (span - 1)) != 0 || key >= domainSpan || span > domainSpan - key) break;
        if (count_ + i > 0 && key < nextFree_) break;
        bool finite = true;
        for (const std::span<const float>& v : layerValues) finite &= std::isfinite(v[i]);
        if (!finite) break;
        nextFree_ = key + span;
    }
    count_ += i;
    if (i == codes.size()) return {};
    float v[256];
    for (size_t l = 0; l < layerValues.size() && l < 256; ++l) v[l] = layerValues[l][i];
    std::string problem = next(codes[i], v);
    if (problem.empty()) throw Error("internal: CellStreamCheck::nextBatch stopped at a cell next() passes");
    return problem;
}

std::string Grid::validateShape() const {
    std::ostringstream err;
    if (!(finestCellM > 0) || !std::isfinite(finestCellM))
        err << "finest cell size " << finestCellM << " m is not positive";
    else if (!std::isfinite(originWorldX) || !std::isfinite(originWorldY))
        err << "origin is not finite";
    else if (!(rotationDeg > -180 && rotationDeg <= 180))
        err << "rotation " << rotationDeg << " degrees is outside (-180, 180]";
    else if (rootLevel < 0 || rootLevel > kMaxRootLevel)
        err << "root level " << rootLevel << " outside 0.." << kMaxRootLevel;
    else if (minLevel < 0 || minLevel > maxLevel || maxLevel > rootLevel)
        err << "level range " << minLevel << ".." << maxLevel << " invalid for root level " << rootLevel;
    else if (layers.empty() || layers[0].name != "elevation")
        err << "layer 0 must be elevation";
    else if (layers.size() > 255)
        err << layers.size() << " layers (at most 255)";
    if (!err.str().empty()) return err.str();
    for (size_t l = 0; l < layers.size(); ++l)
        for (size_t m = 0; m < l; ++m)
            if (layers[m].name == layers[l].name) return "layer name " + layers[l].name + " appears twice";
    if (!steps.empty()) {
        if (firstStepLayer() >= layers.size())
            return std::to_string(steps.size()) + " water steps but no water_depth layer";
        if (step >= steps.size())
            return "selected step " + std::to_string(step) + " of " + std::to_string(steps.size());
        for (size_t k = 0; k < steps.size(); ++k) {
            if (!std::isfinite(steps[k].timeS)) return "step " + std::to_string(k) + " has a time that is not finite";
            if (k > 0 && !(steps[k].timeS > steps[k - 1].timeS))
                return "step times are not strictly increasing: step " + std::to_string(k) + " at " +
                       std::to_string(steps[k].timeS) + " s follows " + std::to_string(steps[k - 1].timeS) + " s";
        }
    } else if (step != 0) {
        return "selected step " + std::to_string(step) + " of a grid without steps";
    }
    return {};
}

std::string Grid::validate() const {
    if (std::string shape = validateShape(); !shape.empty()) return shape;
    if (values.size() != layers.size())
        return std::to_string(values.size()) + " value arrays for " + std::to_string(layers.size()) + " layers";
    for (size_t l = 0; l < layers.size(); ++l)
        if (values[l].size() != codes.size())
            return "layer " + layers[l].name + " has " + std::to_string(values[l].size()) + " values for " +
                   std::to_string(codes.size()) + " cells";
    CellStreamCheck check(*this);
    std::vector<float> v(layers.size());
    for (size_t i = 0; i < codes.size(); ++i) {
        for (size_t l = 0; l < layers.size(); ++l) v[l] = values[l][i];
        std::string problem = check.next(codes[i], v.data());
        if (!problem.empty()) return problem;
    }
    return {};
}

}  // namespace hc
