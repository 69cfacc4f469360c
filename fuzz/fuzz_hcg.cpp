// fuzz_hcg: the .hcg grid reader (hc::readGrid) on any bytes, checksums made valid first (fuzz_input.h).
// Only hc::Error may come out: any other exception, crash or sanitizer report is a finding.
#include <optional>

#include "container_mutator.h"
#include "heightcast/core/error.h"
#include "heightcast/grid/grid_file.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    static hc::fuzz::MemoryFile file;
    std::vector<std::byte> bytes(reinterpret_cast<const std::byte*>(data), reinterpret_cast<const std::byte*>(data) + size);
    hc::fuzz::fixContainer(bytes);
    try {
        const hc::Grid g = hc::readGrid(file.write(bytes));
        // What the reader accepts, the tools query: every cell's centre must locate that cell (a grid with
        // overlapping or out-of-domain cells that passed validation would fail here).
        for (size_t i = 0; i < g.cellCount(); ++i) {
            double x = 0, y = 0;
            g.cellCenterLocal(i, x, y);
            if (g.locate(x, y) != std::optional<uint32_t>(static_cast<uint32_t>(i))) __builtin_trap();
        }
    } catch (const hc::Error&) {
    }
    return 0;
}

extern "C" size_t LLVMFuzzerCustomMutator(uint8_t* data, size_t size, size_t maxSize, unsigned int seed) {
    return hc::fuzz::mutateContainer(data, size, maxSize, seed);
}
