// fuzz_2dm: hc-ingest's SMS/TUFLOW .2dm mesh parser (ingest/src/model/xmdf.cpp) through hc::ingest::readTwoDmMesh.
//
// The .2dm is text parsed by our own code, so the input bytes are the file as they are: libFuzzer's mutations of the
// seeds (small meshes written for the corpus: fuzz/corpus/2dm/) reach every card, field, number, node id and line
// ending. Only hc::Error may come out; a mesh that reads must hold what mesh.h promises (node indexes in range, faces
// of 3 or more nodes, finite node coordinates, one bed value per node).
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>

#include "heightcast/core/error.h"
#include "heightcast/ingest/mesh.h"

namespace {

std::string workDir() {
    static const std::string dir = [] {
        const auto d = std::filesystem::temp_directory_path() / ("fuzz_2dm_" + std::to_string(::getpid()));
        std::filesystem::create_directories(d);
        return d.string();
    }();
    return dir;
}

// What mesh.h promises of a mesh that reads; a broken promise is a finding.
void checkPromises(const hc::ingest::ModelMesh& m) {
    if (m.nodeX.size() != m.nodeY.size() || m.faceStart.empty() || m.faceStart.back() != m.faceNodes.size())
        __builtin_trap();
    if (m.faceCount() == 0) __builtin_trap();
    for (size_t f = 0; f < m.faceCount(); ++f)
        if (m.faceStart[f + 1] < m.faceStart[f] + 3) __builtin_trap();
    for (uint32_t n : m.faceNodes)
        if (n >= m.nodeX.size()) __builtin_trap();
    for (size_t i = 0; i < m.nodeX.size(); ++i)
        if (!std::isfinite(m.nodeX[i]) || !std::isfinite(m.nodeY[i])) __builtin_trap();
    if (m.bed.at != hc::ingest::MeshAt::Node || m.bed.values.size() != m.nodeX.size()) __builtin_trap();
    if (m.nameOf(m.faceCount() - 1).empty()) __builtin_trap();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    const std::string path = workDir() + "/mesh.2dm";
    {
        FILE* out = std::fopen(path.c_str(), "wb");
        if (!out) return 0;
        const bool written = std::fwrite(data, 1, size, out) == size;
        if (std::fclose(out) != 0 || !written) return 0;
    }
    try {
        checkPromises(hc::ingest::readTwoDmMesh(path));
    } catch (const hc::Error&) {
    }
    return 0;
}
