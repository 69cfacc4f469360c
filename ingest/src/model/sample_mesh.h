// ingest/src/model/sample_mesh.h: a mesh's fields sampled at the pixel centres of a working raster (private to
// ingest/).
#pragma once

#include <cstdint>
#include <vector>

#include "heightcast/ingest/mesh.h"

namespace hc::ingest::detail {

// The pixels of a north-up raster of square pixels (raster.h's frame), in the mesh's (metric) coordinates.
struct PixelFrame {
    double west = 0, north = 0, pixelSizeM = 1;
    size_t width = 0, height = 0;
};

// Which face (and which triangle of its fan from its first node) holds each pixel's centre: found once, used for the
// bed and every step. A centre on an edge shared by two faces goes to the later face in the file's order; a centre
// that no face holds has none (a hole, or dry land outside the model's domain). 5 bytes a pixel.
class MeshCover {
public:
    MeshCover(const ModelMesh& mesh, const PixelFrame& frame, unsigned threads);
    // The field at every pixel centre (width * height, row 0 northern-most): a face's value over it, or the node values
    // interpolated linearly over the triangle; NaN where no face holds the centre or a value is NaN.
    std::vector<float> sample(const MeshField& field) const;
    // The water level at every pixel centre, NaN where the model is dry there: a face whose level is not above its bed,
    // a triangle whose three nodes are all dry (`bed`: the model's own, at the level's place; empty: levels only).
    std::vector<float> sampleLevel(const MeshField& level, const MeshField& bed) const;
    uint64_t covered() const { return covered_; }
    const PixelFrame& frame() const { return frame_; }

private:
    float at(const MeshField& field, size_t pixel, const std::vector<uint8_t>* dryNodes, const MeshField* bed) const;
    const ModelMesh& mesh_;
    PixelFrame frame_;
    unsigned threads_;
    std::vector<uint32_t> face_;  // UINT32_MAX: none
    std::vector<uint8_t> tri_;
    uint64_t covered_ = 0;
};

// The side of the finest faces, for the working raster's pixel: the 1st percentile of the faces' square roots of area
// (a few slivers do not make the raster huge), at least 1e-3 of the mesh's extent.
double finestFaceSide(const ModelMesh& mesh);

}  // namespace hc::ingest::detail
