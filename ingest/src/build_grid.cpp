// ingest/src/build_grid.cpp: the quadtree build's entry points (build.h): buildGrid (into memory) and buildGridFile
// (streamed into a .hcg file, from a raster held whole or read window by window), the grid's shape for a raster, the
// sinks the cells go to, and the water steps: each step's merge mask (which merges keep its wet/dry edges and depth
// tolerance) and its depth per cell, gathered from the ranks. The build itself is build.cpp's.
#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <span>

#include <fmt/format.h>

#include "build_internal.h"
#include "heightcast/core/error.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/progress.h"
#include "heightcast/core/ranks.h"
#include "heightcast/core/timer.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/ingest/build.h"

namespace hc::ingest {

void checkToleranceM(double toleranceM) {
    if (!std::isfinite(toleranceM) || toleranceM < 0)
        throw Error(fmt::format("--tolerance {:.6g}: must be a finite number of metres >= 0", toleranceM));
}

namespace {

using detail::Block;
using detail::Builder;
using detail::MergeMask;
using detail::Stats;

// A depth raster, or a window of one, as a Block: the whole raster's pixels at (0, 0).
Block wholeOf(const Raster& d) { return {0, 0, d.width, d.height, d.values.data(), nullptr}; }

// A depth pixel at finest coordinates (ix east, iy north of the south-west corner): NaN outside the block or on a hole.
float depthAt(const Block& d, size_t ix, size_t iy) {
    if (ix < d.x0 || iy < d.y0 || ix - d.x0 >= d.w || iy - d.y0 >= d.h) return std::numeric_limits<float>::quiet_NaN();
    return d.values[d.index(ix, iy)];
}

// The depth a merged cell of `level` at (ix, iy) holds: the float mean of its four children's, bottom up, in the order
// the build merges them (Builder::merge).
float cellMean(const Block& d, size_t ix, size_t iy, int level) {
    if (level == 0) return depthAt(d, ix, iy);
    const size_t h = size_t{1} << (level - 1);
    const double sum = static_cast<double>(cellMean(d, ix, iy, level - 1)) + cellMean(d, ix + h, iy, level - 1) +
                       cellMean(d, ix, iy + h, level - 1) + cellMean(d, ix + h, iy + h, level - 1);
    return static_cast<float>(sum * 0.25);
}

}  // namespace

namespace detail {

// Forbids in `mask` every merge step `d` does not allow: four children that are not all wet or all dry, or whose
// depths the parent's mean does not hold within the tolerance (build.h's rule for water). `d` is the whole raster, or a
// window of it whose corner lies on the top level's lattice (a rank's block: share nodes are no finer than the coarsest
// cell), holding every pixel of the nodes it starts (or the raster's edge).
void restrictByStep(const Block& d, double tolerance, int maxLevel, unsigned threads, MergeMask& mask) {
    if (maxLevel < 1) return;
    struct Depth {
        float mean = 0, lo = 0, hi = 0;
        uint8_t state = 0;  // 0: no merge possible (hole, outside, or a forbidden merge below), 1 dry, 2 wet
    };
    const int top = maxLevel;  // nodes of the top level are independent: one task each
    const size_t side = size_t{1} << top;
    if (d.x0 % side != 0 || d.y0 % side != 0) throw Error("internal: a depth window off the coarsest level's lattice");
    const size_t ox = d.x0 / side, oy = d.y0 / side;  // the window's first top-level node
    const size_t nx = (d.w + side - 1) / side, ny = (d.h + side - 1) / side;
    std::vector<std::vector<std::vector<Depth>>> scratch(resolveThreads(threads));
    std::vector<std::vector<std::pair<int, std::pair<size_t, size_t>>>> forbidden(scratch.size());
    parallelFor(nx * ny, 4, threads, [&](size_t b, size_t e, unsigned worker) {
        auto& lv = scratch[worker];
        lv.resize(size_t(top) + 1);
        for (size_t t = b; t < e; ++t) {
            const size_t tx = ox + t % nx, ty = oy + t / nx;
            size_t n = side;
            lv[0].resize(n * n);
            for (size_t y = 0; y < n; ++y)
                for (size_t x = 0; x < n; ++x) {
                    const float v = depthAt(d, tx * side + x, ty * side + y);
                    lv[0][y * n + x] = std::isnan(v) ? Depth{} : Depth{v, v, v, uint8_t(v > 0 ? 2 : 1)};
                }
            for (int l = 1; l <= top; ++l) {
                const size_t cn = n;
                n /= 2;
                auto& cur = lv[size_t(l)];
                const auto& ch = lv[size_t(l) - 1];
                cur.resize(n * n);
                for (size_t y = 0; y < n; ++y)
                    for (size_t x = 0; x < n; ++x) {
                        const size_t c = 2 * y * cn + 2 * x;
                        const Depth& p = ch[c];
                        const Depth& q = ch[c + 1];
                        const Depth& r = ch[c + cn];
                        const Depth& s = ch[c + cn + 1];
                        Depth out;
                        const bool same =
                            p.state != 0 && p.state == q.state && q.state == r.state && r.state == s.state;
                        const bool anyData = p.state || q.state || r.state || s.state;
                        if (same) {
                            const double sum = static_cast<double>(p.mean) + q.mean + r.mean + s.mean;
                            out.mean = static_cast<float>(sum * 0.25);
                            out.lo = std::min({p.lo, q.lo, r.lo, s.lo});
                            out.hi = std::max({p.hi, q.hi, r.hi, s.hi});
                            if (static_cast<double>(out.hi) - out.mean <= tolerance &&
                                out.mean - static_cast<double>(out.lo) <= tolerance)
                                out.state = p.state;
                        }
                        if (out.state == 0 && anyData)
                            forbidden[worker].push_back({l, {((tx * side) >> l) + x, ((ty * side) >> l) + y}});
                        cur[y * n + x] = out;
                    }
            }
        }
    });
    for (const auto& list : forbidden)
        for (const auto& [l, xy] : list) mask.forbid(l, xy.first, xy.second);
}

}  // namespace detail

namespace {

using detail::restrictByStep;

// The grid's geometry for a raster: origin at its south-west corner, finest cell = its pixel.
// `windowed`: the raster's values are read window by window (RasterWindows), not held in terrain.values.
Grid shapeFor(const Raster& terrain, bool water, const BuildOptions& options, int& rootLevel, int& maxLevel,
              bool windowed = false) {
    if (terrain.width == 0 || terrain.height == 0 ||
        (!windowed && terrain.values.size() != terrain.width * terrain.height))
        throw Error("raster is empty or inconsistent");
    checkToleranceM(options.toleranceM);
    if (!(terrain.pixelSizeM > 0)) throw Error("pixel size must be positive");
    if (!terrain.roundingM.empty() && terrain.roundingM.size() != terrain.values.size())
        throw Error("terrain rounding does not match the terrain raster");
    rootLevel = 0;
    while ((size_t{1} << rootLevel) < std::max(terrain.width, terrain.height)) ++rootLevel;
    if (rootLevel > kMaxRootLevel)
        throw Error("raster of " + std::to_string(terrain.width) + " x " + std::to_string(terrain.height) +
                    " pixels is too large for one grid");
    if (options.maxLevel < 0) throw Error("coarsest level " + std::to_string(options.maxLevel) + " is negative");
    // A coarsest level above the root's (--max-cell wider than the domain) changes nothing: no cell is larger than the
    // root node, and the grid records the level its cells can reach.
    maxLevel = std::min(options.maxLevel, rootLevel);
    Grid g;
    g.originWorldX = terrain.westWorld;
    g.originWorldY = terrain.southWorld();
    g.finestCellM = terrain.pixelSizeM;
    g.rootLevel = rootLevel;
    g.minLevel = 0;
    g.maxLevel = maxLevel;
    g.crsWkt = terrain.crsWkt;
    g.crsName = terrain.crsName;
    if (water) {
        g.layers.push_back({"water_depth", "m"});
        g.values.emplace_back();
    }
    g.stats.sourceWidth = terrain.width;
    g.stats.sourceHeight = terrain.height;
    g.stats.toleranceM = options.toleranceM;
    return g;
}

void checkStepRaster(const Raster& terrain, const Raster& d, size_t k) {
    if (d.width != terrain.width || d.height != terrain.height || d.values.size() != terrain.values.size())
        throw Error("water step " + std::to_string(k) + ": depth raster does not match the terrain raster's geometry");
}

// The merge mask of every step, each step's raster read once (WaterSteps::load), or nullopt without water.
std::optional<MergeMask> maskOf(const Raster& terrain, const WaterSteps* steps, const BuildOptions& opt, int maxLevel) {
    if (!steps || steps->count == 0) return std::nullopt;
    MergeMask mask(terrain.width, terrain.height, maxLevel);
    Progress progress("water steps: wet/dry edges", steps->count, opt.progress && steps->count > 1);
    for (size_t k = 0; k < steps->count; ++k) {
        const Raster d = steps->load(k);
        checkStepRaster(terrain, d, k);
        restrictByStep(wholeOf(d), opt.toleranceM, maxLevel, opt.threads, mask);
        progress.advance(1);
    }
    progress.finish();
    return mask;
}

// One step's depth per cell (cellMean) for the cells `codes`: the wet ones (> 0) in stored form, and the largest
// |pixel - cell depth| over the pixels the cells cover. viewOf(ix, iy): the depths (the whole raster, or the rank's
// block) holding the cell whose south-west pixel is (ix, iy), and so all its pixels.
WaterStepData stepValues(const std::function<const Block&(size_t ix, size_t iy)>& viewOf,
                         std::span<const uint64_t> codes, double timeS, unsigned threads, double& maxDev) {
    struct Part {
        std::vector<uint32_t> wet;
        std::vector<float> depth;
        double maxDev = 0;
    };
    const size_t chunk = size_t{1} << 16;
    std::vector<Part> parts((codes.size() + chunk - 1) / chunk);
    parallelFor(parts.size(), 1, threads, [&](size_t b, size_t e, unsigned) {
        for (size_t c = b; c < e; ++c) {
            Part& part = parts[c];
            for (size_t i = c * chunk; i < std::min(codes.size(), (c + 1) * chunk); ++i) {
                const uint64_t key = codeKey(codes[i]);
                const int level = codeLevel(codes[i]);
                const size_t ix = mortonX(key), iy = mortonY(key), span = size_t{1} << level;
                const Block& d = viewOf(ix, iy);
                const float m = cellMean(d, ix, iy, level);
                for (size_t y = iy; y < iy + span; ++y)
                    for (size_t x = ix; x < ix + span; ++x)
                        part.maxDev = std::max(part.maxDev, std::abs(static_cast<double>(depthAt(d, x, y)) - m));
                if (m > 0) {
                    part.wet.push_back(static_cast<uint32_t>(i));
                    part.depth.push_back(m);
                }
            }
        }
    });
    WaterStepData out;
    out.timeS = timeS;
    out.values.resize(1);
    for (const Part& p : parts) {
        out.wet.insert(out.wet.end(), p.wet.begin(), p.wet.end());
        out.values[0].insert(out.values[0].end(), p.depth.begin(), p.depth.end());
        maxDev = std::max(maxDev, p.maxDev);
    }
    return out;
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
        g_.values[0].reserve(cellCount);
    }
    void append(std::span<const uint64_t> codes, const std::vector<std::span<const float>>& values) override {
        g_.codes.insert(g_.codes.end(), codes.begin(), codes.end());
        g_.values[0].insert(g_.values[0].end(), values[0].begin(), values[0].end());
    }

private:
    Grid& g_;
};

// Streams the cells into a GridFileWriter; keeps their codes (8 bytes a cell) when water steps follow.
class FileSink : public CellSink {
public:
    FileSink(const std::string& path, const Grid& shape, size_t steps) : path_(path), shape_(shape), steps_(steps) {}
    void begin(uint64_t cellCount) override {
        if (cellCount == 0) throw Error("the raster holds no valid pixel (all nodata): nothing to build");
        if (steps_ > 0 && cellCount > UINT32_MAX)
            throw Error(std::to_string(cellCount) + " cells: a grid with water steps holds at most 2^32 - 1 cells");
        writer_ = std::make_unique<GridFileWriter>(path_, shape_, cellCount, steps_);
        if (steps_ > 0 && !ranks::distributed()) codes.reserve(cellCount);  // under mpirun rank 0 keeps its own share
    }
    void append(std::span<const uint64_t> c, const std::vector<std::span<const float>>& values) override {
        writer_->append(c, values);
        keepOwn(c);
    }
    // Water steps: each rank computes the depths of its own cells (buildFile), so it keeps their codes.
    void keepOwn(std::span<const uint64_t> c) override {
        if (steps_ > 0) codes.insert(codes.end(), c.begin(), c.end());
    }
    GridFileWriter& writer() { return *writer_; }
    GridFileWriter* sharedWriter() override { return writer_.get(); }
    const Grid* fileShape() const override { return &shape_; }
    std::vector<uint64_t> codes;  // with water steps: the cells appended or kept, in order

private:
    std::string path_;
    const Grid& shape_;
    size_t steps_;
    std::unique_ptr<GridFileWriter> writer_;
};

}  // namespace

