#include "heightcast/influence/region.h"

#include <algorithm>
#include <numeric>

#include "heightcast/core/error.h"
#include "heightcast/grid/morton.h"

namespace hc::influence {

std::vector<double> kernelReachM(const Grid& shape, const KernelParams& params) {
    std::vector<double> reach(size_t(shape.rootLevel) + 1);
    for (int l = 0; l <= shape.rootLevel; ++l) reach[size_t(l)] = params.radiusM(shape.levelSizeM(l));
    return reach;
}

SurfaceRegion readSurfaceRegion(const GridRegionReader& file, const Grid::Square& box, const KernelParams& params,
                                unsigned threads) {
    if (std::string why = params.validate(); !why.empty()) throw Error("kernel parameters: " + why);
    SurfaceRegion r;
    r.grid = file.region(box, kernelReachM(file.shape(), params));
    r.lists = buildInfluenceLists(r.grid, params, threads, false);
    return r;
}

std::vector<std::optional<double>> valuesFromFile(const GridRegionReader& file,
                                                  std::span<const std::array<double, 2>> pointsLocal,
                                                  const Layer& layer, const KernelParams& params, unsigned threads,
                                                  RegionReadStats* stats) {
    const Grid& shape = file.shape();
    std::vector<std::optional<double>> out(pointsLocal.size());
    RegionReadStats local;
    // Each point inside the domain with the Morton key of its finest cell; points outside stay undefined.
    const double side = shape.domainSizeM();
    std::vector<std::pair<uint64_t, uint32_t>> keyed;  // (key, point index), sorted
    keyed.reserve(pointsLocal.size());
    for (size_t p = 0; p < pointsLocal.size(); ++p)
        if (const auto key = shape.finestKeyAt(pointsLocal[p][0], pointsLocal[p][1]))
            keyed.push_back({*key, uint32_t(p)});
    std::sort(keyed.begin(), keyed.end());
    struct Node {
        uint64_t key;
        int level;
        size_t lo, hi;  // into keyed
    };
    std::vector<Node> stack{{0, shape.rootLevel, 0, keyed.size()}};
    std::vector<std::array<double, 2>> pts;
    while (!stack.empty()) {
        Node n = stack.back();
        stack.pop_back();
        if (n.lo == n.hi) continue;
        // The smallest node holding these points: counting its cells searches next to the points (a node much larger
        // than they would send the count's binary searches, and the blocks they check, far across the file).
        while (n.level > 0 &&
               (keyed[n.lo].first >> (2 * (n.level - 1))) == (keyed[n.hi - 1].first >> (2 * (n.level - 1)))) {
            --n.level;
            n.key = keyed[n.lo].first & ~(mortonSpan(n.level) - 1);
        }
        const uint64_t cells = file.cellsInNode(n.key, n.level);
        if (cells == 0) continue;  // no cell under these points: undefined
        if (n.level > 0 && (n.hi - n.lo > kRegionPoints || cells > kRegionCells)) {
            const uint64_t quarter = mortonSpan(n.level - 1);
            size_t b[5] = {n.lo, 0, 0, 0, n.hi};
            for (int q = 1; q < 4; ++q)
                b[q] = size_t(std::lower_bound(keyed.begin() + std::ptrdiff_t(b[q - 1]),
                                               keyed.begin() + std::ptrdiff_t(n.hi),
                                               std::pair<uint64_t, uint32_t>{n.key + quarter * uint64_t(q), 0}) -
                              keyed.begin());
            for (int q = 3; q >= 0; --q) stack.push_back({n.key + quarter * uint64_t(q), n.level - 1, b[q], b[q + 1]});
            continue;
        }
        Grid::Square box{side, side, 0, 0};
        pts.clear();
        for (size_t k = n.lo; k < n.hi; ++k) {
            const auto& p = pointsLocal[keyed[k].second];
            pts.push_back(p);
            box.x0 = std::min(box.x0, p[0]), box.y0 = std::min(box.y0, p[1]);
            box.x1 = std::max(box.x1, p[0]), box.y1 = std::max(box.y1, p[1]);
        }
        const SurfaceRegion r = readSurfaceRegion(file, box, params, threads);
        ++local.regions;
        local.cellsRead += r.grid.cellCount();
        local.largestRegion = std::max<uint64_t>(local.largestRegion, r.grid.cellCount());
        if (r.grid.cellCount() == 0) continue;
        const SurfaceEvaluator eval(r.grid, r.lists);
        const auto values = eval.values(pts, layer, threads);
        for (size_t k = n.lo; k < n.hi; ++k) out[keyed[k].second] = values[k - n.lo];
    }
    if (stats) *stats = local;
    return out;
}

}  // namespace hc::influence
