// The approximation pass: the Gaussian RBF sum (DESIGN.md section 4) at every visible texel of a
// cascade, in float with a vectorised exponential.
//
// Texels are taken cell by cell: all texel centres inside cell k share k's influence list, and
// every quantity is relative to k's centre and value, so float keeps its precision however far the
// cascade lies from the grid origin (the exact evaluator does the same in double).
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>

#include "heightcast/core/parallel.h"
#include "heightcast/influence/surface.h"
#include "textures.h"

namespace hc::render::detail {
namespace {

constexpr int kLanes = 8;  // candidates per vector step (AVX2: 8 floats)
static_assert(influence::kWetShareMin == 0.5, "render/gl/shaders/approximate.comp writes the wet share rule as denW >= 0.5 * den");

// exp(x) for x <= 0 in float: 2^(x log2 e) split into an integer power (exponent bits) and 2^f,
// f in [-0.5, 0.5], by its Taylor polynomial to degree 6 (relative error < 2e-7, float's epsilon).
// Branch-free, so loops over it vectorise.
inline float expNeg(float x) {
    x = std::max(x, -87.0f);
    const float y = x * 1.44269504088896341f;
    const float n = std::floor(y + 0.5f);
    const float f = y - n;
    const float p = 1.0f + f * (0.693147181f + f * (0.240226507f + f * (0.0555041087f + f * (0.00961812911f + f * (0.00133335581f + f * 0.000154035304f)))));
    const int32_t bits = (static_cast<int32_t>(n) + 127) << 23;
    return p * std::bit_cast<float>(bits);
}

struct Candidates {
    std::vector<float> ex, ey, a, r2, dz;  // relative to the cell's centre / value; padded to kLanes
    std::vector<float> dl, wet;            // water: level z + d relative to the level base (0 if dry), 1 if wet
    size_t count = 0;                          // real entries (before padding)
};

// The texels to evaluate, per row at most two spans: the row's visible span less the part copied from the
// last frame (visible there too: one span, as both rows' spans are intervals).
struct Todo {
    int a0 = 0, a1 = -1, b0 = 0, b1 = -1;  // inclusive; empty when the end is below the start
};

// Writes every texel of tex: the visible texels of c that were visible in `reuse` (if any) copied, their count
// added to `copied`; every other one "no surface" (-inf, depth 0) until evaluated. Returns the spans left to
// evaluate. reuse->tex may be tex itself (renderFrame hands the last frame's storage on, so a moving camera
// allocates nothing): this frame's row j reads the last frame's row j + dj, so rows are written in the order
// that reads each of the last frame's rows before overwriting it.
std::vector<Todo> copyReusedTexels(const Cascade& c, const TexelReuse* reuse, CascadeTextures& tex, uint64_t& copied) {
    const int n = c.n;
    const float noSurface = -std::numeric_limits<float>::infinity();
    std::vector<Todo> todo(static_cast<size_t>(n));
    const bool upwards = reuse && reuse->dj < 0;
    for (int step = 0; step < n; ++step) {
        const int j = upwards ? n - 1 - step : step;
        const Cascade::RowSpan& r = c.rows[size_t(j)];
        Todo& t = todo[size_t(j)];
        t.a0 = r.first, t.a1 = r.last;
        int f = 0, l = -1;  // the copied texels of row j
        const int jp = reuse ? j + reuse->dj : -1;
        if (reuse && r.first <= r.last && jp >= 0 && jp < reuse->cascade->n) {
            const Cascade::RowSpan& p = reuse->cascade->rows[size_t(jp)];
            f = std::max(r.first, p.first - reuse->di), l = std::min(r.last, p.last - reuse->di);
        }
        const size_t row = size_t(j) * size_t(n);
        auto place = [&](std::vector<float>& to, const std::vector<float>& from, float none) {
            float* const out = &to[row];
            if (l < f) {
                std::fill(out, out + n, none);
                return;
            }
            std::memmove(out + f, &from[size_t(jp) * size_t(n) + size_t(f + reuse->di)], size_t(l - f + 1) * sizeof(float));  // may overlap
            std::fill(out, out + f, none);
            std::fill(out + l + 1, out + n, none);
        };
        place(tex.terrain.h, reuse ? reuse->tex->terrain.h : tex.terrain.h, noSurface);
        if (tex.hasWater) {
            place(tex.water.h, reuse ? reuse->tex->water.h : tex.water.h, noSurface);
            place(tex.depth, reuse ? reuse->tex->depth : tex.depth, 0.0f);
        }
        if (f <= l) {
            copied += uint64_t(l - f + 1);
            t = {r.first, f - 1, l + 1, r.last};
        }
    }
    return todo;
}

// Copies into tex the texels of `todo` whose centres are samples of a tile the surface pyramid holds at the
// cascade's level (texelM is that level's spacing and the corner lies on its lattice: cascades.h), applying the
// water rule of surface.h to the water channels as the kernel path does. Each span of `todo` shrinks to the
// texels it could not copy, conservatively: from the first to the last of them (the kernel path evaluates
// copied texels in between again, to the same value within float rounding). Returns the texels copied and not
// left in `todo`, and sets *level to the pyramid level used (-1: none fits the cascade).
uint64_t copyPyramidTexels(const Scene& scene, const Cascade& c, CascadeTextures& tex, double waterMinDepthM, unsigned threads,
                           std::vector<Todo>& todo, int* level) {
    *level = -1;
    const influence::SurfacePyramid* p = scene.pyramid();
    if (!p) return 0;
    const double t = std::round(std::log2(c.texelM / p->finestCellM));
    if (t < 0 || t > p->topLevel() || std::abs(p->spacingM(int(t)) - c.texelM) > 1e-9 * c.texelM) return 0;
    *level = int(t);
    const size_t channels = size_t(p->channels);
    const double i0 = std::round(c.x0 / c.texelM), j0 = std::round(c.y0 / c.texelM);
    const float minDepth = float(waterMinDepthM);
    std::vector<uint64_t> copied(resolveThreads(threads), 0);
    parallelFor(todo.size(), 16, threads, [&](size_t b, size_t e, unsigned worker) {
        influence::SurfacePyramid::Cursor samples(*p, int(t));  // neighbouring rows share tiles
        const size_t plane = samples.plane();
        for (size_t j = b; j < e; ++j) {
            Todo& span = todo[j];
            const double gj = j0 + double(j);
            // Copies texel i if the pyramid holds its sample; false if it does not.
            auto copy = [&](int i) {
                const double gi = i0 + double(i);
                if (gi < 0 || gj < 0) return false;
                const float* s = samples.find(uint64_t(gi), uint64_t(gj));
                if (!s) return false;
                const size_t at = j * size_t(c.n) + size_t(i);
                if (std::isnan(s[0])) return true;  // outside every cell: no surface, as the kernel path leaves it
                tex.terrain.h[at] = s[0];
                if (channels == 3) {
                    const float lvl = s[plane], share = s[2 * plane];
                    if (!std::isnan(lvl) && double(share) >= influence::kWetShareMin) {
                        const float d = lvl - s[0];
                        if (d > 0) tex.depth[at] = d;
                        if (d > minDepth) tex.water.h[at] = lvl;
                    }
                }
                return true;
            };
            for (auto [lo, hi] : {std::pair<int*, int*>{&span.a0, &span.a1}, {&span.b0, &span.b1}}) {
                int first = *hi + 1, last = *lo - 1;
                for (int i = *lo; i <= *hi; ++i)
                    if (!copy(i)) first = std::min(first, i), last = i;
                copied[worker] += uint64_t(std::max(0, *hi - *lo + 1) - std::max(0, last - first + 1));
                *lo = first, *hi = last;
            }
        }
    });
    uint64_t total = 0;
    for (uint64_t v : copied) total += v;
    return total;
}

// Gathers the influence list of cell k into cand, relative to k's centre and value. Returns the water level
// base lk: the level of a wet cell, k's own if k is wet (NaN when no cell of the list is wet).
double gatherCandidates(const Scene& scene, uint32_t k, Candidates& cand) {
    const Grid& g = scene.grid();
    const auto& kernels = scene.kernels();
    const double kx = kernels[k].cx, ky = kernels[k].cy;
    const double zk = g.values[0][k];
    const int depthLayer = scene.waterLayer();
    const float* depthValues = depthLayer >= 0 ? g.values[size_t(depthLayer)].data() : nullptr;
    const auto list = scene.lists().list(k);
    // The water level field (DESIGN.md section 12, influence/surface.h) is taken relative to a wet cell's
    // level, k's own if k is wet, as the exact evaluator's levelBase() does: a constant level stays exact.
    double lk = std::numeric_limits<double>::quiet_NaN();
    if (depthValues) {
        if (depthValues[k] > 0) lk = zk + double(depthValues[k]);
        for (size_t idx = 0; idx < list.size() && std::isnan(lk); ++idx)
            if (depthValues[list[idx]] > 0) lk = double(g.values[0][list[idx]]) + double(depthValues[list[idx]]);
    }
    const bool anyWet = !std::isnan(lk);
    const size_t m = list.size(), padded = (m + kLanes - 1) / kLanes * kLanes;
    for (auto* v : {&cand.ex, &cand.ey, &cand.a, &cand.dz, &cand.dl, &cand.wet}) v->assign(padded, 0.0f);
    cand.r2.assign(padded, -1.0f);  // padding never counts: d2 < -1 is false
    cand.count = m;
    for (size_t idx = 0; idx < m; ++idx) {
        const uint32_t i = list[idx];
        const auto& ck = kernels[i];
        cand.ex[idx] = static_cast<float>(ck.cx - kx);
        cand.ey[idx] = static_cast<float>(ck.cy - ky);
        cand.a[idx] = ck.a;
        cand.r2[idx] = ck.r2;
        cand.dz[idx] = static_cast<float>(g.values[0][i] - zk);
        if (anyWet && depthValues[i] > 0) {
            cand.wet[idx] = 1.0f;
            cand.dl[idx] = static_cast<float>(double(g.values[0][i]) + double(depthValues[i]) - lk);
        }
    }
    return lk;
}

// The texels left to evaluate are listed cell by cell. Their bounding box's cells (Grid::cellsInBox) serve a
// fresh cascade, whose visible texels fill 25-100 % of that box. A moving camera leaves thin strips along the
// cascade's edges, whose bounding box is still the whole cascade: listing its cells would examine every cell
// under the cascade (about 2 M in Wachau's far cascade) for a few thousand texels. Below one texel to evaluate
// in kSparseTodo of the box, each texel's cell is located instead (Grid::locate, a binary search over the cells),
// so the work follows the texels. 16 sits between the two cases, not at a measured break-even: fresh cascades
// (above 1/4) always list the box, as before, and a moving camera's strips (0.1-1 % of the box in hc-bench's
// fly-through) are always located.
constexpr uint64_t kSparseTodo = 16;

// Appends to `cells` (sorted, each once) the cells whose half-open squares hold a texel centre of `todo`:
// the cells the box listing would keep (a cell holding no texel to evaluate is skipped there too).
void cellsUnderTexels(const Grid& g, const Cascade& c, const std::vector<Todo>& todo, unsigned threads, std::vector<uint32_t>& cells) {
    const double s = c.texelM;
    std::vector<std::vector<uint32_t>> found(resolveThreads(threads));
    parallelFor(todo.size(), 64, threads, [&](size_t b, size_t e, unsigned worker) {
        std::vector<uint32_t>& out = found[worker];
        for (size_t j = b; j < e; ++j) {
            const Todo& t = todo[j];
            const double y = c.y0 + double(int(j)) * s;
            for (auto [lo, hi] : {std::pair{t.a0, t.a1}, {t.b0, t.b1}}) {
                Grid::Square last{0, 0, -1, -1};  // empty: no point is inside
                for (int i = lo; i <= hi; ++i) {
                    const double x = c.x0 + i * s;
                    // Along a row, texels smaller than the cells fall into the cell just located.
                    if (x >= last.x0 && x < last.x1 && y >= last.y0 && y < last.y1) continue;
                    const std::optional<uint32_t> k = g.locate(x, y);
                    if (!k) continue;
                    out.push_back(*k);
                    last = g.cellSquare(*k);
                }
            }
        }
    });
    for (const std::vector<uint32_t>& f : found) cells.insert(cells.end(), f.begin(), f.end());
    std::sort(cells.begin(), cells.end());
    cells.erase(std::unique(cells.begin(), cells.end()), cells.end());
}

}  // namespace

void Heightfield::buildMip() {
    // Sides n - 1, then halving to 1. The levels' storage is reused when this heightfield's was (CascadeCache).
    mipSide.clear();
    for (int side = n - 1;; side = (side + 1) / 2) {
        mipSide.push_back(side);
        if (side <= 1) break;
    }
    mip.resize(mipSide.size());
    const int side0 = mipSide[0];
    std::vector<float>& level = mip[0];
    level.resize(size_t(side0) * size_t(side0));
    for (int j = 0; j < side0; ++j)
        for (int i = 0; i < side0; ++i) {
            const float* r0 = &h[size_t(j) * size_t(n) + size_t(i)];
            const float* r1 = r0 + n;
            level[size_t(j) * size_t(side0) + size_t(i)] = std::max(std::max(r0[0], r0[1]), std::max(r1[0], r1[1]));
        }
    for (size_t l = 1; l < mip.size(); ++l) {
        const int side = mipSide[l - 1], next = mipSide[l];
        std::vector<float>& up = mip[l];
        up.assign(size_t(next) * size_t(next), -std::numeric_limits<float>::infinity());
        const std::vector<float>& lo = mip[l - 1];
        for (int j = 0; j < side; ++j)
            for (int i = 0; i < side; ++i) {
                float& m = up[size_t(j / 2) * size_t(next) + size_t(i / 2)];
                m = std::max(m, lo[size_t(j) * size_t(side) + size_t(i)]);
            }
    }
}

ApproximationWork approximate(const Scene& scene, const Cascade& c, CascadeTextures& tex, double waterMinDepthM, unsigned threads,
                              const TexelReuse* reuse) {
    const Grid& g = scene.grid();
    const auto& lists = scene.lists();
    const int n = c.n;
    tex.hasWater = scene.hasWater();
    tex.terrain.n = tex.water.n = n;
    // Sized only: copyReusedTexels writes every texel.
    tex.terrain.h.resize(size_t(n) * size_t(n));
    if (tex.hasWater) {
        tex.water.h.resize(size_t(n) * size_t(n));
        tex.depth.resize(size_t(n) * size_t(n));
    }
    ApproximationWork work;
    std::vector<Todo> todo = copyReusedTexels(c, reuse, tex, work.reusedTexels);
    work.pyramidTexels = copyPyramidTexels(scene, c, tex, waterMinDepthM, threads, todo, &work.pyramidLevel);

    // Their bounding box and count.
    int i0 = n, i1 = -1, j0 = n, j1 = -1;
    uint64_t todoTexels = 0;
    for (int j = 0; j < n; ++j) {
        const Todo& t = todo[size_t(j)];
        for (auto [lo, hi] : {std::pair{t.a0, t.a1}, {t.b0, t.b1}})
            if (lo <= hi) {
                i0 = std::min(i0, lo), i1 = std::max(i1, hi), j0 = std::min(j0, j), j1 = std::max(j1, j);
                todoTexels += uint64_t(hi - lo + 1);
            }
    }
    if (i1 < 0) return work;
    const double s = c.texelM;
    const uint64_t boxTexels = uint64_t(i1 - i0 + 1) * uint64_t(j1 - j0 + 1);
    std::vector<uint32_t> cells;
    if (todoTexels * kSparseTodo < boxTexels) cellsUnderTexels(g, c, todo, threads, cells);
    else g.cellsInBox(c.x0 + i0 * s, c.y0 + j0 * s, c.x0 + i1 * s, c.y0 + j1 * s, cells);
    work.cellsVisited = cells.size();

    const float tail = static_cast<float>(lists.params().tail());
    const float minDepth = static_cast<float>(waterMinDepthM);
    std::vector<uint64_t> gaussians(resolveThreads(threads), 0);
    std::vector<Candidates> scratch(gaussians.size());
    parallelFor(cells.size(), 64, threads, [&](size_t b, size_t e, unsigned worker) {
        Candidates& cand = scratch[worker];
        for (size_t ci = b; ci < e; ++ci) {
            const uint32_t k = cells[ci];
            const Grid::Square q = g.cellSquare(k);
            // Texel centres inside k's half-open square [x0, x1) x [y0, y1).
            auto first = [&](double lo, double origin) {
                double t = std::ceil((lo - origin) / s);
                while (origin + (t - 1) * s >= lo) t -= 1;
                while (origin + t * s < lo) t += 1;
                return t;
            };
            const int ia = std::max(i0, int(first(q.x0, c.x0))), ib = std::min(i1 + 1, int(first(q.x1, c.x0)));
            const int ja = std::max(j0, int(first(q.y0, c.y0))), jb = std::min(j1 + 1, int(first(q.y1, c.y0)));
            if (ia >= ib || ja >= jb) continue;
            // Only a cell with a texel centre to evaluate gathers its list: in the visible texels' bounding box
            // (the polygon is a slab of a trapezoid) 25-65 % of the cells that hold a texel centre hold no
            // visible one.
            bool any = false;
            for (int j = ja; j < jb && !any; ++j) {
                const Todo& t = todo[size_t(j)];
                any = std::max(ia, t.a0) <= std::min(ib - 1, t.a1) || std::max(ia, t.b0) <= std::min(ib - 1, t.b1);
            }
            if (!any) continue;
            const double lk = gatherCandidates(scene, k, cand);
            const bool anyWet = !std::isnan(lk);
            const size_t m = cand.count, padded = cand.ex.size();
            const double kx = scene.kernels()[k].cx, ky = scene.kernels()[k].cy;
            const double zk = g.values[0][k];
            for (int j = ja; j < jb; ++j) {
                const float fy = static_cast<float>(c.y0 + j * s - ky);
                const Todo& span = todo[size_t(j)];
                for (auto [lo, hi] : {std::pair{span.a0, span.a1}, {span.b0, span.b1}}) {
                    for (int i = std::max(ia, lo), rb = std::min(ib, hi + 1); i < rb; ++i) {
                        const size_t t = size_t(j) * size_t(n) + size_t(i);
                        const float fx = static_cast<float>(c.x0 + i * s - kx);
                        gaussians[worker] += m;
                        float num[kLanes] = {}, den[kLanes] = {}, numL[kLanes] = {}, denW[kLanes] = {};
                        const float* __restrict ex = cand.ex.data();
                        const float* __restrict ey = cand.ey.data();
                        const float* __restrict ca = cand.a.data();
                        const float* __restrict cr2 = cand.r2.data();
                        const float* __restrict cdz = cand.dz.data();
                        const float* __restrict cdl = cand.dl.data();
                        const float* __restrict cwet = cand.wet.data();
                        // Branch-free (masks as 0/1 factors) so the compiler vectorises across the 8 lanes.
                        for (size_t base = 0; base < padded; base += kLanes)
                            for (int l = 0; l < kLanes; ++l) {
                                const size_t idx = base + size_t(l);
                                const float dx = fx - ex[idx], dy = fy - ey[idx];
                                const float d2 = dx * dx + dy * dy;
                                const float kernel = expNeg(-d2 * ca[idx]) - tail;
                                const float w = std::max(kernel, 0.0f) * static_cast<float>(d2 < cr2[idx]);
                                num[l] += w * cdz[idx];
                                numL[l] += w * cdl[idx];  // cdl is 0 for dry cells
                                denW[l] += w * cwet[idx];
                                den[l] += w;
                            }
                        float sn = 0, sd = 0, snL = 0, sdW = 0;
                        for (int l = 0; l < kLanes; ++l) sn += num[l], sd += den[l], snL += numL[l], sdW += denW[l];
                        // sd >= the cell's own weight at its farthest point (kernel.h): never zero here.
                        const double z = zk + double(sn / sd);
                        tex.terrain.h[t] = static_cast<float>(z);
                        // Water where the wet cells hold at least kWetShareMin of the weight and their level is above
                        // the terrain (surface.h); the depth texture holds level - terrain there (0 elsewhere), the
                        // water heightfield the level itself where that depth exceeds the minimum drawn.
                        if (anyWet && sdW > 0 && double(sdW) >= influence::kWetShareMin * double(sd)) {
                            const double level = lk + double(snL / sdW);
                            const float d = static_cast<float>(level - z);
                            if (d > 0) tex.depth[t] = d;
                            if (d > minDepth) tex.water.h[t] = static_cast<float>(level);
                        }
                    }
                }
            }
        }
    });
    for (uint64_t v : gaussians) work.gaussians += v;
    return work;
}

}  // namespace hc::render::detail
