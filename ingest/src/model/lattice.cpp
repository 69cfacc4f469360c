// The quadtree a mesh of square faces makes, its lattice fitted to every node by least squares (lattice.h).
#include "lattice.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <fmt/format.h>

#include "heightcast/core/error.h"
#include "heightcast/grid/grid.h"

namespace hc::ingest::detail {
namespace {

std::string num(double v) { return fmt::format("{:.9g}", v); }

// The default tolerance: a node's coordinates are rounded to their storage, each by up to half an ulp at their
// magnitude; the fit's own lattice adds the same again. Two ulps of float32 (or four of double) at the largest
// coordinate cover both, plus 1e-6 of the finest side for what the model computed in its own arithmetic.
double defaultTolerance(const ModelMesh& m, double finest) {
    double big = 0;
    for (size_t i = 0; i < m.nodeX.size(); ++i) big = std::max({big, std::abs(m.nodeX[i]), std::abs(m.nodeY[i])});
    const double ulp = big > 0 ? std::ldexp(1.0, std::ilogb(big) - (m.coordsFloat32 ? 23 : 52)) : 0;
    return (m.coordsFloat32 ? 2 : 4) * ulp + 1e-6 * finest;
}

struct FaceShape {
    double side = 0, angle = 0;  // mean side; first edge's angle modulo 90 degrees, in (-45, 45]
};

double angleMod90(double deg) {
    double a = std::remainder(deg, 90.0);
    return a <= -45.0 ? a + 90.0 : a;
}

// Four nodes, square to `slack` (sides within slack of their mean, corners right within the same).
FaceShape faceShape(const ModelMesh& m, size_t f, double slackOf1) {
    if (m.nodesOf(f) != 4)
        throw Error(m.source + ": " + m.nameOf(f) + " has " + std::to_string(m.nodesOf(f)) +
                    " nodes: a quadtree mesh has square faces of 4 nodes");
    double ex[4], ey[4], len[4], s = 0;
    for (int e = 0; e < 4; ++e) {
        const uint32_t a = m.faceNodes[m.faceStart[f] + size_t(e)],
                       b = m.faceNodes[m.faceStart[f] + size_t((e + 1) % 4)];
        ex[e] = m.nodeX[b] - m.nodeX[a], ey[e] = m.nodeY[b] - m.nodeY[a];
        len[e] = std::hypot(ex[e], ey[e]);
        s += len[e] / 4;
    }
    if (!(len[0] > 0))
        throw Error(m.source + ": " + m.nameOf(f) + " has two nodes at one place: a quadtree mesh has square faces");
    const double slack = slackOf1 + 1e-6 * s;
    for (int e = 0; e < 4; ++e)
        if (std::abs(len[e] - len[0]) > 2 * slack)
            throw Error(m.source + ": " + m.nameOf(f) + " is not a square (sides " + num(len[0]) + " and " +
                        num(len[e]) + " m): not a quadtree mesh");
    for (int e = 0; e < 4; ++e)
        if (std::abs(ex[e] * ex[(e + 1) % 4] + ey[e] * ey[(e + 1) % 4]) > 4 * slack * s)
            throw Error(m.source + ": " + m.nameOf(f) +
                        " is not a square (its corners are not right angles): not a quadtree mesh");
    return {s, angleMod90(std::atan2(ey[0], ex[0]) * 180.0 / M_PI)};
}

// The faces' common orientation: the mean of their edges' angles modulo 90 degrees (as a mean of unit vectors at four
// times the angle, so -44.9 and 44.9 average to 45, not 0).
double commonAngle(const std::vector<FaceShape>& shapes) {
    double sx = 0, sy = 0;
    for (const FaceShape& s : shapes) {
        const double r = 4 * s.angle * M_PI / 180.0;
        sx += s.side * std::cos(r), sy += s.side * std::sin(r);
    }
    return angleMod90(std::atan2(sy, sx) * 180.0 / M_PI / 4);
}

// x = a i - b j + tx, y = b i + a j + ty, relative to a reference point: the similarity that maps lattice indices
// (i, j) to coordinates, fitted by least squares (its normal equations decouple once both sides are centred).
struct Similarity {
    double a = 1, b = 0, tx = 0, ty = 0;
    void toLattice(double x, double y, double& i, double& j) const {
        const double dx = x - tx, dy = y - ty, n = a * a + b * b;
        i = (a * dx + b * dy) / n, j = (-b * dx + a * dy) / n;
    }
};

Similarity fitSimilarity(const std::vector<double>& x, const std::vector<double>& y, const std::vector<int64_t>& i,
                         const std::vector<int64_t>& j, bool turned) {
    const double n = double(x.size());
    double mx = 0, my = 0, mi = 0, mj = 0;
    for (size_t k = 0; k < x.size(); ++k)
        mx += x[k] / n, my += y[k] / n, mi += double(i[k]) / n, mj += double(j[k]) / n;
    double sii = 0, sa = 0, sb = 0;
    for (size_t k = 0; k < x.size(); ++k) {
        const double di = double(i[k]) - mi, dj = double(j[k]) - mj, dx = x[k] - mx, dy = y[k] - my;
        sii += di * di + dj * dj, sa += di * dx + dj * dy, sb += di * dy - dj * dx;
    }
    Similarity s;
    if (!(sii > 0)) return s;  // every node on one lattice point: no fit (the caller's residuals refuse it)
    s.a = sa / sii, s.b = turned ? sb / sii : 0.0;
    s.tx = mx - s.a * mi + s.b * mj, s.ty = my - s.b * mi - s.a * mj;
    return s;
}

}  // namespace

bool looksLikeQuadtree(const ModelMesh& m, double slack, std::string& why) {
    // Each face: four nodes, its sides within `slack` of each other (the fit checks right angles and rounding).
    double smallest = std::numeric_limits<double>::infinity();
    std::vector<double> sides(m.faceCount());
    for (size_t f = 0; f < m.faceCount(); ++f) {
        if (m.nodesOf(f) != 4) return why = m.nameOf(f) + " has " + std::to_string(m.nodesOf(f)) + " nodes", false;
        double len[4];
        for (int e = 0; e < 4; ++e) {
            const uint32_t a = m.faceNodes[m.faceStart[f] + size_t(e)],
                           b = m.faceNodes[m.faceStart[f] + size_t((e + 1) % 4)];
            len[e] = std::hypot(m.nodeX[b] - m.nodeX[a], m.nodeY[b] - m.nodeY[a]);
        }
        const auto [lo, hi] = std::minmax_element(len, len + 4);
        if (*hi - *lo > slack * *hi) return why = m.nameOf(f) + " is not a square", false;
        sides[f] = (len[0] + len[1] + len[2] + len[3]) / 4;
        smallest = std::min(smallest, sides[f]);
    }
    for (size_t f = 0; f < m.faceCount(); ++f) {
        const double r = std::log2(sides[f] / smallest);
        if (std::abs(std::exp2(std::round(r)) * smallest - sides[f]) > slack * sides[f])
            return why = m.nameOf(f) + "'s side is no power-of-two multiple of the smallest", false;
    }
    return true;
}

QuadtreeFit fitQuadtree(const ModelMesh& m, double toleranceM) {
    auto fail = [&](const std::string& what) -> void { throw Error(m.source + ": " + what); };
    const size_t n = m.faceCount();
    // Structure: square faces, one orientation, power-of-two sides (to the tolerance the fit will hold them to).
    double smallest = std::numeric_limits<double>::infinity();
    for (size_t f = 0; f < n; ++f)
        smallest = std::min(
            smallest, std::hypot(m.nodeX[m.faceNodes[m.faceStart[f] + 1]] - m.nodeX[m.faceNodes[m.faceStart[f]]],
                                 m.nodeY[m.faceNodes[m.faceStart[f] + 1]] - m.nodeY[m.faceNodes[m.faceStart[f]]]));
    QuadtreeFit q;
    q.tolerance = toleranceM >= 0 ? toleranceM : defaultTolerance(m, smallest);
    // The faces' shapes are checked to the coordinates' own precision (or a larger tolerance given): a tighter one
    // given is held against the fit's residuals below, which name the face that lies off.
    const double slack = std::max(q.tolerance, defaultTolerance(m, smallest));
    std::vector<FaceShape> shapes(n);
    for (size_t f = 0; f < n; ++f) shapes[f] = faceShape(m, f, slack);
    const double theta = commonAngle(shapes);
    for (size_t f = 0; f < n; ++f) {
        const double slackDeg = std::atan2(4 * slack, shapes[f].side) * 180.0 / M_PI + 1e-6;
        if (std::abs(std::remainder(shapes[f].angle - theta, 90.0)) <= slackDeg) continue;
        size_t other = 0;  // the face turned furthest from this one, to name beside it
        for (size_t g = 0; g < n; ++g)
            if (std::abs(std::remainder(shapes[g].angle - shapes[f].angle, 90.0)) >
                std::abs(std::remainder(shapes[other].angle - shapes[f].angle, 90.0)))
                other = g;
        fail(m.nameOf(f) + " is turned by " + num(shapes[f].angle) + " degrees, " + m.nameOf(other) + " by " +
             num(shapes[other].angle) + ": a quadtree's faces share one orientation");
    }
    double minSide = std::numeric_limits<double>::infinity();
    for (const FaceShape& s : shapes) minSide = std::min(minSide, s.side);
    // Each face's level by its side's ratio to the smallest; then each side against its level's multiple of the mean
    // finest side (the smallest side alone is biased low where nodes scatter by their rounding).
    q.level.resize(n);
    double sumSide = 0, sumScale = 0;
    for (size_t f = 0; f < n; ++f) {
        const int l = int(std::lround(std::log2(shapes[f].side / minSide)));
        if (l < 0 || l > kMaxLevel || std::abs(shapes[f].side / std::ldexp(minSide, l) - 1) > 0.01)
            fail(m.nameOf(f) + " has a side of " + num(shapes[f].side) +
                 " m, not a power-of-two multiple of the smallest face's " + num(minSide) + " m: not a quadtree mesh");
        q.level[f] = l;
        sumSide += shapes[f].side, sumScale += std::ldexp(1.0, l);
    }
    const double meanFinest = sumSide / sumScale;
    for (size_t f = 0; f < n; ++f)
        if (std::abs(shapes[f].side - std::ldexp(meanFinest, q.level[f])) > 2 * slack + 1e-6 * shapes[f].side)
            fail(m.nameOf(f) + " has a side of " + num(shapes[f].side) + " m, " +
                 num(std::ldexp(meanFinest, q.level[f])) + " m for 2^" + std::to_string(q.level[f]) +
                 " faces of the finest side (" + num(meanFinest) +
                 " m on average): not a power-of-two multiple of it " + "to " + num(2 * slack) +
                 " m: not a quadtree mesh");
    // The nodes the faces use, relative to the first face's first node (no UTM magnitude is rotated or squared).
    std::vector<int64_t> slot(m.nodeX.size(), -1);
    std::vector<size_t> nodes, faceOf;
    for (size_t f = 0; f < n; ++f)
        for (uint64_t k = m.faceStart[f]; k < m.faceStart[f + 1]; ++k)
            if (slot[m.faceNodes[k]] < 0)
                slot[m.faceNodes[k]] = int64_t(nodes.size()), nodes.push_back(m.faceNodes[k]), faceOf.push_back(f);
    const double refX = m.nodeX[nodes[0]], refY = m.nodeY[nodes[0]];
    std::vector<double> x(nodes.size()), y(nodes.size());
    for (size_t k = 0; k < nodes.size(); ++k) x[k] = m.nodeX[nodes[k]] - refX, y[k] = m.nodeY[nodes[k]] - refY;
    // Lattice indices from the first estimate (mean side, common angle), then from the fitted lattice once more.
    Similarity s;
    const double s0 = sumSide / sumScale, t = theta * M_PI / 180.0;
    s.a = s0 * std::cos(t), s.b = s0 * std::sin(t);
    std::vector<int64_t> i(nodes.size()), j(nodes.size());
    for (int pass = 0; pass < 3; ++pass) {
        for (size_t k = 0; k < nodes.size(); ++k) {
            double fi = 0, fj = 0;
            s.toLattice(x[k], y[k], fi, fj);
            i[k] = std::llround(fi), j[k] = std::llround(fj);
        }
        s = fitSimilarity(x, y, i, j, true);
        // An axis-aligned mesh stays exactly unturned: a turn that moves no node by a tenth of the tolerance is none.
        int64_t span = 1;
        for (size_t k = 0; k < nodes.size(); ++k) span = std::max({span, std::abs(i[k]), std::abs(j[k])});
        if (std::abs(s.b) * double(span) < 0.1 * q.tolerance) s = fitSimilarity(x, y, i, j, false);
    }
    // Residuals.
    double sumSq = 0;
    size_t worst = 0;
    for (size_t k = 0; k < nodes.size(); ++k) {
        const double ex = s.a * double(i[k]) - s.b * double(j[k]) + s.tx - x[k],
                     ey = s.b * double(i[k]) + s.a * double(j[k]) + s.ty - y[k];
        const double r = std::hypot(ex, ey);
        sumSq += r * r;
        if (r > q.maxResidual) q.maxResidual = r, worst = k;
    }
    q.rmsResidual = std::sqrt(sumSq / double(nodes.size()));
    q.worstFace = faceOf[worst];
    q.finest = std::hypot(s.a, s.b);
    q.rotationDeg = std::atan2(s.b, s.a) * 180.0 / M_PI;
    if (!(q.finest > 0) || !std::isfinite(q.finest) || !std::isfinite(q.maxResidual))
        fail("the faces' nodes fit no lattice (its finest side comes out as " + num(q.finest) +
             " m): not a quadtree mesh");
    if (q.maxResidual > q.tolerance)
        fail(fmt::format(
            "the faces' nodes do not fit one lattice: a node of {} lies {:.6g} m from its lattice point (finest side "
            "{:.9g} m, "
            "turned {:.9g} degrees; tolerance {:.6g} m{}): not a quadtree mesh; --mesh-tolerance M accepts more, "
            "--mesh sample samples the faces instead",
            m.nameOf(q.worstFace), q.maxResidual, q.finest, q.rotationDeg, q.tolerance,
            m.coordsFloat32 ? ", the rounding of float32 coordinates" : ""));
    // Each face's cell: its lowest corner on the lattice, its side 2^level lattice steps.
    std::vector<int64_t> ci(n), cj(n);
    size_t coarsest = 0;
    int64_t minI = INT64_MAX, minJ = INT64_MAX;
    for (size_t f = 0; f < n; ++f) {
        int64_t lo[2] = {INT64_MAX, INT64_MAX}, hi[2] = {INT64_MIN, INT64_MIN};
        for (uint64_t k = m.faceStart[f]; k < m.faceStart[f + 1]; ++k) {
            const size_t at = size_t(slot[m.faceNodes[k]]);
            lo[0] = std::min(lo[0], i[at]), hi[0] = std::max(hi[0], i[at]), lo[1] = std::min(lo[1], j[at]),
            hi[1] = std::max(hi[1], j[at]);
        }
        const int64_t span = int64_t{1} << q.level[f];
        if (hi[0] - lo[0] != span || hi[1] - lo[1] != span)
            fail(m.nameOf(f) + "'s corner is not on the lattice of the smallest faces: not a quadtree mesh");
        ci[f] = lo[0], cj[f] = lo[1];
        minI = std::min(minI, lo[0]), minJ = std::min(minJ, lo[1]);
        if (q.level[f] > q.level[coarsest]) coarsest = f;
    }
    // The origin: on the coarsest face's lattice, at or below every face's corner, so every face aligns to its size.
    const int64_t big = int64_t{1} << q.level[coarsest];
    const int64_t oi = ci[coarsest] - (ci[coarsest] - minI + big - 1) / big * big,
                  oj = cj[coarsest] - (cj[coarsest] - minJ + big - 1) / big * big;
    q.ix.resize(n), q.iy.resize(n);
    int64_t extent = 1;
    for (size_t f = 0; f < n; ++f) {
        const int64_t span = int64_t{1} << q.level[f], fx = ci[f] - oi, fy = cj[f] - oj;
        if (fx % span != 0 || fy % span != 0)
            fail(m.nameOf(f) + " (side " + num(shapes[f].side) +
                 " m) is not aligned to its own size: not a quadtree mesh");
        if (fx + span > (int64_t{1} << kMaxRootLevel) || fy + span > (int64_t{1} << kMaxRootLevel))
            fail("the mesh spans more than 2^" + std::to_string(kMaxRootLevel) +
                 " smallest faces: too large for one grid");
        q.ix[f] = uint32_t(fx), q.iy[f] = uint32_t(fy);
        extent = std::max({extent, fx + span, fy + span});
        q.maxLevel = std::max(q.maxLevel, q.level[f]);
    }
    while ((int64_t{1} << q.rootLevel) < extent) ++q.rootLevel;
    q.originX = refX + s.a * double(oi) - s.b * double(oj) + s.tx;
    q.originY = refY + s.b * double(oi) + s.a * double(oj) + s.ty;
    return q;
}

}  // namespace hc::ingest::detail
