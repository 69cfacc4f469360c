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

#include "heightcast/grid/error.h"
#include "heightcast/grid/parallel.h"
#include "heightcast/grid/progress.h"

namespace hc::ingest {
namespace {

constexpr int kMaxBuildLayers = 2;  // elevation, water depth
constexpr int kTileLevelMax = 6;    // 64 x 64 pixel tiles: a pyramid fits in L2

struct Node {
    std::array<float, kMaxBuildLayers> mean{}, lo{}, hi{};
    bool leaf = false;  // a single cell covers the whole node
    bool wet = false;
};

class Builder {
public:
    Builder(const Raster& terrain, const Raster* water, const BuildOptions& opt, int rootLevel, int maxLevel)
        : t_(terrain), w_(water), opt_(opt), layers_(water ? 2 : 1), rootLevel_(rootLevel), maxLevel_(maxLevel),
          tileLevel_(std::min(rootLevel, kTileLevelMax)), tile_(size_t{1} << tileLevel_),
          ntx_((terrain.width + tile_ - 1) / tile_), nty_((terrain.height + tile_ - 1) / tile_) {}

    void run(Grid& grid);

private:
    // Pixel at finest coordinates (ix east, iy north) from the SW corner; false if none.
    bool pixel(size_t ix, size_t iy, Node& n) const {
        if (ix >= t_.width || iy >= t_.height) return false;
        size_t idx = (t_.height - 1 - iy) * t_.width + ix;
        float z = t_.values[idx];
        if (std::isnan(z)) return false;
        n.mean[0] = n.lo[0] = n.hi[0] = z;
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
    size_t emitTile(size_t tx, size_t ty, const std::vector<std::vector<Node>>& scratch, Grid* grid, size_t at) const {
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

    void writeCell(Grid& g, size_t at, size_t ix, size_t iy, int level, const Node& n) const {
        g.codes[at] = makeCellCode(mortonEncode(static_cast<uint32_t>(ix), static_cast<uint32_t>(iy)), level);
        for (int l = 0; l < layers_; ++l) g.values[static_cast<size_t>(l)][at] = n.mean[static_cast<size_t>(l)];
    }

    void measureDeviation(Grid& g) const;

    const Raster& t_;
    const Raster* w_;
    const BuildOptions& opt_;
    int layers_;
    int rootLevel_, maxLevel_, tileLevel_;
    size_t tile_, ntx_, nty_;
};

void Builder::run(Grid& grid) {
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

        grid.codes.resize(total);
        for (int l = 0; l < layers_; ++l) grid.values[static_cast<size_t>(l)].resize(total);

        // Pass C, write: every unit fills its own slice of the final arrays.
        parallelFor(units.size(), 16, threads, [&](size_t b, size_t e, unsigned worker) {
            size_t tilesDone = 0;
            for (size_t u = b; u < e; ++u) {
                const Unit& unit = units[u];
                if (unit.level > tileLevel_) {
                    auto k = static_cast<size_t>(unit.level - tileLevel_);
                    const Node& n = coarse[k][unit.y * dims[k].first + unit.x];
                    size_t span = size_t{1} << unit.level;
                    writeCell(grid, unit.offset, unit.x * span, unit.y * span, unit.level, n);
                    continue;
                }
                buildTile(unit.x, unit.y, scratch[worker]);
                size_t written = emitTile(unit.x, unit.y, scratch[worker], &grid, unit.offset);
                assert(written == leafCount[unit.y * ntx_ + unit.x]);
                (void)written;
                ++tilesDone;
            }
            progress.advance(tilesDone);
        });
        progress.advance(2 * tiles);  // units cover fewer than all tiles; fill the bar
        progress.finish();
    }
    measureDeviation(grid);
}

// The guarantee, measured: every valid pixel against the stored value of its cell.
void Builder::measureDeviation(Grid& g) const {
    const unsigned threads = resolveThreads(opt_.threads);
    struct Acc {
        double maxDev = 0, sumSq = 0;
        uint64_t pixels = 0;
    };
    std::vector<Acc> acc(threads);
    parallelFor(g.cellCount(), 4096, threads, [&](size_t b, size_t e, unsigned worker) {
        Acc& a = acc[worker];
        for (size_t i = b; i < e; ++i) {
            uint64_t key = codeKey(g.codes[i]);
            size_t span = size_t{1} << codeLevel(g.codes[i]);
            size_t ix0 = mortonX(key), iy0 = mortonY(key);
            for (size_t iy = iy0; iy < iy0 + span; ++iy) {
                size_t row = t_.height - 1 - iy;
                for (size_t ix = ix0; ix < ix0 + span; ++ix) {
                    size_t idx = row * t_.width + ix;
                    double dz = static_cast<double>(t_.values[idx]) - g.values[0][i];
                    a.sumSq += dz * dz;
                    a.maxDev = std::max(a.maxDev, std::abs(dz));
                    if (w_) a.maxDev = std::max(a.maxDev, std::abs(static_cast<double>(w_->values[idx]) - g.values[1][i]));
                    ++a.pixels;
                }
            }
        }
    });
    Acc total;
    for (const Acc& a : acc) {
        total.maxDev = std::max(total.maxDev, a.maxDev);
        total.sumSq += a.sumSq;
        total.pixels += a.pixels;
    }
    g.stats.maxDevM = total.maxDev;
    g.stats.rmsDevM = total.pixels ? std::sqrt(total.sumSq / static_cast<double>(total.pixels)) : 0.0;
    g.stats.validPixels = total.pixels;
}

}  // namespace

Grid buildGrid(const Raster& terrain, const Raster* waterDepth, const BuildOptions& options) {
    if (terrain.width == 0 || terrain.height == 0 || terrain.values.size() != terrain.width * terrain.height)
        throw Error("raster is empty or inconsistent");
    if (!(options.toleranceM >= 0) || !std::isfinite(options.toleranceM)) throw Error("tolerance must be a finite number >= 0");
    if (!(terrain.pixelSizeM > 0)) throw Error("pixel size must be positive");
    if (waterDepth && (waterDepth->width != terrain.width || waterDepth->height != terrain.height ||
                       waterDepth->values.size() != terrain.values.size()))
        throw Error("water depth raster does not match the terrain raster's geometry");

    int rootLevel = 0;
    while ((size_t{1} << rootLevel) < std::max(terrain.width, terrain.height)) ++rootLevel;
    if (rootLevel > kMaxRootLevel) throw Error("raster of " + std::to_string(terrain.width) + " x " +
                                               std::to_string(terrain.height) + " pixels is too large for one grid");
    int maxLevel = std::clamp(options.maxLevel, 0, rootLevel);

    Grid g;
    g.originWorldX = terrain.westWorld;
    g.originWorldY = terrain.southWorld();
    g.finestCellM = terrain.pixelSizeM;
    g.rootLevel = rootLevel;
    g.minLevel = 0;
    g.maxLevel = maxLevel;
    g.crsWkt = terrain.crsWkt;
    if (waterDepth) {
        g.layers.push_back({"water_depth", "m"});
        g.values.emplace_back();
    }
    g.stats.sourceWidth = terrain.width;
    g.stats.sourceHeight = terrain.height;
    g.stats.toleranceM = options.toleranceM;
    Builder(terrain, waterDepth, options, rootLevel, maxLevel).run(g);
    if (g.cellCount() == 0) throw Error("the raster holds no valid pixel (all nodata): nothing to build");
    assert(g.validate().empty());
    return g;
}

}  // namespace hc::ingest
