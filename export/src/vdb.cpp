#include <cmath>

#include <openvdb/openvdb.h>

#include "heightcast/export/export.h"
#include "heightcast/core/atomic_file.h"
#include "heightcast/core/error.h"

namespace hc::exporting {

bool vdbAvailable() { return true; }
void checkVdbAvailable(const std::string&) {}

namespace {

constexpr int kHalfWidthVoxels = 3;

// A narrow-band level set of the heightfield: in each column, the voxels within kHalfWidthVoxels
// of the surface get phi = (z - h) / sqrt(1 + |grad h|^2), the vertical distance projected on the
// normal (exact for a plane, first-order elsewhere).
openvdb::FloatGrid::Ptr levelSet(const SampledRaster& r, const std::string& name) {
    const double v = r.pixelSizeM;
    const float background = static_cast<float>(kHalfWidthVoxels * v);
    auto grid = openvdb::FloatGrid::create(background);
    auto xform = openvdb::math::Transform::createLinearTransform(v);
    xform->postTranslate(openvdb::Vec3d(0.5 * v, 0.5 * v, 0.0));  // voxel (i, j) centred in pixel (i, j)
    grid->setTransform(xform);
    grid->setGridClass(openvdb::GRID_LEVEL_SET);
    grid->setName(name);
    auto acc = grid->getAccessor();
    for (size_t row = 0; row < r.height; ++row)
        for (size_t col = 0; col < r.width; ++col) {
            const size_t i = row * r.width + col;
            const float h = r.values[i];
            if (std::isnan(h)) continue;
            const double gx = r.gradX.empty() || std::isnan(r.gradX[i]) ? 0.0 : r.gradX[i];
            const double gy = r.gradY.empty() || std::isnan(r.gradY[i]) ? 0.0 : r.gradY[i];
            const double cosSlope = 1.0 / std::sqrt(1.0 + gx * gx + gy * gy);
            const auto ix = static_cast<int>(col), iy = static_cast<int>(r.height - 1 - row);
            // Enough voxels to cover the band along the normal on steep slopes too.
            const int reach = kHalfWidthVoxels + static_cast<int>(std::ceil(kHalfWidthVoxels / cosSlope));
            const int k0 = static_cast<int>(std::floor(h / v));
            for (int k = k0 - reach; k <= k0 + reach; ++k) {
                const float phi = static_cast<float>((k * v - h) * cosSlope);
                if (std::abs(phi) < background) acc.setValue(openvdb::Coord(ix, iy, k), phi);
            }
        }
    grid->insertMeta("heightcast.gridOriginX", openvdb::DoubleMetadata(r.originWorldX));
    grid->insertMeta("heightcast.gridOriginY", openvdb::DoubleMetadata(r.originWorldY));
    grid->insertMeta("heightcast.rasterSouthWestX", openvdb::DoubleMetadata(r.westWorld));
    grid->insertMeta("heightcast.rasterSouthWestY",
                     openvdb::DoubleMetadata(r.northWorld - static_cast<double>(r.height) * v));
    grid->insertMeta("heightcast.crsWkt", openvdb::StringMetadata(r.crsWkt));
    grid->insertMeta("heightcast.layer", openvdb::StringMetadata(r.layer));
    grid->pruneGrid();
    return grid;
}

}  // namespace

void writeVdb(const SampledRaster& terrain, const SampledRaster* water, const std::string& path) {
    openvdb::initialize();
    AtomicPath out(path);
    try {
        openvdb::GridPtrVec grids;
        grids.push_back(levelSet(terrain, "terrain"));
        if (water) grids.push_back(levelSet(*water, "water_surface"));
        openvdb::io::File file(out.temp());
        file.write(grids);
        file.close();
    } catch (const std::exception& e) {
        throw Error(path + ": cannot write OpenVDB: " + e.what());
    }
    out.commit();
}

}  // namespace hc::exporting