Grid buildGrid(const Raster& terrain, const Raster* waterDepth, const BuildOptions& options) {
    int rootLevel = 0, maxLevel = 0;
    Grid g = shapeFor(terrain, waterDepth != nullptr, options, rootLevel, maxLevel);
    WaterSteps one;
    if (waterDepth) {
        checkStepRaster(terrain, *waterDepth, 0);
        one.count = 1;
        one.timesS = {0.0};
        one.load = [&](size_t) { return *waterDepth; };
    }
    const std::optional<MergeMask> mask = maskOf(terrain, waterDepth ? &one : nullptr, options, maxLevel);
    GridSink sink(g);
    if (options.cellElevations)
        options.cellElevations->assign(terrain.values.size(), std::numeric_limits<float>::quiet_NaN());
    Stats st = Builder(terrain, nullptr, mask ? &*mask : nullptr, options, rootLevel, maxLevel).run(sink);
    if (g.cellCount() == 0) throw Error("the raster holds no valid pixel (all nodata): nothing to build");
    if (waterDepth) {
        g.values[1].clear();
        const Block whole = wholeOf(*waterDepth);
        const WaterStepData data =
            stepValues([&](size_t, size_t) -> const Block& { return whole; }, g.codes, 0.0, options.threads, st.maxDev);
        selectStep(g, data, 0);
    }
    fillStats(st, g.stats);
    assert(g.validate().empty());
    return g;
}

