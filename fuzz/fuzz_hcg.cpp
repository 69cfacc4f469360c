// fuzz_hcg: the .hcg grid readers on any bytes, checksums made valid first (fuzz_input.h): hc::readGrid, and the
// out-of-core GridRegionReader (open, regions with margins, point queries), which reads only what a query touches.
// Only hc::Error may come out: any other exception, crash or sanitizer report is a finding; where readGrid accepts
// the file, a region over the whole domain must hold exactly its cells.
#include <optional>
#include <string>

#include "container_mutator.h"
#include "heightcast/core/error.h"
#include "heightcast/grid/grid_file.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    static hc::fuzz::MemoryFile file;
    std::vector<std::byte> bytes(reinterpret_cast<const std::byte*>(data),
                                 reinterpret_cast<const std::byte*>(data) + size);
    hc::fuzz::fixContainer(bytes);
    const std::string path = file.write(bytes);
    std::optional<hc::Grid> whole;
    try {
        const hc::Grid g = hc::readGrid(path);
        // What the reader accepts, the tools query: every cell's centre must locate that cell (a grid with
        // overlapping or out-of-domain cells that passed validation would fail here).
        for (size_t i = 0; i < g.cellCount(); ++i) {
            double x = 0, y = 0;
            g.cellCenterLocal(i, x, y);
            if (g.locate(x, y) != std::optional<uint32_t>(static_cast<uint32_t>(i))) __builtin_trap();
        }
        whole = g;
    } catch (const hc::Error&) {
    }
    try {
        const hc::GridRegionReader reader(path);
        const hc::Grid& shape = reader.shape();
        const double side = shape.domainSizeM(), f = shape.finestCellM;
        const double margins[] = {0.0, 2 * f, 5 * f};
        const hc::Grid all = reader.region({0, 0, side, side}, margins);
        if (whole && all.codes != whole->codes) __builtin_trap();
        (void)reader.region({0.3 * side, 0.6 * side, 0.3 * side, 0.6 * side}, margins);
        (void)reader.cellSquareAt(0.5 * side, 0.25 * side);
        (void)reader.cellsInNode(0, shape.rootLevel);
    } catch (const hc::Error&) {
    }
    return 0;
}

extern "C" size_t LLVMFuzzerCustomMutator(uint8_t* data, size_t size, size_t maxSize, unsigned int seed) {
    return hc::fuzz::mutateContainer(data, size, maxSize, seed);
}
