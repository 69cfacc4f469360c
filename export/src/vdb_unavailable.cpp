// writeVdb in a build without OpenVDB (-DHC_WITH_VDB=OFF): says so instead of writing anything.
#include "heightcast/core/error.h"
#include "heightcast/export/export.h"

namespace hc::exporting {

bool vdbAvailable() { return false; }

void checkVdbAvailable(const std::string& path) {
    throw Error(path +
                ": this heightcast was built without OpenVDB (-DHC_WITH_VDB=OFF); rebuild with -DHC_WITH_VDB=ON "
                "(Debian: libopenvdb-dev) to write .vdb, or export .tif or .exr");
}

void writeVdb(const SampledRaster&, const SampledRaster*, const std::string& path) { checkVdbAvailable(path); }

}  // namespace hc::exporting
