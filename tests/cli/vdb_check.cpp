// vdb_check: reads an OpenVDB file whole and prints what it holds, so that two files can be compared without
// their bytes (every file gets a fresh UUID): one line per grid with its name, value type, active voxel count
// and active bounding box. Exits 1, saying why, if the file cannot be read whole (truncated, corrupt).
// The kill -9 test's validator for hc-export's .vdb (kill_during_write.sh).
//
//   vdb_check FILE.vdb
#include <openvdb/openvdb.h>

#include <cstdio>
#include <exception>

int main(int argc, char** argv) {
    if (argc != 2) {
        std::fprintf(stderr, "usage: vdb_check FILE.vdb\n");
        return 2;
    }
    try {
        openvdb::initialize();
        openvdb::io::File file(argv[1]);
        file.open();
        openvdb::GridPtrVecPtr grids = file.getGrids();  // reads every grid's tree: a short file throws
        file.close();
        if (!grids || grids->empty()) {
            std::fprintf(stderr, "vdb_check: %s: no grids\n", argv[1]);
            return 1;
        }
        for (const openvdb::GridBase::Ptr& g : *grids) {
            const openvdb::CoordBBox box = g->evalActiveVoxelBoundingBox();
            std::printf("%s %s active %llu bbox %d,%d,%d..%d,%d,%d\n", g->getName().c_str(), g->valueType().c_str(),
                        static_cast<unsigned long long>(g->activeVoxelCount()), box.min().x(), box.min().y(),
                        box.min().z(), box.max().x(), box.max().y(), box.max().z());
        }
    } catch (const std::exception& e) {
        std::fprintf(stderr, "vdb_check: %s: cannot read: %s\n", argv[1], e.what());
        return 1;
    }
    return 0;
}
