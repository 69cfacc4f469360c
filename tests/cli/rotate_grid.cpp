// rotate_grid: a grid file rewritten with its origin kept and its axes turned by DEG degrees (every water step
// copied), the CLI tests' way to make a rotated quadtree that hc-export then writes as a turned UGRID mesh, as a
// quadtree flood model set up at an angle to the CRS would write its map file.
//
//   rotate_grid IN.hcg OUT.hcg DEG
#include <cstdio>
#include <cstdlib>
#include <span>

#include "heightcast/core/error.h"
#include "heightcast/grid/grid_file.h"

int main(int argc, char** argv) {
    if (argc != 4) {
        std::fprintf(stderr, "usage: rotate_grid IN.hcg OUT.hcg DEG\n");
        return 2;
    }
    try {
        hc::Grid g = hc::readGrid(argv[1]);
        hc::Grid shape = g;
        shape.rotationDeg = std::atof(argv[3]);
        hc::GridFileWriter w(argv[2], shape, g.cellCount(), g.steps.size());
        w.append(g.codes, {std::span<const float>(g.values[0])});
        for (size_t k = 0; k < g.steps.size(); ++k) {
            if (k > 0) hc::readGridStep(argv[1], g, k);
            w.appendStep(hc::sparseStep(g));
        }
        w.commit(g.stats);
    } catch (const hc::Error& e) {
        std::fprintf(stderr, "rotate_grid: error: %s\n", e.what());
        return 1;
    }
    return 0;
}
