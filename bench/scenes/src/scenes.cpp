// bench/scenes/src/scenes.cpp: the four synthetic flood scenes: landscape functions, the lists' size and the fixed
// camera (heightcast/scenes/scenes.h says what each is; generate.cpp builds their quadtree).
#include "heightcast/scenes/scenes.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <random>

namespace hc::scenes {

namespace {

const Scenario kScenarios[] = {
    {"Marchfeld",
     82.9,
     57.1,
     3.0,
     7.46,
     15.1,
     5.1,
     580000,
     5330000,
     {160, 0.0004, 0.42, {2600, 700}, {32000, 7000}, 2600, 1800, 150, 6, 2.4, 1.2, 45, 8, 11}},
    {"Petzenkirchen",
     15.4,
     16.0,
     0.75,
     1.81,
     20.8,
     4.3,
     510000,
     5330000,
     {300, 0.002, 0.5, {700, 160}, {9000, 1800}, 110, 700, 4, 1.5, 0.8, 0.4, 90, 12, 22}},
    {"Wachau",
     24.1,
     16.5,
     3.0,
     1.95,
     5.3,
     4.3,
     530000,
     5360000,
     {205, 0.0003, 0.5, {1600, 400}, {19000, 5200}, 450, 2600, 140, 5, 3.0, 1.0, 430, 35, 33}},
    {"Florence",
     44.6,
     28.2,
     3.0,
     4.53,
     1.5,
     2.8,
     660000,
     4840000,
     {55, 0.0005, 0.45, {1300, 320}, {21000, 4300}, 1900, 3200, 60, 4, 2.5, 0.9, 330, 28, 44}},
};

}  // namespace

std::span<const Scenario> scenarios() { return kScenarios; }

const Scenario* findScenario(std::string_view name) {
    for (const Scenario& sc : kScenarios)
        if (name == sc.name) return &sc;
    return nullptr;
}

double extentXM(const Scenario& sc) { return std::round(sc.extentXKm * 1000 / kCoarsestM) * kCoarsestM; }
double extentYM(const Scenario& sc) { return std::round(sc.extentYKm * 1000 / kCoarsestM) * kCoarsestM; }

// ---------------- the landscape ----------------

Terrain::Terrain(const Scenario& sc) : l_(sc.land), extentY_(extentYM(sc)) {
    std::mt19937_64 rng(l_.seed);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    auto waves = [&](int count, double minLen, double maxLen, std::vector<Wave>& out) {
        double total = 0;
        for (int k = 0; k < count; ++k) {
            const double len = minLen * std::pow(maxLen / minLen, unit(rng));
            const double dir = 2 * std::numbers::pi * unit(rng), kk = 2 * std::numbers::pi / len;
            const double amp = 0.5 + unit(rng);
            out.push_back({kk * std::cos(dir), kk * std::sin(dir), 2 * std::numbers::pi * unit(rng), amp});
            total += amp;
        }
        for (Wave& w : out) w.amp /= total;  // the sum stays within [-1, 1]
    };
    waves(4, 6000, 30000, large_);
    waves(6, 150, 900, hills_);
    waves(3, 200, 900, micro_);
    for (int k = 0; k < 2; ++k) meanderPhase_[k] = 2 * std::numbers::pi * unit(rng);
}

void Terrain::centreline(double x, double& y, double& dydx) const {
    y = l_.riverYFraction * extentY_;
    dydx = 0;
    for (int k = 0; k < 2; ++k) {
        const double w = 2 * std::numbers::pi / l_.meanderLen[k], a = w * x + meanderPhase_[k];
        y += l_.meanderAmp[k] * std::sin(a);
        dydx += l_.meanderAmp[k] * w * std::cos(a);
    }
}

Terrain::Sample Terrain::at(double x, double y) const {
    double yc, dydx;
    centreline(x, yc, dydx);
    const double d = std::abs(y - yc) / std::sqrt(1 + dydx * dydx);  // distance to the centreline, nearly
    const double floor = floorAt(x);
    // 0 on the floodplain, 1 on the uplands, smooth in between.
    double t = std::clamp((d - l_.floorHalfWidth) / l_.sideWidth, 0.0, 1.0);
    t = t * t * (3 - 2 * t);
    double z = floor;
    if (t < 1) z += (1 - t) * l_.microAmp * sum(micro_, x, y);
    if (t > 0) {
        const double large = sum(large_, x, y);  // [-1, 1]
        const double relief = l_.reliefAmp * (1 + 0.5 * large);
        const double hills = l_.hillAmp * (0.5 + 0.5 * large) * sum(hills_, x, y);
        z += t * (relief + hills);
    }
    if (d < l_.channelHalfWidth) {
        const double r = d / l_.channelHalfWidth;
        z -= l_.channelDepth * (1 - r * r);
    }
    const double depth = std::max(0.0, waterLevelAt(x) - z);
    return {static_cast<float>(z), static_cast<float>(depth), static_cast<float>(d - l_.channelHalfWidth)};
}

double Terrain::sum(const std::vector<Wave>& waves, double x, double y) {
    double s = 0;
    for (const Wave& w : waves) s += w.amp * std::sin(w.kx * x + w.ky * y + w.phase);
    return s;
}

// ---------------- the lists' size ----------------

ListsEstimate estimateInfluenceLists(const Grid& g, const influence::KernelParams& params, size_t sampleCells) {
    ListsEstimate est;
    const size_t n = g.cellCount();
    if (n == 0) return est;
    const size_t stride = std::max<size_t>(1, n / std::max<size_t>(1, sampleCells));
    uint64_t entries = 0, sampled = 0;
    std::vector<uint32_t> met;
    for (size_t i = stride / 2; i < n; i += stride, ++sampled) {
        double x, y;
        g.cellCenterLocal(i, x, y);
        met.clear();
        // The kernel is zero on its disk's rim, and R sigma = 3.5 cell sizes puts rims exactly on the edges of
        // cells of the same size: a disk only touching a square must not count, so the radius is a hair shorter.
        g.cellsInDisk(x, y, params.radiusM(g.cellSizeM(i)) * (1 - 1e-9), met);
        entries += met.size();
    }
    est.meanLength = double(entries) / double(sampled);
    est.bytes = uint64_t(8.0 * double(n + 1) + 4.0 * est.meanLength * double(n));
    return est;
}

// ---------------- the camera ----------------

render::Camera floodCamera(const Scenario& sc, const Grid& g, int width, int height) {
    const Terrain terrain(sc);
    const double aboveM = 1500, pitch = -20;
    double ey, ey2, dydx;
    const double ex = 0.1 * extentXM(sc);
    terrain.centreline(ex, ey, dydx);
    const double ex2 = ex + aboveM / std::tan(-pitch * std::numbers::pi / 180);  // where the centre ray meets the floor
    terrain.centreline(ex2, ey2, dydx);
    render::Camera c;
    c.xWorld = g.originWorldX + ex;
    c.yWorld = g.originWorldY + ey;
    c.zWorld = terrain.waterLevelAt(ex) + aboveM;
    c.yawDeg = std::atan2(ex2 - ex, ey2 - ey) * 180 / std::numbers::pi;
    c.pitchDeg = pitch;
    c.fovYDeg = 50;
    c.width = width;
    c.height = height;
    return c;
}

}  // namespace hc::scenes
