// The approximation pass, per cascade (approximate()): the texels visible in the last frame too copied from it, then
// those the surface pyramid holds copied or interpolated (approximate_copy.cpp, approximate_interpolate.cpp), then the
// Gaussian RBF sum (docs/design.md section 3) at the rest (approximate_sum.cpp): over the scene's cells in memory, or
// out of core over blocks of texels whose cells are read from the grid file (here). What these files share is in
// approximate_internal.h. The water at the shores (CascadeTextures::extendWaterToShores) and the cascades' max mipmaps
// (Heightfield::buildMip, CascadeTextures::buildBothMip) are made here too, after the pass.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <mutex>
#include <utility>
#include <vector>

#include "approximate_internal.h"
#include "heightcast/core/error.h"
#include "heightcast/core/parallel.h"
#include "heightcast/influence/region.h"
#include "heightcast/render/gpu_layout.h"
#include "heightcast/render/water_rule.h"

namespace hc::render::detail {
namespace {

// approximate()'s mode, named once from its optional arguments (frame.h keeps that form for its callers), so that no
// stage below tells the mode by a null pointer.
struct ApproximationPlan {
    enum class Output {
        kTextures,      // every texel into tex: those kept from `reuse` (if any) copied, the others evaluated
        kRows,          // `rows` (RowFill): only the spans to evaluate written, the texels kept counted, not copied
        kRowsAndTiles,  // kRows, and the pyramid's copies marked in `tiles` (PyramidTiles), not written
    };
    Output output = Output::kTextures;
    const TexelReuse* reuse = nullptr;     // the last frame's texels to keep; nullptr: none (a fresh cascade)
    int interpolateLevels = 0;             // levels above the cascade's a texel may be interpolated from
    std::vector<RowFill>* rows = nullptr;  // kRows and kRowsAndTiles
    PyramidTiles* tiles = nullptr;         // kRowsAndTiles

