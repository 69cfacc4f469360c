// ingest/src/model/model_ingest.h: a flood model's water levels on a terrain raster's pixels (--water-mesh; private to
// ingest/).
#pragma once

#include "heightcast/ingest/build.h"
#include "heightcast/ingest/ingest.h"

namespace hc::ingest::detail {

// Options::waterMesh's steps as water depths on `terrain`'s pixels: each step's level sampled at the pixel centres
// (constant per face, linear over triangles), depth = level - terrain, dry where the model is dry, where no face holds
// the pixel, or where the depth is not positive. The steps own what they read; `terrain` must outlive them.
WaterSteps meshWaterSteps(const Options& options, const Raster& terrain, LoadReport& report);

}  // namespace hc::ingest::detail
