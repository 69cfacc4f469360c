// ingest/src/model/lattice.h: the quadtree a mesh of square faces makes, its lattice fitted to every node (private to
// ingest/).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "heightcast/ingest/mesh.h"

namespace hc::ingest::detail {

struct QuadtreeFit {
    double originX = 0, originY = 0;  // the grid's south-west corner in the mesh's coordinates
    double finest = 0;                // side of the finest faces
    double rotationDeg = 0;           // the lattice's axes against the coordinates', in (-45, 45]
    std::vector<uint32_t> ix, iy;     // each face's south-west corner in finest units from the origin
    std::vector<int> level;           // each face's level (side = finest * 2^level)
    int rootLevel = 0, maxLevel = 0;
    double maxResidual = 0;  // the largest distance of a node from its lattice point
    double rmsResidual = 0;
    size_t worstFace = 0;
    double tolerance = 0;  // what the fit accepted
};

// Whether the mesh looks like a quadtree (every face four nodes, square to `slack` of its side, sides power-of-two
// multiples of the smallest to `slack`): what decides, for a mesh of no quadtree model, between its faces as cells and
// sampling. On false, `why` names the first face that is not.
bool looksLikeQuadtree(const ModelMesh& mesh, double slack, std::string& why);

// The lattice of rotation, origin and finest size that fits every node best (least squares), each face's cell on it.
// Accepts when every node lies within `toleranceM` of its lattice point (toleranceM < 0: the default, which covers the
// coordinates' own rounding: a few float32 ulps at their magnitude, or 1e-6 of the finest side for doubles). Throws
// hc::Error naming the face and the problem when the faces are no quadtree (not squares, one turned against the
// others, a side that is no power-of-two multiple of the finest, a corner off the lattice or not aligned to its size),
// and naming the worst face and its residual when the fit leaves a node beyond the tolerance.
QuadtreeFit fitQuadtree(const ModelMesh& mesh, double toleranceM);

}  // namespace hc::ingest::detail
