// fuzz_hcp: the .hcp surface pyramid reader (hc::influence::readSurfacePyramid) on any bytes, checksums made
// valid first (fuzz_input.h), against the grid the seed pyramids were built from (HC_FUZZ_HCP_GRID). The kernel
// parameters wanted are the ones the input declares, so mutating them does not end the run at the parameter
// check. An accepted pyramid is then read as the renderer reads it: every lattice point of every level through
// sample(). Only hc::Error may come out: any other exception, crash or sanitizer report is a finding.
#include "container_mutator.h"
#include "heightcast/core/error.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/influence/pyramid.h"

namespace {
const hc::Grid& grid() {
    static const hc::Grid g = hc::readGrid(HC_FUZZ_HCP_GRID);
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
        params.kernelId = hc::bytes::load<uint32_t>(bytes.data() + 52);
        params.sigma = hc::bytes::load<double>(bytes.data() + 64);
        params.truncation = hc::bytes::load<double>(bytes.data() + 72);
    }
    try {
        const hc::influence::SurfacePyramid p = hc::influence::readSurfacePyramid(file.write(bytes), g, params);
        float sum = 0;
        for (int t = 0; t <= p.topLevel(); ++t) {
            const uint64_t side = uint64_t{1} << (p.rootLevel - t);
            for (uint64_t j = 0; j <= side; ++j)
                for (uint64_t i = 0; i <= side; ++i)
                    for (int c = 0; c < p.channels; ++c)
                        if (auto v = p.sample(t, i, j, hc::influence::PyramidChannel(c))) sum += *v;
        }
        (void)sum;
    } catch (const hc::Error&) {
    }
    return 0;
}

extern "C" size_t LLVMFuzzerCustomMutator(uint8_t* data, size_t size, size_t maxSize, unsigned int seed) {
    return hc::fuzz::mutateContainer(data, size, maxSize, seed);
}
