// The bottom-up quadtree build. See build.h for the merge rule and the guarantee.
//
// The domain is cut into tiles of 2^tileLevel pixels. Pass A builds each tile's pyramid (in parallel)
// and keeps only its root summary and leaf count. Pass B merges tile roots up the coarse levels.
// Pass C walks the coarse tree in Morton order to give every tile its output offset, then rebuilds
// each tile's pyramid (cheap, cache-resident) and writes its cells straight into the final arrays:
// no sort, no reallocation, and memory beyond the raster and the grid stays at a few hundred kB.
#include "heightcast/ingest/build.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <limits>
#include <memory>

#include "heightcast/grid/grid_file.h"

#include "heightcast/core/error.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/progress.h"
#include "heightcast/core/timer.h"

namespace hc::ingest {
namespace {

constexpr int kMaxBuildLayers = 2;  // elevation, water depth
constexpr int kTileLevelMax = 6;    // 64 x 64 pixel tiles: a pyramid fits in L2

struct Node {
    std::array<float, kMaxBuildLayers> mean{}, lo{}, hi{};
    bool leaf = false;  // a single cell covers the whole node
    bool wet = false;
};

// Cells on their way to the sink: one batch at a time, so the grid never has to be in memory.
struct Batch {
    std::vector<uint64_t> codes;
    std::vector<std::vector<float>> values;
};

struct Stats {
    double maxDev = 0, sumSq = 0;
    uint64_t pixels = 0, wetCells = 0;
    std::vector<uint64_t> perLevel;
};

class Builder {
public:
    Builder(const Raster& terrain, const Raster* water, const BuildOptions& opt, int rootLevel, int maxLevel)
        : t_(terrain), w_(water), opt_(opt), layers_(water ? 2 : 1), rootLevel_(rootLevel), maxLevel_(maxLevel),
          tileLevel_(std::min(rootLevel, kTileLevelMax)), tile_(size_t{1} << tileLevel_),
          ntx_((terrain.width + tile_ - 1) / tile_), nty_((terrain.height + tile_ - 1) / tile_) {}

    // Builds the tree and hands its cells, in Morton order, to the sink. Returns the measurements.
    Stats run(CellSink& sink);

private:
    // Pixel at finest coordinates (ix east, iy north) from the SW corner; false if none.
    bool pixel(size_t ix, size_t iy, Node& n) const {
        if (ix >= t_.width || iy >= t_.height) return false;
        size_t idx = (t_.height - 1 - iy) * t_.width + ix;
        float z = t_.values[idx];
        if (std::isnan(z)) return false;
        n.mean[0] = n.lo[0] = n.hi[0] = z;
        if (!t_.roundingM.empty() && t_.roundingM[idx] != 0) {
            // The source's own value lies between lo and hi (float32 neighbours of it), so merges
            // checked against lo and hi keep the tolerance against the source, not only its rounding.
            const double exact = static_cast<double>(z) + t_.roundingM[idx];
            (exact > z ? n.hi[0] : n.lo[0]) = std::nextafter(z, exact > z ? HUGE_VALF : -HUGE_VALF);
        }
        if (w_) {
            float d = w_->values[idx];
            n.mean[1] = n.lo[1] = n.hi[1] = d;
            n.wet = d > 0;
        }
        n.leaf = true;
        return true;
    }

    // The merge rule (build.h).
    Node merge(const Node& a, const Node& b, const Node& c, const Node& d, int level) const {
        Node p;
        if (!(a.leaf && b.leaf && c.leaf && d.leaf) || level > maxLevel_) return p;
        if (w_ && !(a.wet == b.wet && b.wet == c.wet && c.wet == d.wet)) return p;
        for (int l = 0; l < layers_; ++l) {
            double sum = static_cast<double>(a.mean[l]) + b.mean[l] + c.mean[l] + d.mean[l];
            float m = static_cast<float>(sum * 0.25);
            float lo = std::min({a.lo[l], b.lo[l], c.lo[l], d.lo[l]});
            float hi = std::max({a.hi[l], b.hi[l], c.hi[l], d.hi[l]});
            // Checked against the stored float value, so the guarantee holds after rounding too.
            if (static_cast<double>(hi) - m > opt_.toleranceM || m - static_cast<double>(lo) > opt_.toleranceM) return p;
            p.mean[l] = m;
            p.lo[l] = lo;
            p.hi[l] = hi;
        }
        p.wet = a.wet;
        p.leaf = true;
        return p;
    }

