// heightcast/render/image_io.h: a rendered frame to files, atomically (temporary + rename).
#pragma once

#include <string>

#include "heightcast/render/renderer.h"

namespace hc::render {

// 8-bit sRGB PNG (libpng).
void writePng(const Frame& frame, const std::string& path);

// OpenEXR with FLOAT channels Z (distance along the ray [m], +inf where the ray misses), P.X, P.Y,
// P.Z (hit position relative to the grid origin [m]), N.X, N.Y, N.Z (unit normal), cascade (-1 on a
// miss), water_depth [m] and wall (1 on hits on the terrain block's cut faces: hole and domain edge walls
// and the bottom, 0 elsewhere: Frame::wall); ZIP compression, through hc::exr::writeFloatImage. Header
// attributes: heightcast.gridOriginX/Y (double, world [m]: the grid's origin, which P.X/P.Y are relative to;
// the same name and meaning as in hc-export's files, export/export.h).
void writeFrameExr(const Frame& frame, const std::string& path);

}  // namespace hc::render
