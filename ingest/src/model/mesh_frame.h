// ingest/src/model/mesh_frame.h: a model mesh's coordinates brought into the metric frame of a grid (private to
// ingest/).
#pragma once

#include <string>

#include "heightcast/ingest/ingest.h"
#include "heightcast/ingest/mesh.h"

namespace hc::ingest::detail {

struct MeshFrame {
    std::string crsWkt, crsName;  // the grid's CRS ("" = local metres)
    std::string sourceCrsName;    // the mesh's own, as taken
    bool moved = false;           // the nodes were transformed (projected, or feet to metres)
    bool geographic = false;      // the mesh was in degrees (projected to UTM)
};

// The mesh on its own: a projected CRS in metres is kept (nodes untouched), degrees are projected to the UTM zone of
// the mesh's centre on their own datum, a projected CRS in other units to the same projection in metres. `srs`
// overrides the file's CRS ("local": metres in a local frame). A CRS the coordinates cannot be in (degrees beyond
// +-360/90, a projected CRS whose area of use is far from them) is not used: local metres, with a warning.
MeshFrame meshToMetric(ModelMesh& mesh, const std::string& srs, LoadReport& report);

// The mesh into the CRS `targetWkt` of a terrain ("" = local): from `srs` (or the file's CRS); a mesh without one is
// taken to be in the terrain's CRS already, with a warning.
void meshToTarget(ModelMesh& mesh, const std::string& srs, const std::string& targetWkt, LoadReport& report);

}  // namespace hc::ingest::detail