namespace {

// buildGridFile, its pixels from terrain.values or read window by window (`windows`; without water steps).
BuildSummary buildFile(const Raster& terrain, const RasterWindows* windows, const WaterSteps* steps,
                       const BuildOptions& options, const std::string& path, const IngestStats& extraStats) {
    const Stopwatch clock;
    int rootLevel = 0, maxLevel = 0;
    const size_t stepCount = steps ? steps->count : 0;
    if (steps && steps->timesS.size() != stepCount)
        throw Error("water steps: " + std::to_string(steps->timesS.size()) + " times for " + std::to_string(stepCount) +
                    " steps");
    for (size_t k = 1; k < stepCount; ++k)
        if (!(steps->timesS[k] > steps->timesS[k - 1]))
            throw Error("water step times must increase strictly: step " + std::to_string(k) + " at " +
                        std::to_string(steps->timesS[k]) + " s follows " + std::to_string(steps->timesS[k - 1]) + " s");
    BuildSummary out;
    if (windows && options.cellElevations) throw Error("internal: a raster read by windows is built without a trace");
    out.shape = shapeFor(terrain, stepCount > 0, options, rootLevel, maxLevel, windows != nullptr);
    // Steps read by windows: each rank makes the masks of its own nodes (Builder::run).
    const std::optional<MergeMask> mask = windows ? std::nullopt : maskOf(terrain, steps, options, maxLevel);
    FileSink sink(path, out.shape, stepCount);
    const bool root = ranks::rank() == 0;  // under mpirun, rank 0 commits the file (Builder::run)
    if (options.cellElevations && root)
        options.cellElevations->assign(terrain.values.size(), std::numeric_limits<float>::quiet_NaN());
    Builder builder(terrain, windows, mask ? &*mask : nullptr, options, rootLevel, maxLevel);
    Stats st = builder.run(sink);
    for (uint64_t c : st.perLevel) out.cellCount += c;  // on rank 0 every rank's cells, on another its share
    if (stepCount > 0) {
        // Each step's depth per cell: every rank over its own cells (the codes its sink kept), the wet ones sent to
        // rank 0 in rank order, which is the cells' order.
        if (sink.codes.size() < st.ownCells) throw Error("internal: a rank kept fewer codes than it has cells");
        const std::span<const uint64_t> own = std::span<const uint64_t>(sink.codes).first(st.ownCells);
        const Stopwatch stepClock;
        Progress progress("water steps: depth per cell", stepCount, options.progress && root);
        for (size_t k = 0; k < stepCount; ++k) {
            WaterStepData data;
            double maxDev = 0;
            ranks::together([&] {
                if (windows) {  // the same windows of the step as of the terrain: every own cell lies in one
                    std::vector<std::vector<float>> storage;
                    const std::vector<Block> views = builder.stepBlocks(k, storage, false);
                    auto viewOf = [&](size_t ix, size_t iy) -> const Block& {
                        return views[builder.blockIndexAt(ix, iy)];
                    };
                    data = stepValues(viewOf, own, steps->timesS[k], options.threads, maxDev);
                } else {
                    const Raster d = steps->load(k);
                    checkStepRaster(terrain, d, k);
                    const Block whole = wholeOf(d);
                    data = stepValues([&](size_t, size_t) -> const Block& { return whole; }, own, steps->timesS[k],
                                      options.threads, maxDev);
                }
                for (uint32_t& i : data.wet) i = uint32_t(i + st.firstCell);  // < 2^32: FileSink::begin
            });
            if (!root) {  // after the agreement: rank 0 receives every piece
                ranks::sendToRoot(data.wet);
                ranks::sendToRoot(data.values[0]);
                ranks::sendToRoot(std::vector<double>{maxDev});
                continue;
            }
            st.maxDev = std::max(st.maxDev, maxDev);
            std::string bad;  // said once every rank's pieces are in: a sender is never left blocked
            for (int r = 1; r < ranks::count(); ++r) {
                const std::vector<uint32_t> wet = ranks::receiveVectorFrom<uint32_t>(r);
                const std::vector<float> depth = ranks::receiveVectorFrom<float>(r);
                const std::vector<double> dev = ranks::receiveVectorFrom<double>(r);
                if (depth.size() != wet.size() || dev.size() != 1) {
                    if (bad.empty())
                        bad = fmt::format("rank {} sent {} depths for {} wet cells of water step {}", r + 1,
                                          depth.size(), wet.size(), k);
                    continue;
                }
                data.wet.insert(data.wet.end(), wet.begin(), wet.end());
                data.values[0].insert(data.values[0].end(), depth.begin(), depth.end());
                st.maxDev = std::max(st.maxDev, dev[0]);
            }
            if (!bad.empty()) throw Error(bad);
            StepInfo info;
            info.timeS = data.timeS;
            info.wetCells = data.wet.size();
            out.steps.push_back(info);
            out.stepBytes += 8 * data.wet.size();
            sink.writer().appendStep(data);
            progress.advance(1);
        }
        progress.finish();
        if (ranks::distributed())
            ranks::log("hc-ingest", fmt::format("water steps: the depths of its {} cells in {} step{}, {:.3f} s",
                                                own.size(), stepCount, stepCount == 1 ? "" : "s", stepClock.seconds()));
    }
    if (!root) return out;
    IngestStats stats = extraStats;
    stats.sourceWidth = out.shape.stats.sourceWidth;
    stats.sourceHeight = out.shape.stats.sourceHeight;
    stats.toleranceM = options.toleranceM;
    fillStats(st, stats);
    stats.seconds = extraStats.seconds + clock.seconds();
    sink.writer().commit(stats);
    out.shape.stats = stats;
    out.shape.steps = out.steps;
    out.cellsPerLevel = st.perLevel;
    out.wetCells = out.steps.empty() ? 0 : out.steps.back().wetCells;
    return out;
}

}  // namespace

BuildSummary buildGridFile(const Raster& terrain, const WaterSteps* steps, const BuildOptions& options,
                           const std::string& path, const IngestStats& extraStats) {
    return buildFile(terrain, nullptr, steps, options, path, extraStats);
}

BuildSummary buildGridFile(const RasterWindows& terrain, const BuildOptions& options, const std::string& path,
                           const IngestStats& extraStats) {
    if (!terrain.read) throw Error("internal: raster windows without a reader");
    WaterSteps steps;  // read by the builder through terrain.readStep
    steps.count = terrain.stepTimesS.size();
    steps.timesS = terrain.stepTimesS;
    return buildFile(terrain.shape, &terrain, steps.count ? &steps : nullptr, options, path, extraStats);
}

}  // namespace hc::ingest
