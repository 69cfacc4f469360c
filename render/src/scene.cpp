// render/src/scene.cpp: the Scene (renderer.h): a grid in memory with its lists, or a grid file read a region at a
// time, with its surface pyramid, bounds and per-cell kernels; the terrain height under a camera and the overview
// camera. Its error per pyramid level is in error_bound.cpp.
#include <algorithm>
#include <cmath>
#include <optional>
#include <string>
#include <vector>

#include "heightcast/core/error.h"
#include "heightcast/influence/region.h"
#include "heightcast/render/detail/frame.h"
#include "heightcast/render/renderer.h"
#include "renderer_internal.h"

namespace hc::render {

namespace {

void checkOnePyramid(const influence::SurfacePyramid* pyramid, uint64_t structureHash, uint64_t contentHash,
                     const influence::KernelParams& params, const char* kernelOf) {
    if (pyramid && (pyramid->structureHash != structureHash || pyramid->contentHash != contentHash))
        throw Error("the surface pyramid does not belong to this grid");
    if (pyramid && (pyramid->params.sigma != params.sigma || pyramid->params.truncation != params.truncation ||
                    pyramid->params.kernelId != params.kernelId))
        throw Error(std::string("the surface pyramid was built for another kernel than ") + kernelOf);
}

// A whole pyramid of the shown values; or a base (the first step's) and the shown step's water pyramid (pyramid.h).
void checkPyramid(const influence::SurfacePyramid* pyramid, const influence::SurfacePyramid* water, const Grid& shape,
                  uint64_t structureHash, uint64_t contentHash, const influence::KernelParams& params,
                  const char* kernelOf) {
    if (pyramid && pyramid->waterOnly())
        throw Error("a water pyramid is not a base pyramid: the terrain comes from the first step's");
    if (!water) return checkOnePyramid(pyramid, structureHash, contentHash, params, kernelOf);
    if (!water->waterOnly()) throw Error("the water pyramid holds more than water");
    if (!pyramid || pyramid->channels != 3 || shape.steps.empty())
        throw Error("a water pyramid needs the base pyramid of the scenario's first step");
    checkOnePyramid(water, structureHash, contentHash, params, kernelOf);
    checkOnePyramid(pyramid, structureHash, shape.steps[0].contentHash, params, kernelOf);
}

// The sum of docs/design.md section 3 over the list of cell k, in double, as the approximation evaluates it.
double terrainIn(const Grid& g, const influence::InfluenceLists& lists, const std::vector<Scene::CellKernel>& kernels,
                 uint32_t k, double xLocal, double yLocal) {
    const double tail = lists.params().tail(), zk = g.values[0][k];
    double num = 0, den = 0;
    for (const uint32_t i : lists.list(k)) {
        const Scene::CellKernel& c = kernels[i];
        const double d2 = (c.cx - xLocal) * (c.cx - xLocal) + (c.cy - yLocal) * (c.cy - yLocal);
        if (!(d2 < c.r2)) continue;
        const double w = std::max(0.0, std::exp(-d2 * c.a) - tail);
        num += w * (g.values[0][i] - zk);
        den += w;
    }
    return zk + num / den;  // den >= the cell's own weight inside it (kernel.h): never zero
}

}  // namespace

std::vector<Scene::CellKernel> Scene::kernelsOf(const Grid& grid, const influence::KernelParams& params) {
    std::vector<CellKernel> kernels(grid.cellCount());
    const double sigma = params.sigma;
    for (size_t i = 0; i < grid.cellCount(); ++i) {
        CellKernel& k = kernels[i];
        grid.cellCenterLocal(i, k.cx, k.cy);
        const double size = grid.cellSizeM(i), r = params.radiusM(size);
        k.a = static_cast<float>(1.0 / (2.0 * sigma * sigma * size * size));
        k.r2 = static_cast<float>(r * r);
    }
    return kernels;
}

namespace {

// The largest water depth over every step of the grid's scenario (the shown step's when it has no step table).
double scenarioDepthMax(const Grid& grid, double shown) {
    double m = shown;
    for (const StepInfo& s : grid.steps)
        if (!s.layerMax.empty()) m = std::max(m, double(s.layerMax[0]));
    return m;
}

}  // namespace

Scene::Scene(const Grid& grid, const influence::InfluenceLists& lists, const influence::SurfacePyramid* pyramid,
             const influence::SurfacePyramid* waterPyramid, std::optional<GridHashes> known)
    : grid_(grid),
      lists_(&lists),
      pyramid_(pyramid),
      waterPyramid_(waterPyramid),
      params_(lists.params()),
      cellCount_(grid.cellCount()) {
    if (grid.cellCount() == 0) throw Error("the grid has no cells: nothing to render");
    const uint64_t structure = known ? known->structure : grid.structureHash();
    if (lists.cellCount() != grid.cellCount() || lists.gridStructureHash() != structure)
        throw Error("the influence lists do not belong to this grid");
    if (pyramid || waterPyramid)
        checkPyramid(pyramid, waterPyramid, grid, structure, known ? known->content : grid.contentHash(),
                     lists.params(), "the influence lists");
    waterLayer_ = grid.findLayer("water_depth");
    grid.boundsLocal(xMin, yMin, xMax, yMax);
    elevationMin = HUGE_VAL, elevationMax = -HUGE_VAL, depthMax = 0;
    double surfaceMax = -HUGE_VAL;
    for (size_t i = 0; i < grid.cellCount(); ++i) {
        const double z = grid.values[0][i];
        elevationMin = std::min(elevationMin, z);
        elevationMax = std::max(elevationMax, z);
        double top = z;
        if (waterLayer_ >= 0) {
            const double d = grid.values[size_t(waterLayer_)][i];
            depthMax = std::max(depthMax, d);
            top += std::max(d, 0.0);
        }
        surfaceMax = std::max(surfaceMax, top);
    }
    kernels_ = kernelsOf(grid, lists.params());
    // The smooth surface is a convex combination of cell values: it stays within their range.
    zMin = elevationMin;
    zMax = surfaceMax;
    depthColorMaxM = scenarioDepthMax(grid, depthMax);
    boundLevels();
    boundRelief();
}

Scene::Scene(const GridRegionReader& file, const influence::KernelParams& params,
             const influence::SurfacePyramid* pyramid, const influence::SurfacePyramid* waterPyramid)
    : grid_(file.shape()),
      file_(&file),
      pyramid_(pyramid),
      waterPyramid_(waterPyramid),
      params_(params),
      cellCount_(file.cellCount()) {
    if (cellCount_ == 0) throw Error(file.path() + ": the grid has no cells: nothing to render");
    if (std::string why = params.validate(); !why.empty()) throw Error("kernel parameters: " + why);
    checkPyramid(pyramid, waterPyramid, file.shape(), file.info().structureHash, file.info().contentHash, params,
                 "this render's --sigma/--truncation");
    const GridSummary& sum = file.info().summary;
    waterLayer_ = grid_.findLayer("water_depth");
    const double f = grid_.finestCellM;
    xMin = double(sum.boundsFinest[0]) * f, yMin = double(sum.boundsFinest[1]) * f;
    xMax = double(sum.boundsFinest[2]) * f, yMax = double(sum.boundsFinest[3]) * f;
    elevationMin = sum.layerMin.at(0), elevationMax = sum.layerMax.at(0);
    depthMax = waterLayer_ >= 0 ? std::max(0.0, double(sum.layerMax.at(size_t(waterLayer_)))) : 0.0;
    zMin = elevationMin;
    zMax = elevationMax + depthMax;
    depthColorMaxM = scenarioDepthMax(grid_, depthMax);
    boundLevels();
}

const influence::SurfaceEvaluator& Scene::evaluator() const {
    if (!lists_)
        throw Error(
            "colouring by a layer needs the grid in memory with its influence lists (hc-influence writes them; "
            "--cache)");
    std::call_once(evaluatorMade_, [&] { evaluator_ = std::make_unique<influence::SurfaceEvaluator>(grid_, *lists_); });
    return *evaluator_;
}

const influence::InfluenceLists& Scene::lists() const {
    if (!lists_) throw Error("an out-of-core scene has no influence lists (its regions build their own)");
    return *lists_;
}

std::optional<double> Scene::terrainAt(double xLocal, double yLocal) const {
    if (!file_) {
        const auto k = grid_.locate(xLocal, yLocal);
        if (!k) return std::nullopt;
        return terrainIn(grid_, *lists_, kernels_, *k, xLocal, yLocal);
    }
    const influence::SurfaceRegion r =
        influence::readSurfaceRegion(*file_, {xLocal, yLocal, xLocal, yLocal}, params_, 1);
    const auto k = r.grid.locate(xLocal, yLocal);
    if (!k) return std::nullopt;
    return terrainIn(r.grid, r.lists, kernelsOf(r.grid, params_), *k, xLocal, yLocal);
}

std::optional<Grid::Square> Scene::cellSquareAt(double xLocal, double yLocal) const {
    if (!file_) {
        const auto k = grid_.locate(xLocal, yLocal);
        return k ? std::optional<Grid::Square>(grid_.cellSquare(*k)) : std::nullopt;
    }
    return file_->cellSquareAt(xLocal, yLocal);
}

double cameraBelowTerrainM(const Scene& scene, const Camera& camera) {
    if (camera.nearM > 0) return 0;
    const Grid& g = scene.grid();
    double x = 0, y = 0;
    g.worldToLocal(camera.xWorld, camera.yWorld, x, y);
    const std::optional<double> z = scene.terrainAt(x, y);
    return z ? *z - camera.zWorld : 0.0;
}

Camera overviewCamera(const Scene& s, int width, int height) {
    const Grid& g = s.grid();
    const double cx = 0.5 * (s.xMin + s.xMax), cy = 0.5 * (s.yMin + s.yMax), cz = 0.5 * (s.zMin + s.zMax);
    const double diag = std::hypot(s.xMax - s.xMin, s.yMax - s.yMin, s.zMax - s.zMin);
    Camera c;
    c.yawDeg = 20;
    c.pitchDeg = -35;
    c.fovYDeg = 45;
    c.width = width;
    c.height = height;
    const CameraBasis b = basisOf(c);  // in the local frame: 20 degrees from the grid's own y axis
    const double dist = 0.4 * diag / b.tanHalfY;
    g.localToWorld(cx - b.forward[0] * dist, cy - b.forward[1] * dist, c.xWorld, c.yWorld);
    c.zWorld = cz - b.forward[2] * dist;
    c.yawDeg = std::remainder(c.yawDeg - g.rotationDeg, 360.0);  // the same view, in the CRS's yaw
    return c;
}

// A copied sample is the exact surface rounded to float once: half an ulp of the largest height.
double detail::pyramidCopyBoundM(const Scene& scene) {
    return std::ldexp(std::max(std::abs(scene.zMin), std::abs(scene.zMax)), -24);
}

}  // namespace hc::render