    // Builds tile (tx, ty)'s pyramid into scratch[level]; returns the root.
    const Node& buildTile(size_t tx, size_t ty, std::vector<std::vector<Node>>& scratch) const {
        scratch.resize(static_cast<size_t>(tileLevel_) + 1);
        size_t side = tile_;
        scratch[0].assign(side * side, Node{});
        for (size_t y = 0; y < side; ++y)
            for (size_t x = 0; x < side; ++x) pixel(tx * tile_ + x, ty * tile_ + y, scratch[0][y * side + x]);
        for (int l = 1; l <= tileLevel_; ++l) {
            size_t childSide = side;
            side /= 2;
            auto& cur = scratch[static_cast<size_t>(l)];
            const auto& ch = scratch[static_cast<size_t>(l) - 1];
            if (l > maxLevel_) {  // nothing merges above the coarsest level: skip the arithmetic
                cur.assign(side * side, Node{});
                continue;
            }
            cur.resize(side * side);
            for (size_t y = 0; y < side; ++y)
                for (size_t x = 0; x < side; ++x) {
                    size_t c = 2 * y * childSide + 2 * x;
                    cur[y * side + x] = merge(ch[c], ch[c + 1], ch[c + childSide], ch[c + childSide + 1], l);
                }
        }
        return scratch[static_cast<size_t>(tileLevel_)][0];
    }

    // Emits the leaves of a built tile pyramid in Morton order; returns how many.
    size_t emitTile(size_t tx, size_t ty, const std::vector<std::vector<Node>>& scratch, Batch* grid, size_t at) const {
        size_t count = 0;
        auto visit = [&](auto&& self, int l, size_t x, size_t y) -> void {
            size_t side = tile_ >> l;
            const Node& n = scratch[static_cast<size_t>(l)][y * side + x];
            if (n.leaf) {
                if (grid) writeCell(*grid, at + count, tx * tile_ + (x << l), ty * tile_ + (y << l), l, n);
                ++count;
                return;
            }
            if (l == 0) return;  // a hole
            for (int q = 0; q < 4; ++q) self(self, l - 1, 2 * x + (q & 1), 2 * y + (q >> 1));
        };
        visit(visit, tileLevel_, 0, 0);
        return count;
    }

    void writeCell(Batch& b, size_t at, size_t ix, size_t iy, int level, const Node& n) const {
        b.codes[at] = makeCellCode(mortonEncode(static_cast<uint32_t>(ix), static_cast<uint32_t>(iy)), level);
        for (int l = 0; l < layers_; ++l) b.values[static_cast<size_t>(l)][at] = n.mean[static_cast<size_t>(l)];
    }

    // The guarantee, measured: every valid pixel under cells [begin, end) of the batch against the
    // stored value of its cell; also counts cells per level and wet cells.
    void measure(const Batch& b, size_t begin, size_t end, Stats& acc) const;

