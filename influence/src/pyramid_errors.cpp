// influence/src/pyramid_errors.cpp: what drawing the surface from a pyramid level costs in accuracy (pyramid.h,
// bilinearErrorByLevelM and RegionalLevelErrors): the tiles' measured parent errors chained from the finest level up,
// over the whole domain or over the regions a box meets.
#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "heightcast/grid/morton.h"
#include "heightcast/influence/pyramid.h"

namespace hc::influence {

namespace {

// Level 0's own error (its bilinear patches against the surface) as a share of its parent errors. For a surface smooth
// at level 0's spacing it is a quarter (the bilinear error grows with the spacing squared); but where the finest cells
// lie, the kernels (of one cell's size) put detail at that very spacing, and the quarter law fails: hc-bench --trade
// found a hit 1.43 m off under a level-1 bound of 1.34 m with a share of one half. The whole parent error holds there.
constexpr double kLevel0Share = 1.0;

// The chain of bilinearErrorByLevelM from the largest parent error of each level.
std::vector<double> chained(const std::vector<double>& parentMax) {
    std::vector<double> bound(parentMax.size());
    if (bound.empty()) return bound;
    double chain = kLevel0Share * parentMax[0];
    for (size_t t = 0; t < bound.size(); ++t) bound[t] = chain += t > 0 ? parentMax[t - 1] : 0.0;
    return bound;
}

}  // namespace

std::vector<double> bilinearErrorByLevelM(const SurfacePyramid& pyramid, PyramidChannel c) {
    const int k = pyramid.channelIndex(c);
    if (k < 0 || pyramid.levels.empty()) return {};
    std::vector<double> parentMax(pyramid.levels.size(), 0.0);
    for (size_t t = 0; t < pyramid.levels.size(); ++t) {
        const SurfacePyramid::Level& L = pyramid.levels[t];
        for (size_t tile = 0; tile < L.tileCount(); ++tile) {
            const float e = L.parentErrorM[tile * size_t(pyramid.channels) + size_t(k)];
            if (std::isfinite(e)) parentMax[t] = std::max(parentMax[t], double(e));
        }
    }
    return chained(parentMax);
}

RegionalLevelErrors::RegionalLevelErrors(const SurfacePyramid& pyramid, PyramidChannel c) {
    const int k = pyramid.channelIndex(c);
    if (k < 0 || pyramid.levels.empty()) return;
    levels_ = int(pyramid.levels.size());
    finestCellM_ = pyramid.finestCellM;
    side_ = 1 << std::clamp(pyramid.rootLevel, 0, kRegionsLog2);
    regionM_ = pyramid.finestCellM * std::exp2(pyramid.rootLevel) / side_;
    parentMax_.assign(size_t(levels_) * size_t(side_) * size_t(side_), 0.0f);
    for (int t = 0; t < levels_; ++t) {
        const SurfacePyramid::Level& L = pyramid.levels[size_t(t)];
        const double tileM = double(L.tileSide) * pyramid.spacingM(t);
        float* level = &parentMax_[size_t(t) * size_t(side_) * size_t(side_)];
        for (size_t tile = 0; tile < L.tileCount(); ++tile) {
            const float e = L.parentErrorM[tile * size_t(pyramid.channels) + size_t(k)];
            if (!std::isfinite(e)) continue;
            const double x0 = double(mortonX(L.keys[tile])) * finestCellM_,
                         y0 = double(mortonY(L.keys[tile])) * finestCellM_;
            const auto [i0, i1] = regionsOver(x0, x0 + tileM);
            const auto [j0, j1] = regionsOver(y0, y0 + tileM);
            for (int j = j0; j <= j1; ++j)
                for (int i = i0; i <= i1; ++i) {
                    float& m = level[size_t(j) * size_t(side_) + size_t(i)];
                    m = std::max(m, e);
                }
        }
    }
}

// The regions [first, last] along one axis that the half-open span [a, b) of local metres meets (clamped to the
// domain's).
std::pair<int, int> RegionalLevelErrors::regionsOver(double a, double b) const {
    auto at = [&](double x) { return std::clamp(int(std::floor(x / regionM_)), 0, side_ - 1); };
    const int first = at(a), last = at(std::nextafter(b, -HUGE_VAL));
    return {first, std::max(first, last)};
}

std::vector<double> RegionalLevelErrors::byLevelM(double x0, double y0, double x1, double y1) const {
    std::vector<double> parentMax(size_t(levels_), 0.0);
    for (int t = 0; t < levels_; ++t) {
        // A point of the box reads the level-t patch around it: samples up to one spacing away.
        const double h = finestCellM_ * std::exp2(t);
        const auto [i0, i1] = regionsOver(x0 - h, x1 + h);
        const auto [j0, j1] = regionsOver(y0 - h, y1 + h);
        const float* level = &parentMax_[size_t(t) * size_t(side_) * size_t(side_)];
        float m = 0;
        for (int j = j0; j <= j1; ++j)
            for (int i = i0; i <= i1; ++i) m = std::max(m, level[size_t(j) * size_t(side_) + size_t(i)]);
        parentMax[size_t(t)] = m;
    }
    return chained(parentMax);
}

}  // namespace hc::influence
