// render/src/verify_error.cpp: the error measured at a frame's hits against the exact surface (verifyFrameError): each
// checked hit's height against the exact one, and with water which side of the exact shoreline each hit was drawn on
// and, for the hits on the wrong side, the distance to the exact shore and the height of water drawn over dry ground.
// The bounds the frame claims are error_bound.cpp's.
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>
#include <vector>

#include "heightcast/core/quantile.h"
#include "heightcast/influence/region.h"
#include "heightcast/render/detail/frame.h"
#include "heightcast/render/renderer.h"

namespace hc::render {

namespace {

using Points = std::vector<std::array<double, 2>>;
using Values = std::vector<std::optional<double>>;

// The hits to check: every hit off the walls, or `samples` of them spread evenly.
std::vector<size_t> hitsToCheck(const Frame& f, size_t samples) {
    std::vector<size_t> hits;
    for (size_t i = 0; i < f.distanceM.size(); ++i)
        if (std::isfinite(f.distanceM[i]) && !(i < f.wall.size() && f.wall[i] != 0)) hits.push_back(i);
    if (hits.size() <= samples) return hits;
    std::vector<size_t> picked(samples);
    for (size_t k = 0; k < samples; ++k) picked[k] = hits[(k * hits.size()) / samples];
    return picked;
}

// The exact layer at local points: over the grid and its lists in memory, else from the file around the points.
Values exactValues(const Scene& scene, const Points& pts, const influence::Layer& layer, unsigned threads) {
    if (scene.outOfCore()) return influence::valuesFromFile(*scene.file(), pts, layer, scene.params(), threads);
    return scene.evaluator().values(pts, layer, threads);
}

Values exactValues(const Scene& scene, const Points& pts, const char* layer, unsigned threads) {
    return exactValues(scene, pts, influence::Layer::byName(scene.grid(), layer), threads);
}

// The distance from each point to the nearest point whose exact water is drawn (water_depth > 0) where wet[k], and
// to the nearest where it is not (dry, in a hole or outside the grid) where not: searched on rings of kDirections
// points, their radii growing by kShoreRingStep from start[k] up to twice the domain's size. The first ring that holds
// such a point gives the distance: at most kShoreRingStep times too long (start[k] where it is nearer), and short only
// where the shore passes between two of a ring's points. Infinity where no ring holds one.
std::vector<double> distanceToExactShore(const Scene& scene, const Points& pts, const std::vector<bool>& wet,
                                         const std::vector<double>& start, unsigned threads) {
    constexpr int kDirections = 16;
    const double farthest = 2 * scene.grid().domainSizeM();
    std::vector<double> dist(pts.size(), std::numeric_limits<double>::infinity());
    std::vector<size_t> pending;
    for (size_t k = 0; k < pts.size(); ++k)
        if (start[k] > 0) pending.push_back(k);
    for (double scale = 1; !pending.empty(); scale *= kShoreRingStep) {
        Points ring;
        ring.reserve(pending.size() * kDirections);
        for (const size_t k : pending)
            for (int d = 0; d < kDirections; ++d) {
                const double a = 2 * std::numbers::pi * d / kDirections, r = start[k] * scale;
                ring.push_back({pts[k][0] + r * std::cos(a), pts[k][1] + r * std::sin(a)});
            }
        const Values depth = exactValues(scene, ring, "water_depth", threads);
        std::vector<size_t> still;
        for (size_t n = 0; n < pending.size(); ++n) {
            bool found = false;
            for (int d = 0; d < kDirections && !found; ++d) {
                const std::optional<double>& v = depth[n * kDirections + size_t(d)];
                found = (v && *v > 0) == wet[pending[n]];
            }
            if (found)
                dist[pending[n]] = start[pending[n]] * scale;
            else if (start[pending[n]] * scale * kShoreRingStep <= farthest)
                still.push_back(pending[n]);
        }
        pending.swap(still);
    }
    return dist;
}

// The checked hits drawn dry, or on water: their places (local m) and pixels.
struct Checked {
    Points pts;
    std::vector<size_t> at;  // the pixel
};

// Which side of the shoreline each checked hit was drawn on, against the exact water depth there (water_depth: level
// minus terrain where the exact water stands, 0 where it is dry). A hit over a hole's edge has no exact value: skipped.
// A dry hit under exact water counts only where its ray came down through the exact water surface: where the ray meets
// the exact level (terrain plus depth at the hit) the exact water stands too. Water has no sides, so a ray from beside
// the domain or below the level reaches the ground under it without passing any shoreline: not counted.
// Of the hits on the wrong side: for those drawn on water, the height of the drawn water over the exact ground; for
// each, the distance to the exact shore (distanceToExactShore): from a hit drawn on water to the nearest exact water,
// and from where a hit drawn dry had its ray come down through the exact water (there the drawn water was missing) to
// the nearest place without it.
void checkShoreline(const Scene& scene, const Camera& camera, const Frame& f, const Checked& dry, const Checked& wet,
                    double pixelRad, unsigned threads, ErrorCheck& check) {
    check.water = true;
    Points pts(dry.pts);
    pts.insert(pts.end(), wet.pts.begin(), wet.pts.end());
    if (pts.empty()) return;
    const Values depth = exactValues(scene, pts, "water_depth", threads);
    Points from;                 // where each hit on the wrong side has its shore's distance measured from
    std::vector<bool> toWater;   // to the nearest exact water (else to the nearest place without it)
    std::vector<size_t> fromAt;  // its pixel
    Points wetOverDry;
    std::vector<size_t> wetOverDryAt;
    for (size_t k = 0; k < wet.pts.size(); ++k)
        if (const std::optional<double>& d = depth[dry.pts.size() + k]; d && !(*d > 0)) {
            wetOverDry.push_back(wet.pts[k]), wetOverDryAt.push_back(wet.at[k]);
            from.push_back(wet.pts[k]), toWater.push_back(true), fromAt.push_back(wet.at[k]);
        }
    check.drawnWetOverDry = wetOverDry.size();
    const Values ground = exactValues(scene, wetOverDry, "elevation", threads);
    for (size_t k = 0; k < wetOverDry.size(); ++k)
        if (ground[k])
            check.shoreMaxM = std::max(check.shoreMaxM, std::abs(double(f.posZ[wetOverDryAt[k]]) - *ground[k]));
    double ex = 0, ey = 0;
    scene.grid().worldToLocal(camera.xWorld, camera.yWorld, ex, ey);
    Points entries;  // where each dry hit under exact water has its ray at the level
    std::vector<size_t> entryAt;
    for (size_t k = 0; k < dry.pts.size(); ++k) {
        if (!depth[k] || !(*depth[k] > 0)) continue;
        const double level = double(f.posZ[dry.at[k]]) + *depth[k],
                     s = (level - camera.zWorld) / (double(f.posZ[dry.at[k]]) - camera.zWorld);
        if (!(camera.zWorld > level) || !(s > 0 && s < 1)) continue;  // the camera below the level: a side view
        entries.push_back({ex + s * (dry.pts[k][0] - ex), ey + s * (dry.pts[k][1] - ey)});
        entryAt.push_back(dry.at[k]);
    }
    const Values above = exactValues(scene, entries, "water_depth", threads);
    for (size_t n = 0; n < entries.size(); ++n)
        if (above[n] && *above[n] > 0) {
            from.push_back(entries[n]), toWater.push_back(false), fromAt.push_back(entryAt[n]);
            ++check.drawnDryOverWater;
        }
    std::vector<double> start(from.size());  // a sixteenth of a pixel's footprint at the hit
    for (size_t n = 0; n < from.size(); ++n) start[n] = pixelRad * double(f.distanceM[fromAt[n]]) / 16;
    const std::vector<double> dist = distanceToExactShore(scene, from, toWater, start, threads);
    for (size_t n = 0; n < from.size(); ++n) {
        check.shoreDistanceM = std::max(check.shoreDistanceM, dist[n]);
        check.shoreDistancePx = std::max(check.shoreDistancePx, dist[n] / (pixelRad * double(f.distanceM[fromAt[n]])));
    }
}

}  // namespace

ErrorCheck verifyFrameError(const Scene& scene, const Camera& camera, const Frame& f, size_t samples,
                            unsigned threads) {
    const std::vector<size_t> hits = hitsToCheck(f, samples);
    const Grid& grid = scene.grid();
    Checked dry, wet;
    for (const size_t i : hits) {
        std::array<double, 2> p{};
        grid.worldToLocal(f.originWorldX + f.posX[i], f.originWorldY + f.posY[i], p[0], p[1]);
        Checked& c = i < f.waterDepthM.size() && f.waterDepthM[i] > 0 ? wet : dry;
        c.pts.push_back(p), c.at.push_back(i);
    }
    ErrorCheck check;
    std::vector<double> errors;
    const double pixelRad = detail::setUpFrame(scene, camera).view.pixelRad;
    auto compare = [&](const Checked& c, const char* name) {
        if (c.pts.empty()) return;
        const Values exact = exactValues(scene, c.pts, name, threads);
        for (size_t k = 0; k < c.pts.size(); ++k) {
            if (!exact[k]) continue;  // a hit on a patch over a hole's edge: no exact surface there to compare with
            const double e = std::abs(double(f.posZ[c.at[k]]) - *exact[k]);
            errors.push_back(e);
            check.maxPx = std::max(check.maxPx, e / (pixelRad * double(f.distanceM[c.at[k]])));
        }
    };
    compare(dry, "elevation");
    compare(wet, "water_surface");
    if (scene.hasWater()) checkShoreline(scene, camera, f, dry, wet, pixelRad, threads, check);
    check.hits = errors.size();
    check.maxM = errors.empty() ? 0 : *std::max_element(errors.begin(), errors.end());
    check.p99M = quantile(errors, 0.99);
    check.medianM = quantile(errors, 0.5);
    return check;
}

}  // namespace hc::render