    const Raster& t_;
    const Raster* w_;
    const BuildOptions& opt_;
    int layers_;
    int rootLevel_, maxLevel_, tileLevel_;
    size_t tile_, ntx_, nty_;
};

Stats Builder::run(CellSink& sink) {
    const unsigned threads = resolveThreads(opt_.threads);
    const size_t tiles = ntx_ * nty_;

    // Pass A: tile roots and leaf counts.
    std::vector<Node> roots(tiles);
    std::vector<uint32_t> leafCount(tiles);
    {
        Progress progress("building quadtree", 2 * tiles, opt_.progress);
        std::vector<std::vector<std::vector<Node>>> scratch(threads);
        parallelFor(tiles, 16, threads, [&](size_t b, size_t e, unsigned worker) {
            for (size_t i = b; i < e; ++i) {
                size_t tx = i % ntx_, ty = i / ntx_;
                roots[i] = buildTile(tx, ty, scratch[worker]);
                leafCount[i] = static_cast<uint32_t>(emitTile(tx, ty, scratch[worker], nullptr, 0));
            }
            progress.advance(e - b);
        });

        // Pass B: coarse levels over tile roots, level tileLevel+1 .. rootLevel.
        std::vector<std::vector<Node>> coarse{roots};
        std::vector<std::pair<size_t, size_t>> dims{{ntx_, nty_}};
        for (int l = tileLevel_ + 1; l <= rootLevel_; ++l) {
            auto [cw, chh] = dims.back();
            size_t nw = (cw + 1) / 2, nh = (chh + 1) / 2;
            const auto& ch = coarse.back();
            std::vector<Node> cur(nw * nh);
            auto child = [&](size_t x, size_t y) -> Node { return (x < cw && y < chh) ? ch[y * cw + x] : Node{}; };
            for (size_t y = 0; y < nh; ++y)
                for (size_t x = 0; x < nw; ++x)
                    cur[y * nw + x] = merge(child(2 * x, 2 * y), child(2 * x + 1, 2 * y), child(2 * x, 2 * y + 1),
                                            child(2 * x + 1, 2 * y + 1), l);
            coarse.push_back(std::move(cur));
            dims.emplace_back(nw, nh);
        }

        // Pass C, walk: units in Morton order. A unit is a merged coarse cell or one tile.
        struct Unit {
            size_t x, y;  // node coordinates at its level
            int level;    // absolute level; tileLevel_ means "a tile"
            size_t offset;
        };
        std::vector<Unit> units;
        size_t total = 0;
        auto walk = [&](auto&& self, int l, size_t x, size_t y) -> void {
            auto k = static_cast<size_t>(l - tileLevel_);
            auto [cw, chh] = dims[k];
            if (x >= cw || y >= chh) return;
            const Node& n = coarse[k][y * cw + x];
            if (l == tileLevel_) {
                size_t count = leafCount[y * ntx_ + x];
                if (count > 0) units.push_back({x, y, l, total});
                total += count;
                return;
            }
            if (n.leaf) {
                units.push_back({x, y, l, total});
                total += 1;
                return;
            }
            for (int q = 0; q < 4; ++q) self(self, l - 1, 2 * x + (q & 1), 2 * y + (q >> 1));
        };
        walk(walk, rootLevel_, 0, 0);

        sink.begin(total);

        // Pass C, write: batches of consecutive units (about 64 k cells, a few MB), filled in
        // parallel, measured, and handed to the sink in order.
        std::vector<Stats> acc(threads);
        for (auto& a : acc) a.perLevel.assign(static_cast<size_t>(maxLevel_) + 1, 0);
        Batch batch;
        batch.values.resize(static_cast<size_t>(layers_));
        size_t u0 = 0;
        while (u0 < units.size()) {
            size_t u1 = u0;
            const size_t first = units[u0].offset;
            while (u1 < units.size() && (u1 == u0 || units[u1].offset - first < (size_t{1} << 16))) ++u1;
            const size_t last = u1 < units.size() ? units[u1].offset : total;
            batch.codes.resize(last - first);
            for (auto& v : batch.values) v.resize(last - first);
            parallelFor(u1 - u0, 1, threads, [&](size_t b, size_t e, unsigned worker) {
                size_t tilesDone = 0;
                for (size_t k = u0 + b; k < u0 + e; ++k) {
                    const Unit& unit = units[k];
                    const size_t at = unit.offset - first;
                    size_t written = 1;
                    if (unit.level > tileLevel_) {
                        auto lk = static_cast<size_t>(unit.level - tileLevel_);
                        const Node& n = coarse[lk][unit.y * dims[lk].first + unit.x];
                        size_t span = size_t{1} << unit.level;
                        writeCell(batch, at, unit.x * span, unit.y * span, unit.level, n);
                    } else {
                        buildTile(unit.x, unit.y, scratch[worker]);
                        written = emitTile(unit.x, unit.y, scratch[worker], &batch, at);
                        assert(written == leafCount[unit.y * ntx_ + unit.x]);
                        ++tilesDone;
                    }
                    measure(batch, at, at + written, acc[worker]);
                }
                progress.advance(tilesDone);
            });
            std::vector<std::span<const float>> values(batch.values.begin(), batch.values.end());
            sink.append(batch.codes, values);
            u0 = u1;
        }
        progress.advance(2 * tiles);  // units cover fewer than all tiles; fill the bar
        progress.finish();
        Stats sum;
        sum.perLevel.assign(static_cast<size_t>(maxLevel_) + 1, 0);
        for (const Stats& a : acc) {
            sum.maxDev = std::max(sum.maxDev, a.maxDev);
            sum.sumSq += a.sumSq;
            sum.pixels += a.pixels;
            sum.wetCells += a.wetCells;
            for (size_t l = 0; l < a.perLevel.size(); ++l) sum.perLevel[l] += a.perLevel[l];
        }
        return sum;
    }
}

void Builder::measure(const Batch& b, size_t begin, size_t end, Stats& a) const {
    for (size_t i = begin; i < end; ++i) {
        const uint64_t key = codeKey(b.codes[i]);
        const int level = codeLevel(b.codes[i]);
        ++a.perLevel[static_cast<size_t>(level)];
        if (w_ && b.values[1][i] > 0) ++a.wetCells;
        const size_t span = size_t{1} << level;
        const size_t ix0 = mortonX(key), iy0 = mortonY(key);
        const double z = b.values[0][i];
        for (size_t iy = iy0; iy < iy0 + span; ++iy) {
            const size_t row = t_.height - 1 - iy;
            for (size_t ix = ix0; ix < ix0 + span; ++ix) {
                const size_t idx = row * t_.width + ix;
                const double exact = static_cast<double>(t_.values[idx]) + (t_.roundingM.empty() ? 0.0 : t_.roundingM[idx]);
                const double dz = exact - z;
                if (opt_.cellElevations) (*opt_.cellElevations)[idx] = b.values[0][i];
                a.sumSq += dz * dz;
                a.maxDev = std::max(a.maxDev, std::abs(dz));
                if (w_) a.maxDev = std::max(a.maxDev, std::abs(static_cast<double>(w_->values[idx]) - b.values[1][i]));
                ++a.pixels;
            }
        }
    }
}

}  // namespace

namespace {

// The grid's geometry for a raster: origin at its south-west corner, finest cell = its pixel.
Grid shapeFor(const Raster& terrain, const Raster* waterDepth, const BuildOptions& options, int& rootLevel, int& maxLevel) {
    if (terrain.width == 0 || terrain.height == 0 || terrain.values.size() != terrain.width * terrain.height)
        throw Error("raster is empty or inconsistent");
    if (!(options.toleranceM >= 0) || !std::isfinite(options.toleranceM)) throw Error("tolerance must be a finite number >= 0");
    if (!(terrain.pixelSizeM > 0)) throw Error("pixel size must be positive");
    if (!terrain.roundingM.empty() && terrain.roundingM.size() != terrain.values.size())
        throw Error("terrain rounding does not match the terrain raster");
    if (waterDepth && (waterDepth->width != terrain.width || waterDepth->height != terrain.height ||
                       waterDepth->values.size() != terrain.values.size()))
        throw Error("water depth raster does not match the terrain raster's geometry");
    rootLevel = 0;
    while ((size_t{1} << rootLevel) < std::max(terrain.width, terrain.height)) ++rootLevel;
    if (rootLevel > kMaxRootLevel) throw Error("raster of " + std::to_string(terrain.width) + " x " +
                                               std::to_string(terrain.height) + " pixels is too large for one grid");
    maxLevel = std::clamp(options.maxLevel, 0, rootLevel);
    Grid g;
    g.originWorldX = terrain.westWorld;
    g.originWorldY = terrain.southWorld();
    g.finestCellM = terrain.pixelSizeM;
    g.rootLevel = rootLevel;
    g.minLevel = 0;
    g.maxLevel = maxLevel;
    g.crsWkt = terrain.crsWkt;
    g.crsName = terrain.crsName;
    if (waterDepth) {
        g.layers.push_back({"water_depth", "m"});
        g.values.emplace_back();
    }
    g.stats.sourceWidth = terrain.width;
    g.stats.sourceHeight = terrain.height;
    g.stats.toleranceM = options.toleranceM;
    return g;
}

void fillStats(const Stats& st, IngestStats& out) {
    out.maxDevM = st.maxDev;
    out.rmsDevM = st.pixels ? std::sqrt(st.sumSq / static_cast<double>(st.pixels)) : 0.0;
    out.validPixels = st.pixels;
}

class GridSink : public CellSink {
public:
    explicit GridSink(Grid& g) : g_(g) {}
    void begin(uint64_t cellCount) override {
        g_.codes.reserve(cellCount);
        for (auto& v : g_.values) v.reserve(cellCount);
    }
    void append(std::span<const uint64_t> codes, const std::vector<std::span<const float>>& values) override {
        g_.codes.insert(g_.codes.end(), codes.begin(), codes.end());
        for (size_t l = 0; l < values.size(); ++l) g_.values[l].insert(g_.values[l].end(), values[l].begin(), values[l].end());
    }

private:
    Grid& g_;
};

class FileSink : public CellSink {
public:
    FileSink(const std::string& path, const Grid& shape) : path_(path), shape_(shape) {}
    void begin(uint64_t cellCount) override {
        if (cellCount == 0) throw Error("the raster holds no valid pixel (all nodata): nothing to build");
        writer_ = std::make_unique<GridFileWriter>(path_, shape_, cellCount);
    }
    void append(std::span<const uint64_t> codes, const std::vector<std::span<const float>>& values) override {
        writer_->append(codes, values);
    }
    GridFileWriter& writer() { return *writer_; }

private:
    std::string path_;
    const Grid& shape_;
    std::unique_ptr<GridFileWriter> writer_;
};

}  // namespace

Grid buildGrid(const Raster& terrain, const Raster* waterDepth, const BuildOptions& options) {
    int rootLevel = 0, maxLevel = 0;
    Grid g = shapeFor(terrain, waterDepth, options, rootLevel, maxLevel);
    GridSink sink(g);
    if (options.cellElevations) options.cellElevations->assign(terrain.values.size(), std::numeric_limits<float>::quiet_NaN());
    Stats st = Builder(terrain, waterDepth, options, rootLevel, maxLevel).run(sink);
    if (g.cellCount() == 0) throw Error("the raster holds no valid pixel (all nodata): nothing to build");
    fillStats(st, g.stats);
    assert(g.validate().empty());
    return g;
}

BuildSummary buildGridFile(const Raster& terrain, const Raster* waterDepth, const BuildOptions& options,
                           const std::string& path, const IngestStats& extraStats) {
    const Stopwatch clock;
    int rootLevel = 0, maxLevel = 0;
    BuildSummary out;
    out.shape = shapeFor(terrain, waterDepth, options, rootLevel, maxLevel);
    FileSink sink(path, out.shape);
    if (options.cellElevations) options.cellElevations->assign(terrain.values.size(), std::numeric_limits<float>::quiet_NaN());
    Stats st = Builder(terrain, waterDepth, options, rootLevel, maxLevel).run(sink);
    IngestStats stats = extraStats;
    stats.sourceWidth = out.shape.stats.sourceWidth;
    stats.sourceHeight = out.shape.stats.sourceHeight;
    stats.toleranceM = options.toleranceM;
    fillStats(st, stats);
    stats.seconds = extraStats.seconds + clock.seconds();
    sink.writer().commit(stats);
    out.shape.stats = stats;
    out.cellsPerLevel = st.perLevel;
    out.wetCells = st.wetCells;
    for (uint64_t c : st.perLevel) out.cellCount += c;
    return out;
}

}  // namespace hc::ingest
