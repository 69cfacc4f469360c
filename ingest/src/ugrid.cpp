// UGRID quadtree meshes -> grid with water steps (ugrid.h): the model reader (mesh.h) with the faces taken as cells.
#include "heightcast/ingest/ugrid.h"

#include "heightcast/ingest/mesh.h"
#include "heightcast/ingest/model.h"

namespace hc::ingest {

bool isUgridMesh(const std::string& path) { return modelFormatOf(path).find("UGRID") != std::string::npos; }

BuildSummary ingestUgridToFile(const Options& options, const std::string& path, LoadReport& report) {
    Options o = options;
    o.meshMode = MeshMode::Cells;
    return ingestModelToFile(o, path, report);
}

}  // namespace hc::ingest
