// A mesh's fields sampled at pixel centres (sample_mesh.h).
#include "sample_mesh.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "heightcast/core/parallel.h"

namespace hc::ingest::detail {
namespace {

constexpr uint32_t kNone = std::numeric_limits<uint32_t>::max();
constexpr size_t kBandRows = 64;  // rows a worker rasterizes together: the faces are bucketed by band once

// Twice the signed area of (a, b, p).
double edge(double ax, double ay, double bx, double by, double px, double py) {
    return (bx - ax) * (py - ay) - (by - ay) * (px - ax);
}

// Barycentric weights of the pixel centre (px, py) in triangle (a, b, c); false outside. Inclusive to a few
// roundings of the triangle's area, so a centre on a shared edge lies in both (the later face keeps it).
bool weights(const double* x, const double* y, double px, double py, double w[3]) {
    const double area = edge(x[0], y[0], x[1], y[1], x[2], y[2]);
    if (area == 0) return false;
    w[0] = edge(x[1], y[1], x[2], y[2], px, py) / area;
    w[1] = edge(x[2], y[2], x[0], y[0], px, py) / area;
    w[2] = 1.0 - w[0] - w[1];
    const double eps = -1e-12;
    return w[0] >= eps && w[1] >= eps && w[2] >= eps;
}

}  // namespace

double finestFaceSide(const ModelMesh& m) {
    std::vector<double> sides;
    sides.reserve(m.faceCount());
    double x0 = HUGE_VAL, x1 = -HUGE_VAL, y0 = HUGE_VAL, y1 = -HUGE_VAL;
    for (size_t f = 0; f < m.faceCount(); ++f) {
        double a = 0;  // shoelace
        for (uint64_t k = m.faceStart[f]; k < m.faceStart[f + 1]; ++k) {
            const uint32_t p = m.faceNodes[k], q = m.faceNodes[k + 1 < m.faceStart[f + 1] ? k + 1 : m.faceStart[f]];
            a += m.nodeX[p] * m.nodeY[q] - m.nodeX[q] * m.nodeY[p];
            x0 = std::min(x0, m.nodeX[p]), x1 = std::max(x1, m.nodeX[p]), y0 = std::min(y0, m.nodeY[p]),
            y1 = std::max(y1, m.nodeY[p]);
        }
        if (a != 0) sides.push_back(std::sqrt(std::abs(a) / 2));
    }
    const double floor = 1e-3 * std::max(x1 - x0, y1 - y0);
    if (sides.empty()) return floor;
    const size_t at = sides.size() / 100;
    std::nth_element(sides.begin(), sides.begin() + long(at), sides.end());
    return std::max(sides[at], floor);
}

MeshCover::MeshCover(const ModelMesh& m, const PixelFrame& fr, unsigned threads)
    : mesh_(m), frame_(fr), threads_(threads) {
    face_.assign(fr.width * fr.height, kNone);
    tri_.assign(fr.width * fr.height, 0);
    // Each face's rows, bucketed by band.
    const size_t bands = (fr.height + kBandRows - 1) / kBandRows;
    std::vector<std::vector<uint32_t>> inBand(bands);
    for (size_t f = 0; f < m.faceCount(); ++f) {
        double y0 = HUGE_VAL, y1 = -HUGE_VAL;
        for (uint64_t k = m.faceStart[f]; k < m.faceStart[f + 1]; ++k)
            y0 = std::min(y0, m.nodeY[m.faceNodes[k]]), y1 = std::max(y1, m.nodeY[m.faceNodes[k]]);
        const double r0 = std::floor((fr.north - y1) / fr.pixelSizeM - 0.5),
                     r1 = std::ceil((fr.north - y0) / fr.pixelSizeM - 0.5);
        if (r1 < 0 || r0 >= double(fr.height)) continue;
        const size_t b0 = size_t(std::max(0.0, r0)) / kBandRows, b1 = std::min(size_t(r1), fr.height - 1) / kBandRows;
        for (size_t b = b0; b <= b1; ++b) inBand[b].push_back(uint32_t(f));
    }
    std::vector<uint64_t> count(resolveThreads(threads), 0);
    parallelFor(bands, 1, threads, [&](size_t b0, size_t b1, unsigned worker) {
        for (size_t b = b0; b < b1; ++b) {
            const size_t rowLo = b * kBandRows, rowHi = std::min(fr.height, rowLo + kBandRows);
            for (uint32_t f : inBand[b]) {
                const uint64_t s = m.faceStart[f];
                for (size_t t = 0; t + 2 < m.nodesOf(f); ++t) {
                    const uint32_t n[3] = {m.faceNodes[s], m.faceNodes[s + t + 1], m.faceNodes[s + t + 2]};
                    const double x[3] = {m.nodeX[n[0]], m.nodeX[n[1]], m.nodeX[n[2]]},
                                 y[3] = {m.nodeY[n[0]], m.nodeY[n[1]], m.nodeY[n[2]]};
                    const double c0 = std::ceil((*std::min_element(x, x + 3) - fr.west) / fr.pixelSizeM - 0.5);
                    const double c1 = std::floor((*std::max_element(x, x + 3) - fr.west) / fr.pixelSizeM - 0.5);
                    const double r0 = std::ceil((fr.north - *std::max_element(y, y + 3)) / fr.pixelSizeM - 0.5);
                    const double r1 = std::floor((fr.north - *std::min_element(y, y + 3)) / fr.pixelSizeM - 0.5);
                    const size_t cLo = size_t(std::max(0.0, c0)), rLo = std::max(rowLo, size_t(std::max(0.0, r0)));
                    if (c1 < 0 || r1 < double(rowLo) || c0 >= double(fr.width)) continue;
                    const size_t cHi = std::min(fr.width - 1, size_t(c1)),
                                 rHi = std::min(rowHi - 1, size_t(std::max(0.0, r1)));
                    for (size_t r = rLo; r <= rHi; ++r)
                        for (size_t c = cLo; c <= cHi; ++c) {
                            double w[3];
                            const double px = fr.west + (double(c) + 0.5) * fr.pixelSizeM,
                                         py = fr.north - (double(r) + 0.5) * fr.pixelSizeM;
                            if (!weights(x, y, px, py, w)) continue;
                            face_[r * fr.width + c] = f;
                            tri_[r * fr.width + c] = uint8_t(std::min<size_t>(t, 255));
                        }
                }
            }
            for (size_t i = rowLo * fr.width; i < rowHi * fr.width; ++i) count[worker] += face_[i] != kNone;
        }
    });
    for (uint64_t c : count) covered_ += c;
}

float MeshCover::at(const MeshField& field, size_t i, const std::vector<uint8_t>* dryNodes,
                    const MeshField* bed) const {
    const uint32_t f = face_[i];
    if (f == kNone) return NAN;
    if (field.at == MeshAt::Face) {
        const double v = field.values[f];
        if (bed && !bed->values.empty() && bed->at == MeshAt::Face && !(v > bed->values[f])) return NAN;
        return float(v);
    }
    const uint64_t s = mesh_.faceStart[f];
    const uint32_t n[3] = {mesh_.faceNodes[s], mesh_.faceNodes[s + tri_[i] + 1], mesh_.faceNodes[s + tri_[i] + 2]};
    if (dryNodes && (*dryNodes)[n[0]] && (*dryNodes)[n[1]] && (*dryNodes)[n[2]]) return NAN;
    const size_t c = i % frame_.width, r = i / frame_.width;
    const double x[3] = {mesh_.nodeX[n[0]], mesh_.nodeX[n[1]], mesh_.nodeX[n[2]]},
                 y[3] = {mesh_.nodeY[n[0]], mesh_.nodeY[n[1]], mesh_.nodeY[n[2]]};
    double w[3] = {0, 0, 0};
    weights(x, y, frame_.west + (double(c) + 0.5) * frame_.pixelSizeM,
            frame_.north - (double(r) + 0.5) * frame_.pixelSizeM, w);
    return float(w[0] * field.values[n[0]] + w[1] * field.values[n[1]] + w[2] * field.values[n[2]]);
}

std::vector<float> MeshCover::sample(const MeshField& field) const { return sampleLevel(field, MeshField{}); }

std::vector<float> MeshCover::sampleLevel(const MeshField& level, const MeshField& bed) const {
    std::vector<uint8_t> dry;
    const bool nodeBed = level.at == MeshAt::Node && bed.at == MeshAt::Node && bed.values.size() == level.values.size();
    if (nodeBed) {
        dry.resize(level.values.size());
        for (size_t k = 0; k < dry.size(); ++k) dry[k] = !(level.values[k] > bed.values[k]);
    }
    std::vector<float> out(face_.size());
    parallelFor(frame_.height, 16, threads_, [&](size_t r0, size_t r1, unsigned) {
        for (size_t i = r0 * frame_.width; i < r1 * frame_.width; ++i)
            out[i] = at(level, i, nodeBed ? &dry : nullptr, bed.values.empty() ? nullptr : &bed);
    });
    return out;
}

}  // namespace hc::ingest::detail
