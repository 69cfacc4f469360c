// heightcast/ingest/model.h: flood model results -> a grid with water steps (docs/models.md).
//
// A quadtree model's faces (SFINCS, 3Di, or any mesh of square faces of power-of-two sizes) are taken as they are: one
// cell per face, the lattice (rotation, origin, finest size) fitted to every node by least squares and accepted within
// a tolerance that covers the file's own coordinate precision (Options::meshToleranceM overrides). Any other mesh is
// sampled at the pixel centres of a working raster of the finest faces' size (or --min-cell): the bed and each step's
// water level as the model defines them (constant per face, or linear over triangles), then built like a raster, so
// the build's tolerance guarantee holds against the mesh's fields. Depth = level - bed; dry where the model is dry or
// the depth is not positive. Coordinates in degrees are projected to the UTM zone of the mesh's centre, a projected CRS
// in feet to the same projection in metres.
#pragma once

#include <string>

#include "heightcast/ingest/build.h"
#include "heightcast/ingest/ingest.h"

namespace hc::ingest {

// The model results of options.input into a grid file at `path` (atomically). Fills `report`; throws hc::Error naming
// the file and the face, step or variable that is wrong; nothing is written then.
BuildSummary ingestModelToFile(const Options& options, const std::string& path, LoadReport& report);

}  // namespace hc::ingest
