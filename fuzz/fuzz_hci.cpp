// fuzz_hci: the .hci influence cache reader (hc::influence::readInfluenceCache) on any bytes, checksums
// made valid first (fuzz_input.h), against the grid the seed caches were built from (HC_FUZZ_HCI_GRID).
// The kernel parameters wanted are the ones the input declares, so mutating them does not end the run at
// the parameter check. An accepted cache is then used as hc-probe uses it: the surface at every cell
// centre. Only hc::Error may come out: any other exception, crash or sanitizer report is a finding.
#include <array>

#include "container_mutator.h"
#include "heightcast/core/error.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/influence/influence.h"
#include "heightcast/influence/surface.h"

namespace {
const hc::Grid& grid() {
    static const hc::Grid g = hc::readGrid(HC_FUZZ_HCI_GRID);
    return g;
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    static hc::fuzz::MemoryFile file;
    const hc::Grid& g = grid();
    std::vector<std::byte> bytes(reinterpret_cast<const std::byte*>(data),
                                 reinterpret_cast<const std::byte*>(data) + size);
    hc::fuzz::fixContainer(bytes);
    hc::influence::KernelParams params;
    if (bytes.size() >= hc::kFileHeaderBytes) {
        params.kernelId = hc::bytes::load<uint32_t>(bytes.data() + 56);
        params.sigma = hc::bytes::load<double>(bytes.data() + 64);
        params.truncation = hc::bytes::load<double>(bytes.data() + 72);
    }
    try {
        const hc::influence::InfluenceLists lists = hc::influence::readInfluenceCache(file.write(bytes), g, params);
        // The evaluator needs parameters it can use (hc-probe validates its options first).
        if (!params.validate().empty()) return 0;
        hc::influence::SurfaceEvaluator eval(g, lists);
        const auto layer = hc::influence::Layer::byName(g, "elevation");
        std::vector<std::array<double, 2>> centres;
        for (size_t i = 0; i < g.cellCount(); ++i) {
            std::array<double, 2> c{};
            g.cellCenterLocal(i, c[0], c[1]);
            centres.push_back(c);
        }
        (void)eval.values(centres, layer, 1);
    } catch (const hc::Error&) {
    }
    return 0;
}

extern "C" size_t LLVMFuzzerCustomMutator(uint8_t* data, size_t size, size_t maxSize, unsigned int seed) {
    return hc::fuzz::mutateContainer(data, size, maxSize, seed);
}
