// The Gaussian RBF sum (docs/design.md section 3) at the texels of a cascade left to evaluate, in float with a
// vectorised exponential: sumTexels() and the cells it takes, cellsUnderTexels() (approximate_internal.h). Part of the
// approximation pass (approximate.cpp).
//
// Texels are taken cell by cell: all texel centres inside cell k share k's influence list, and
// every quantity is relative to k's centre and value, so float keeps its precision however far the
// cascade lies from the grid origin (the exact evaluator does the same in double).
#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <optional>
#include <vector>

#include "approximate_internal.h"
#include "heightcast/core/parallel.h"

namespace hc::render::detail {
namespace {

constexpr int kLanes = 8;  // candidates per vector step (AVX2: 8 floats)

// exp(x) for x <= 0 in float: 2^(x log2 e) split into an integer power (exponent bits) and 2^f,
// f in [-0.5, 0.5], by its Taylor polynomial to degree 6 (relative error < 2e-7, float's epsilon).
// Branch-free, so loops over it vectorise.
inline float expNeg(float x) {
    x = std::max(x, -87.0f);
    const float y = x * 1.44269504088896341f;
    const float n = std::floor(y + 0.5f);
    const float f = y - n;
    const float p =
        1.0f + f * (0.693147181f +
                    f * (0.240226507f +
                         f * (0.0555041087f + f * (0.00961812911f + f * (0.00133335581f + f * 0.000154035304f)))));
    const int32_t bits = (static_cast<int32_t>(n) + 127) << 23;
    return p * std::bit_cast<float>(bits);
}

struct Candidates {
    std::vector<float> ex, ey, a, r2, dz;  // relative to the cell's centre / value; padded to kLanes
    std::vector<float> dl, wet;            // water: level z + d relative to the level base (0 if dry), 1 if wet
    size_t count = 0;                      // real entries (before padding)
};

// Gathers the influence list of cell k into cand, relative to k's centre and value. Returns the water level
// base lk: the level of a wet cell, k's own if k is wet (NaN when no cell of the list is wet).
double gatherCandidates(const CellData& cells, uint32_t k, Candidates& cand) {
    const Grid& g = cells.grid;
    const auto& kernels = cells.kernels;
    const double kx = kernels[k].cx, ky = kernels[k].cy;
    const double zk = g.values[0][k];
    const int depthLayer = cells.waterLayer;
    const float* depthValues = depthLayer >= 0 ? g.values[size_t(depthLayer)].data() : nullptr;
    const auto list = cells.lists.list(k);
    // The water level field (docs/design.md section 6, influence/surface.h) is taken relative to a wet cell's
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

}  // namespace

void cellsUnderTexels(const Grid& g, const Cascade& c, const std::vector<uint8_t>& need, const TexelRange& r,
                      unsigned threads, std::vector<uint32_t>& cells) {
    const double s = c.texelM;
    std::vector<std::vector<uint32_t>> found(resolveThreads(threads));
    parallelFor(size_t(r.j1 - r.j0 + 1), 64, threads, [&](size_t b, size_t e, unsigned worker) {
        std::vector<uint32_t>& out = found[worker];
        for (size_t jr = b; jr < e; ++jr) {
            const size_t j = size_t(r.j0) + jr;
            const double y = c.y0 + double(int(j)) * s;
            const uint8_t* row = &need[j * size_t(c.n)];
            Grid::Square last{0, 0, -1, -1};  // empty: no point is inside
            for (int i = r.i0; i <= r.i1; ++i) {
                if (!row[i]) continue;
                const double x = c.x0 + i * s;
                // Along a row, texels smaller than the cells fall into the cell just located.
                if (x >= last.x0 && x < last.x1 && y >= last.y0 && y < last.y1) continue;
                const std::optional<uint32_t> k = g.locate(x, y);
                if (!k) continue;
                out.push_back(*k);
                last = g.cellSquare(*k);
            }
        }
    });
    for (const std::vector<uint32_t>& f : found) cells.insert(cells.end(), f.begin(), f.end());
    std::sort(cells.begin(), cells.end());
    cells.erase(std::unique(cells.begin(), cells.end()), cells.end());
}

void sumTexels(const CellData& data, const Cascade& c, const std::vector<Todo>& todo, const std::vector<uint8_t>& need,
               const TexelRange& r, const std::vector<uint32_t>& cells, CascadeTextures& tex, double waterMinDepthM,
               unsigned threads, uint64_t* gaussiansOut) {
    const Grid& g = data.grid;
    const int n = c.n;
    const double s = c.texelM;
    const int i0 = r.i0, i1 = r.i1, j0 = r.j0, j1 = r.j1;
    const float tail = static_cast<float>(data.lists.params().tail());
    const float minDepth = static_cast<float>(waterMinDepthM);
    std::vector<uint64_t> gaussians(resolveThreads(threads), 0);
    std::vector<Candidates> scratch(gaussians.size());
    parallelFor(cells.size(), 64, threads, [&](size_t b, size_t e, unsigned worker) {
        Candidates& cand = scratch[worker];
        uint64_t evaluated = 0;  // added to gaussians[worker] once: the workers' counters share a cache line
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
                any = std::max(ia, t.a.first) <= std::min(ib - 1, t.a.last) ||
                      std::max(ia, t.b.first) <= std::min(ib - 1, t.b.last);
            }
            if (!any) continue;
            const double lk = gatherCandidates(data, k, cand);
            const bool anyWet = !std::isnan(lk);
            const size_t m = cand.count, padded = cand.ex.size();
            const double kx = data.kernels[k].cx, ky = data.kernels[k].cy;
            const double zk = g.values[0][k];
            for (int j = ja; j < jb; ++j) {
                const float fy = static_cast<float>(c.y0 + j * s - ky);
                const Todo& span = todo[size_t(j)];
                for (auto [lo, hi] : {std::pair{span.a.first, span.a.last}, {span.b.first, span.b.last}}) {
                    for (int i = std::max(ia, lo), rb = std::min(ib, hi + 1); i < rb; ++i) {
                        const size_t t = size_t(j) * size_t(n) + size_t(i);
                        if (!need[t]) continue;
                        const float fx = static_cast<float>(c.x0 + i * s - kx);
                        evaluated += m;
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
                        // The water rule (water_rule.h): the depth texture holds level - terrain, the water
                        // heightfield the level.
                        if (anyWet && water::wetWeights(double(sdW), double(sd))) {
                            const double level = lk + double(snL / sdW);
                            const float d = static_cast<float>(level - z);
                            if (water::holdsDepth(d)) tex.depth[t] = d;
                            if (water::drawsWater(d, minDepth)) tex.water.h[t] = static_cast<float>(level);
                        }
                    }
                }
            }
        }
        gaussians[worker] += evaluated;
    });
    for (uint64_t v : gaussians) *gaussiansOut += v;
}

}  // namespace hc::render::detail
