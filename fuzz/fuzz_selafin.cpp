// fuzz_selafin: hc-ingest's TELEMAC Selafin reader (ingest/src/model/selafin.cpp) through hc::ingest::readModelMesh.
//
// Selafin is parsed by our own code, so the input bytes are the file as they are: libFuzzer's mutations of the seeds
// (small files written for the corpus: fuzz/corpus/selafin/) reach every record length, count, node index, time and
// value. The reader is called through the public readModelMesh (its readers are private to ingest/), and every
// step's water level is read, since steps are read lazily. Only hc::Error may come out; a mesh that reads must hold
// what mesh.h promises (node indexes in range, faces of 3 or more nodes, one value per node or face at every step,
// times increasing). Inputs that do not start like a Selafin file (an 80-byte title record, in either byte order)
// are skipped: the dispatcher would hand them to GDAL's drivers, which this target is not about.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>

#include "heightcast/core/error.h"
#include "heightcast/ingest/mesh.h"

namespace {

std::string workDir() {
    static const std::string dir = [] {
        const auto d = std::filesystem::temp_directory_path() / ("fuzz_selafin_" + std::to_string(::getpid()));
        std::filesystem::create_directories(d);
        return d.string();
    }();
    return dir;
}

// The opening and closing length of the title record: 80, big- or little-endian.
bool startsLikeSelafin(const uint8_t* data, size_t size) {
    if (size < 88) return false;
    const auto is = [&](size_t at, uint8_t b0, uint8_t b3) {
        return data[at] == b0 && data[at + 1] == 0 && data[at + 2] == 0 && data[at + 3] == b3;
    };
    return (is(0, 0, 80) && is(84, 0, 80)) || (is(0, 80, 0) && is(84, 80, 0));
}

size_t valuesExpected(const hc::ingest::ModelMesh& m, hc::ingest::MeshAt at) {
    return at == hc::ingest::MeshAt::Node ? m.nodeX.size() : m.faceCount();
}

// What mesh.h promises of a mesh that reads; a broken promise is a finding.
void checkPromises(const hc::ingest::ModelMesh& m) {
    if (m.nodeX.size() != m.nodeY.size() || m.faceStart.empty() || m.faceStart.back() != m.faceNodes.size())
        __builtin_trap();
    for (size_t f = 0; f < m.faceCount(); ++f)
        if (m.faceStart[f + 1] < m.faceStart[f] + 3) __builtin_trap();
    for (uint32_t n : m.faceNodes)
        if (n >= m.nodeX.size()) __builtin_trap();
    if (!m.bed.values.empty() && m.bed.values.size() != valuesExpected(m, m.bed.at)) __builtin_trap();
    for (size_t k = 0; k < m.timesS.size(); ++k) {
        if (k > 0 && !(m.timesS[k] > m.timesS[k - 1])) __builtin_trap();
        const hc::ingest::MeshField level = m.level(k);
        if (level.values.size() != valuesExpected(m, level.at)) __builtin_trap();
        for (const hc::ingest::MeshLayer& layer : m.layers) {
            const hc::ingest::MeshField f = layer.read(k);
            if (f.values.size() != valuesExpected(m, f.at)) __builtin_trap();
        }
    }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    if (!startsLikeSelafin(data, size)) return 0;
    const std::string path = workDir() + "/mesh.slf";
    {
        FILE* out = std::fopen(path.c_str(), "wb");
        if (!out) return 0;
        const bool written = std::fwrite(data, 1, size, out) == size;
        if (std::fclose(out) != 0 || !written) return 0;
    }
    try {
        const hc::ingest::ModelMesh mesh = hc::ingest::readModelMesh(path, {});
        checkPromises(mesh);
    } catch (const hc::Error&) {
    }
    return 0;
}