    static ApproximationPlan of(const TexelReuse* reuse, int interpolateLevels, std::vector<RowFill>* rows,
                                PyramidTiles* tiles) {
        if (tiles && !rows) throw Error("approximate: pyramid tiles without row spans (a bug)");
        const Output output = !rows ? Output::kTextures : tiles ? Output::kRowsAndTiles : Output::kRows;
        return {output, reuse, interpolateLevels, rows, tiles};
    }
};

// The texels [f, l] of row j of c that were visible in `reuse` too (empty: l < f), and the row's spans left to
// evaluate.
Todo keptSpan(const Cascade& c, const TexelReuse* reuse, int j, int& f, int& l) {
    const Cascade::RowSpan& r = c.rows[size_t(j)];
    Todo t{{r.first, r.last}, {0, -1}};
    f = 0, l = -1;
    const int jp = reuse ? j + reuse->dj : -1;
    if (reuse && r.first <= r.last && jp >= 0 && jp < reuse->cascade->n) {
        const Cascade::RowSpan& p = reuse->cascade->rows[size_t(jp)];
        f = std::max(r.first, p.first - reuse->di), l = std::min(r.last, p.last - reuse->di);
    }
    if (f <= l) t = {{r.first, f - 1}, {l + 1, r.last}};
    return t;
}

// Writes every texel of tex: the visible texels of c that were visible in `reuse` (if any) copied, their count
// added to `copied`; every other one "no surface" (-inf, depth 0) until evaluated. Returns the spans left to
// evaluate. reuse->tex may be tex itself where the side is the same (renderFrame hands the last frame's storage on, so
// a moving camera allocates nothing): this frame's row j reads the last frame's row j + dj, so rows are written in the
// order that reads each of the last frame's rows before overwriting it. A cascade of another side reads storage of
// its own (rows of reuse->cascade->n texels).
// With `rows` (RowFill; the plan's kRows and kRowsAndTiles): each row's spans into it, and only the spans left to
// evaluate written ("no surface"): the texels kept from `reuse` are counted, not copied (the caller keeps them
// elsewhere), and the others left as they are.
std::vector<Todo> copyReusedTexels(const Cascade& c, const ApproximationPlan& plan, CascadeTextures& tex,
                                   uint64_t& copied, unsigned threads) {
    const TexelReuse* const reuse = plan.reuse;
    const int n = c.n;
    const float noSurface = -std::numeric_limits<float>::infinity();
    std::vector<Todo> todo(static_cast<size_t>(n));
    auto clearSpan = [&](size_t row, int lo, int hi) {  // [lo, hi] of a row "no surface"
        if (hi < lo) return;
        std::fill(&tex.terrain.h[row + size_t(lo)], &tex.terrain.h[row + size_t(hi)] + 1, noSurface);
        if (tex.hasWater) {
            std::fill(&tex.water.h[row + size_t(lo)], &tex.water.h[row + size_t(hi)] + 1, noSurface);
            std::fill(&tex.depth[row + size_t(lo)], &tex.depth[row + size_t(hi)] + 1, 0.0f);
        }
    };
    if (plan.output != ApproximationPlan::Output::kTextures) {  // the spans only, the rows on all workers
        std::vector<RowFill>& rows = *plan.rows;
        rows = rowFills(c, reuse, copied);
        parallelFor(size_t(n), 64, threads, [&](size_t b, size_t e, unsigned) {
            for (size_t j = b; j < e; ++j) {
                const RowFill& r = rows[j];
                todo[j] = {r.a, r.b};
                clearSpan(j * size_t(n), r.a.first, r.a.last), clearSpan(j * size_t(n), r.b.first, r.b.last);
            }
        });
        return todo;
    }
    if (!reuse) {  // a fresh cascade: every texel "no surface", the rows on all workers (three textures to write)
        parallelFor(size_t(n), 64, threads, [&](size_t b, size_t e, unsigned) {
            for (size_t j = b; j < e; ++j) {
                const Cascade::RowSpan& r = c.rows[j];
                todo[j].a.first = r.first, todo[j].a.last = r.last;
                clearSpan(j * size_t(n), 0, n - 1);
            }
        });
        return todo;
    }
    if (reuse->tex == &tex && reuse->cascade->n != n)
        throw hc::Error("approximate: a cascade kept in place changed its side (a bug)");
    const bool upwards = reuse->dj < 0;
    for (int step = 0; step < n; ++step) {
        const int j = upwards ? n - 1 - step : step;
        int f, l;  // the copied texels of row j
        Todo& t = todo[size_t(j)];
        t = keptSpan(c, reuse, j, f, l);
        if (f <= l) copied += uint64_t(l - f + 1);
        const int jp = j + reuse->dj;
        const size_t row = size_t(j) * size_t(n);
        auto place = [&](Texels& to, const Texels& from, float none) {
            float* const out = &to[row];
            if (l < f) {
                std::fill(out, out + n, none);
                return;
            }
            const size_t at = size_t(jp) * size_t(reuse->cascade->n) + size_t(f + reuse->di);
            std::memmove(out + f, &from[at], size_t(l - f + 1) * sizeof(float));  // may overlap (in place)
            std::fill(out, out + f, none);
            std::fill(out + l + 1, out + n, none);
        };
        place(tex.terrain.h, reuse->tex->terrain.h, noSurface);
        if (tex.hasWater) {
            place(tex.water.h, reuse->tex->water.h, noSurface);
            place(tex.depth, reuse->tex->depth, 0.0f);
        }
    }
    return todo;
}

// Out of core, the texels left to evaluate are taken a block of kOutOfCoreBlock^2 at a time: the block's cells,
// with those whose kernels reach it, are read from the grid file and their lists built (influence/region.h), then
// dropped. 256: a block of a fresh far cascade (texels up to 2x the cells) reads a few hundred thousand cells at most,
// so memory follows the block, and the per-block overhead (the kernel margin read twice at block edges) stays a small
// share.
constexpr int kOutOfCoreBlock = 256;
// Blocks whose texels to evaluate fill less than 1/kOutOfCoreSplit of them are split, down to kOutOfCoreMinBlock a
// side: a block's region holds every cell under it, and in a far cascade the texels to sum (over coarse cells) sit
// beside copied ones over fine cells, whose cells a loose block would read and build lists for in vain.
constexpr uint64_t kOutOfCoreSplit = 4;
constexpr int kOutOfCoreMinBlock = 16;

// Clears `need` at the texels of r whose pyramid tile (level t, its lattice: copyPyramidTexels) is not stored because
// its quadtree node holds no cell at all: the surface is undefined at every texel there (a hole, or outside the data),
// so no cell need be read for them (EmptyTiles). Texels outside the domain are cleared too.
void dropEmptyTiles(const GridRegionReader& file, const Cascade& c, int t, const TexelRange& r,
                    std::vector<uint8_t>& need) {
    EmptyTiles empty(file, t);
    if (!empty.asks()) return;
    const double i0 = std::round(c.x0 / c.texelM), j0 = std::round(c.y0 / c.texelM);
    for (int j = r.j0; j <= r.j1; ++j)
        for (int i = r.i0; i <= r.i1; ++i) {
            uint8_t& flag = need[size_t(j) * size_t(c.n) + size_t(i)];
            if (!flag) continue;
            const double gi = i0 + i, gj = j0 + j;
            if (gi < 0 || gj < 0 || empty(uint64_t(gi), uint64_t(gj))) flag = 0;
        }
}

// The region out of core for the texels `need`ed in block r: the cells whose squares meet the block grown by their
// kernel reach (GridRegionReader::region), less those that reach no needed texel (their square grown by their reach
// holds none: a summed-area table of `need` over the block answers each in four reads), with the lists of the rest.
// A far cascade's texels to sum lie over coarse cells beside copied texels over fine ones, whose cells the box alone
// would bring in and build lists for in vain (Marchfeld's far cascade: 1.0 M cells read for 64 k texels). A cell kept
// is one that may weigh at a needed texel, so the texels' sums are what the whole grid gives. Adds the cells read
// from the file to *cellsRead.
influence::SurfaceRegion readNeededRegion(const GridRegionReader& file, const influence::KernelParams& params,
                                          const std::vector<double>& reach, const Cascade& c,
                                          const std::vector<uint8_t>& need, const TexelRange& r, uint64_t& cellsRead) {
    const double s = c.texelM;
    Grid all = file.region({c.x0 + r.i0 * s, c.y0 + r.j0 * s, c.x0 + r.i1 * s, c.y0 + r.j1 * s}, reach);
    cellsRead += all.cellCount();
    const int w = r.i1 - r.i0 + 1, h = r.j1 - r.j0 + 1;
    std::vector<uint32_t> sat(size_t(w + 1) * size_t(h + 1),
                              0);  // sat[(j + 1) (w + 1) + i + 1]: needed texels in [0, i] x [0, j]
    for (int j = 0; j < h; ++j)
        for (int i = 0; i < w; ++i)
            sat[size_t(j + 1) * size_t(w + 1) + size_t(i + 1)] =
                sat[size_t(j) * size_t(w + 1) + size_t(i + 1)] + sat[size_t(j + 1) * size_t(w + 1) + size_t(i)] -
                sat[size_t(j) * size_t(w + 1) + size_t(i)] + need[size_t(r.j0 + j) * size_t(c.n) + size_t(r.i0 + i)];
    auto first = [&](double v, double origin, int lo,
                     int count) {  // first texel index at or after v, clamped to [lo, lo + count]
        return std::clamp(int(std::ceil((v - origin) / s)), lo, lo + count);
    };
    auto last = [&](double v, double origin, int lo,
                    int count) {  // last texel index at or before v, clamped to [lo - 1, lo + count - 1]
        return std::clamp(int(std::floor((v - origin) / s)), lo - 1, lo + count - 1);
    };
    Grid kept = all;
    kept.codes.clear();
    for (auto& v : kept.values) v.clear();
    for (size_t k = 0; k < all.cellCount(); ++k) {
        const Grid::Square q = all.cellSquare(k);
        const double m = reach[size_t(all.level(k))] + s;  // a texel's rounding aside, one texel of slack
        const int ia = first(q.x0 - m, c.x0, r.i0, w), ib = last(q.x1 + m, c.x0, r.i0, w);
        const int ja = first(q.y0 - m, c.y0, r.j0, h), jb = last(q.y1 + m, c.y0, r.j0, h);
        if (ia > ib || ja > jb) continue;
        const size_t x0 = size_t(ia - r.i0), x1 = size_t(ib - r.i0 + 1), y0 = size_t(ja - r.j0),
                     y1 = size_t(jb - r.j0 + 1);
        const size_t W = size_t(w + 1);
        if (sat[y1 * W + x1] + sat[y0 * W + x0] - sat[y0 * W + x1] - sat[y1 * W + x0] == 0) continue;
        kept.codes.push_back(all.codes[k]);
        for (size_t l = 0; l < all.values.size(); ++l) kept.values[l].push_back(all.values[l][k]);
    }
    influence::SurfaceRegion out;
    out.lists = influence::buildInfluenceLists(kept, params, 1, false);
    out.grid = std::move(kept);
    return out;
}

// What the stages of one approximate() share: the scene, the cascade and its textures.
struct CascadeJob {
    const Scene& scene;
    const Cascade& c;
    CascadeTextures& tex;
    double waterMinDepthM;
    unsigned threads;
};

// The textures sized only: copyReusedTexels writes every texel (with `rows`, every texel to evaluate).
void sizeTextures(const Scene& scene, int n, CascadeTextures& tex) {
    tex.hasWater = scene.hasWater();
    tex.terrain.n = tex.water.n = n;
    tex.terrain.h.resize(size_t(n) * size_t(n));
    if (tex.hasWater) {
        tex.water.h.resize(size_t(n) * size_t(n));
        tex.depth.resize(size_t(n) * size_t(n));
    }
}

// The texels left to the kernels: their box (empty: i1 < 0) and count.
struct TexelsToSum {
    TexelRange box;
    uint64_t texels;
};

// Marks in `need` the texels of the spans of `todo` that `copied` does not mark: those left to the kernels. On all
// cores where the spans are long (a fresh cascade 0: hundreds of thousands of texels to look at), else on this one (a
// moving frame's few new texels: waking the workers would cost more).
TexelsToSum markTexelsToSum(const std::vector<Todo>& todo, const std::vector<uint8_t>& copied,
                            std::vector<uint8_t>& need, int n, unsigned threads) {
    struct Box {
        int i0, i1, j0, j1;
        uint64_t texels;
    };
    uint64_t spanTexels = 0;
    for (const Todo& t : todo) spanTexels += uint64_t(t.a.count() + t.b.count());
    const unsigned boxThreads = spanTexels >= (uint64_t{1} << 16) ? threads : 1;
    std::vector<Box> boxes(resolveThreads(boxThreads), Box{n, -1, n, -1, 0});
    parallelFor(size_t(n), 64, boxThreads, [&](size_t b, size_t e, unsigned worker) {
        Box x = boxes[worker];  // a copy: the workers' boxes share cache lines
        for (int j = int(b); j < int(e); ++j) {
            const Todo& t = todo[size_t(j)];
            for (auto [lo, hi] : {std::pair{t.a.first, t.a.last}, {t.b.first, t.b.last}})
                for (int i = lo; i <= hi; ++i) {
                    const size_t at = size_t(j) * size_t(n) + size_t(i);
                    if (copied[at]) continue;
                    need[at] = 1;
                    x = {std::min(x.i0, i), std::max(x.i1, i), std::min(x.j0, j), std::max(x.j1, j), x.texels + 1};
                }
        }
        boxes[worker] = x;
    });
    int i0 = n, i1 = -1, j0 = n, j1 = -1;
    uint64_t todoTexels = 0;
    for (const Box& x : boxes)
        i0 = std::min(i0, x.i0), i1 = std::max(i1, x.i1), j0 = std::min(j0, x.j0), j1 = std::max(j1, x.j1),
        todoTexels += x.texels;
    return {{i0, i1, j0, j1}, todoTexels};
}

// The cells of g whose texels in r (`texels` of them `need`ed) are summed, into `cells`: each texel's cell located
// where those texels are sparse in r (kSparseTodo), else the cells of r's box.
void cellsToSum(const Grid& g, const Cascade& c, const std::vector<uint8_t>& need, const TexelRange& r, uint64_t texels,
                unsigned threads, std::vector<uint32_t>& cells) {
    const double s = c.texelM;
    const uint64_t boxTexels = uint64_t(r.i1 - r.i0 + 1) * uint64_t(r.j1 - r.j0 + 1);
    if (texels * kSparseTodo < boxTexels)
        cellsUnderTexels(g, c, need, r, threads, cells);
    else
        g.cellsInBox(c.x0 + r.i0 * s, c.y0 + r.j0 * s, c.x0 + r.i1 * s, c.y0 + r.j1 * s, cells);
}

// In memory: the kernels summed at the texels `need`ed, over the scene's own cells and lists.
void sumInMemory(const CascadeJob& job, const std::vector<Todo>& todo, const std::vector<uint8_t>& need,
                 const TexelsToSum& sum, ApproximationWork& work) {
    const Scene& scene = job.scene;
    std::vector<uint32_t> cells;
    cellsToSum(scene.grid(), job.c, need, sum.box, sum.texels, job.threads, cells);
    work.cellsVisited += cells.size();
    sumTexels({scene.grid(), scene.lists(), scene.kernels(), scene.waterLayer()}, job.c, todo, need, sum.box, cells,
              job.tex, job.waterMinDepthM, job.threads, &work.gaussians);
}

// Blocks of at most kOutOfCoreBlock^2 texels holding the texels `need`ed in `all`, shrunk to the texels they need and
// split while those are sparse, so that a region read follows the texels (a frame's few stray texels along a hole's
// edge must not read the cells of whole blocks around them). Each block's count of texels into blockTexels.
std::vector<TexelRange> splitIntoBlocks(const std::vector<uint8_t>& need, int n, const TexelRange& all,
                                        std::vector<uint64_t>& blockTexels) {
    std::vector<TexelRange> blocks, pending{all};
    while (!pending.empty()) {
        TexelRange r = pending.back();
        pending.pop_back();
        uint64_t count = 0;
        TexelRange box{r.i1 + 1, r.i0 - 1, r.j1 + 1, r.j0 - 1};
        for (int j = r.j0; j <= r.j1; ++j)
            for (int i = r.i0; i <= r.i1; ++i)
                if (need[size_t(j) * size_t(n) + size_t(i)]) {
                    ++count;
                    box = {std::min(box.i0, i), std::max(box.i1, i), std::min(box.j0, j), std::max(box.j1, j)};
                }
        if (count == 0) continue;
        r = box;
        const int w = r.i1 - r.i0 + 1, h = r.j1 - r.j0 + 1;
        const uint64_t area = uint64_t(w) * uint64_t(h);
        if (area > uint64_t(kOutOfCoreBlock) * kOutOfCoreBlock ||
            (count * kOutOfCoreSplit < area && std::max(w, h) > kOutOfCoreMinBlock)) {
            const int mi = r.i0 + w / 2, mj = r.j0 + h / 2;
            for (const TexelRange& q : {TexelRange{r.i0, mi - 1, r.j0, mj - 1}, TexelRange{mi, r.i1, r.j0, mj - 1},
                                        TexelRange{r.i0, mi - 1, mj, r.j1}, TexelRange{mi, r.i1, mj, r.j1}})
                if (q.i0 <= q.i1 && q.j0 <= q.j1) pending.push_back(q);
            continue;
        }
        blocks.push_back(r);
        blockTexels.push_back(count);
    }
    return blocks;
}

// Out of core: the kernels summed at the texels `need`ed (less those over empty tiles), block by block, each block's
// cells and lists read from the grid file (readNeededRegion).
void sumOutOfCore(const CascadeJob& job, const std::vector<Todo>& todo, std::vector<uint8_t>& need,
                  const TexelsToSum& sum, ApproximationWork& work) {
    const Scene& scene = job.scene;
    const Cascade& c = job.c;
    // Out of core: less the texels in pyramid tiles whose nodes hold no cell.
    if (work.pyramidLevel >= 0) dropEmptyTiles(*scene.file(), c, work.pyramidLevel, sum.box, need);
    std::vector<uint64_t> blockTexels;
    const std::vector<TexelRange> blocks = splitIntoBlocks(need, c.n, sum.box, blockTexels);
    // The blocks on the workers, one each at a time, single-threaded inside: most are small (a moving camera's strips,
    // the scattered texels of a far cascade over coarse cells), where starting threads per block cost more than the
    // block (Marchfeld's far cascade: 1.1 s for 64 k texels that way). Blocks hold disjoint texels.
    struct Tally {
        uint64_t regions = 0, cellsRead = 0, cellsVisited = 0, gaussians = 0;
    };
    std::vector<Tally> tally(resolveThreads(job.threads));
    const std::vector<double> reach = influence::kernelReachM(scene.grid(), scene.params());
    parallelFor(blocks.size(), 1, job.threads, [&](size_t b, size_t e, unsigned worker) {
        Tally& t = tally[worker];
        std::vector<uint32_t> blockCells;
        for (size_t k = b; k < e; ++k) {
            const TexelRange& r = blocks[k];
            const influence::SurfaceRegion region =
                readNeededRegion(*scene.file(), scene.params(), reach, c, need, r, t.cellsRead);
            ++t.regions;
            if (region.grid.cellCount() == 0) continue;
            const std::vector<Scene::CellKernel> kernels = Scene::kernelsOf(region.grid, scene.params());
            blockCells.clear();
            cellsToSum(region.grid, c, need, r, blockTexels[k], 1, blockCells);
            t.cellsVisited += blockCells.size();
            sumTexels({region.grid, region.lists, kernels, scene.waterLayer()}, c, todo, need, r, blockCells, job.tex,
                      job.waterMinDepthM, 1, &t.gaussians);
        }
    });
    for (const Tally& t : tally)
        work.regionsRead += t.regions, work.cellsRead += t.cellsRead, work.cellsVisited += t.cellsVisited,
            work.gaussians += t.gaussians;
}

}  // namespace

void CascadeTextures::extendWaterToShores(unsigned threads) {
    if (!hasWater) return;
    const size_t n = size_t(water.n);
    constexpr float kNone = -std::numeric_limits<float>::infinity();
    // Each texel's level where its water stands above its terrain, else -inf; then each texel whose water does not
    // takes the largest of those around it (3 x 3, itself -inf), as the column maxima of three rows and their maxima
    // along the row: the loops vectorise, and they read no texel another worker writes.
    Texels standing(n * n);
    parallelFor(n, 64, threads, [&](size_t b, size_t e, unsigned) {
        for (size_t k = b * n; k < e * n; ++k)
            standing[k] = water::standsAbove(water.h[k], terrain.h[k]) ? water.h[k] : kNone;
    });
    parallelFor(n, 64, threads, [&](size_t b, size_t e, unsigned) {
        std::vector<float> column(n + 2, kNone);  // column[i + 1]: the largest of texel i's column over rows j +- 1
        for (size_t j = b; j < e; ++j) {
            const float* above = &standing[(j > 0 ? j - 1 : j) * n];
            const float* row = &standing[j * n];
            const float* below = &standing[(j + 1 < n ? j + 1 : j) * n];
            for (size_t i = 0; i < n; ++i) column[i + 1] = std::max(std::max(above[i], row[i]), below[i]);
            float* w = &water.h[j * n];
            const float* t = &terrain.h[j * n];
            for (size_t i = 0; i < n; ++i) {
                const float around = std::max(std::max(column[i], column[i + 1]), column[i + 2]);
                w[i] = row[i] > kNone ? row[i] : water::shoreLevel(t[i], around);
            }
        }
    });
}

float CascadeTextures::errorEstimateM(unsigned threads) const {
    return std::max(terrain.errorEstimateM(threads), hasWater ? water.errorEstimateM(threads) : 0.0f);
}

void CascadeTextures::buildBothMip(unsigned threads) {
    bothMip.resize(terrain.mip.size());
    for (size_t l = 0; l < terrain.mip.size(); ++l) {
        const Texels &a = terrain.mip[l], &b = water.mip[l];
        bothMip[l].resize(a.size());
        parallelFor(a.size(), a.size() < kMipParallelNodes ? a.size() : size_t{1} << 16, threads,
                    [&](size_t begin, size_t end, unsigned) {
                        for (size_t i = begin; i < end; ++i) bothMip[l][i] = std::max(a[i], b[i]);
                    });
    }
}

void Heightfield::buildMip(unsigned threads) {
    // Sides n - 1, then halving to 1. The levels' storage is reused when this heightfield's was (CascadeCache).
    mipSide.clear();
    for (int side = n - 1;; side = (side + 1) / 2) {
        mipSide.push_back(side);
        if (side <= 1) break;
    }
    mip.resize(mipSide.size());
    // Row by row, each node the largest of the four texels around its patch (level 0) or of its children (a child
    // past the lower level's side is none); the rows of the large levels on the workers.
    for (size_t l = 0; l < mip.size(); ++l) {
        const int side = mipSide[l];
        Texels& level = mip[l];
        level.resize(size_t(side) * size_t(side));
        const size_t rowsPerChunk = size_t(side) * size_t(side) < kMipParallelNodes ? size_t(side) : 16;
        parallelFor(size_t(side), rowsPerChunk, threads, [&](size_t b, size_t e, unsigned) {
            for (size_t j = b; j < e; ++j) {
                float* out = &level[j * size_t(side)];
                if (l == 0) {
                    const float* r0 = &h[j * size_t(n)];
                    const float* r1 = r0 + n;
                    for (int i = 0; i < side; ++i)
                        out[i] = std::max(std::max(r0[i], r0[i + 1]), std::max(r1[i], r1[i + 1]));
                    continue;
                }
                const int lower = mipSide[l - 1];
                const Texels& lo = mip[l - 1];
                const float* c0 = &lo[2 * j * size_t(lower)];
                const float* c1 = 2 * j + 1 < size_t(lower) ? c0 + lower : nullptr;
                for (int i = 0; i < side; ++i) {
                    const int a = 2 * i, b1 = 2 * i + 1;
                    float m = c0[a];
                    if (b1 < lower) m = std::max(m, c0[b1]);
                    if (c1) m = std::max(m, b1 < lower ? std::max(c1[a], c1[b1]) : c1[a]);
                    out[i] = m;
                }
            }
        });
    }
}

float Heightfield::errorEstimateM(unsigned threads) const {
    if (n < 3) return 0;
    std::mutex mutex;
    float largest = 0;
    const size_t rows = size_t(n - 2);
    parallelFor(rows, std::max<size_t>(16, rows / 64), threads, [&](size_t b, size_t e, unsigned) {
        float m = 0;
        for (size_t j = b; j < e; ++j) {
            const float* r0 = &h[j * size_t(n)];
            const float* r1 = r0 + n;
            const float* r2 = r1 + n;
            for (int i = 0; i + 2 < n; ++i)
                m = std::max(m, gpu::patchErrorEstimateM(r0[i], r0[i + 1], r0[i + 2], r1[i], r2[i]));
        }
        const std::lock_guard<std::mutex> lock(mutex);
        largest = std::max(largest, m);
    });
    return largest;
}

std::vector<RowFill> rowFills(const Cascade& c, const TexelReuse* reuse, uint64_t& kept) {
    std::vector<RowFill> rows(size_t(c.n));
    for (int j = 0; j < c.n; ++j) {
        int f, l;
        const Todo t = keptSpan(c, reuse, j, f, l);
        rows[size_t(j)] = RowFill{{f, l}, t.a, t.b};
        if (f <= l) kept += uint64_t(l - f + 1);
    }
    return rows;
}

ApproximationWork approximate(const Scene& scene, const Cascade& c, CascadeTextures& tex, double waterMinDepthM,
                              unsigned threads, const TexelReuse* reuse, int interpolateLevels,
                              std::vector<RowFill>* rows, PyramidTiles* tiles) {
    const ApproximationPlan plan = ApproximationPlan::of(reuse, interpolateLevels, rows, tiles);
    const CascadeJob job{scene, c, tex, waterMinDepthM, threads};
    const int n = c.n;
    sizeTextures(scene, n, tex);
    ApproximationWork work;
    std::vector<Todo> todo = copyReusedTexels(c, plan, tex, work.reusedTexels, threads);
    // The texels left to evaluate: `need` (n^2) marks them, the spans of `todo` hold them (and copies between them).
    std::vector<uint8_t> copied(size_t(n) * size_t(n), 0), need(size_t(n) * size_t(n), 0);
    PyramidTiles* const pyramidTiles = plan.output == ApproximationPlan::Output::kRowsAndTiles ? plan.tiles : nullptr;
    const PyramidCopy pyramidCopy{scene,   c,    tex,    waterMinDepthM, plan.interpolateLevels,
                                  threads, todo, copied, pyramidTiles};
    work.pyramidTexels = copyPyramidTexels(pyramidCopy, work);
    // Each span: the texels written here, the copies left out at its ends.
    if (plan.output == ApproximationPlan::Output::kRowsAndTiles)
        for (size_t j = 0; j < size_t(n); ++j) {
            RowFill& r = (*plan.rows)[j];
            r.a.first = todo[j].a.first, r.a.last = todo[j].a.last, r.b.first = todo[j].b.first,
            r.b.last = todo[j].b.last;
        }
    const TexelsToSum sum = markTexelsToSum(todo, copied, need, n, threads);
    copied = {};
    if (sum.box.i1 < 0) return work;
    if (!scene.outOfCore())
        sumInMemory(job, todo, need, sum, work);
    else
        sumOutOfCore(job, todo, need, sum, work);
    return work;
}

}  // namespace hc::render::detail
