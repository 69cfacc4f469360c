// add_step_layer: a grid with water steps rewritten with one more step layer, NAME [UNITS], whose value on each wet
// cell is the shallow-water wave speed sqrt(g d) of its depth d (m/s): a made-up but depth-shaped field, the CLI tests'
// stand-in for a simulation's velocity magnitude (hc-export writes it into a UGRID mesh, hc-ingest --face-layers reads
// it back, hc-render --color-by draws it).
//
//   add_step_layer IN.hcg OUT.hcg NAME [UNITS]
#include <cmath>
#include <cstdio>
#include <span>

#include "heightcast/core/error.h"
#include "heightcast/grid/grid_file.h"

int main(int argc, char** argv) {
    if (argc != 4 && argc != 5) {
        std::fprintf(stderr, "usage: add_step_layer IN.hcg OUT.hcg NAME [UNITS]\n");
        return 2;
    }
    try {
        hc::Grid g = hc::readGrid(argv[1]);
        if (g.steps.empty()) throw hc::Error(std::string(argv[1]) + ": has no water steps");
        hc::Grid shape = g;
        shape.layers.push_back({argv[3], argc == 5 ? argv[4] : "m s-1"});
        shape.values.emplace_back();
        hc::GridFileWriter w(argv[2], shape, g.cellCount(), g.steps.size());
        w.append(g.codes, {std::span<const float>(g.values[0])});
        for (size_t k = 0; k < g.steps.size(); ++k) {
            if (k > 0) hc::readGridStep(argv[1], g, k);
            hc::WaterStepData step = hc::sparseStep(g);
            std::vector<float> speed;
            for (float d : step.values[0]) speed.push_back(float(std::sqrt(9.81 * double(d))));
            step.values.push_back(std::move(speed));
            w.appendStep(step);
        }
        w.commit(g.stats);
    } catch (const hc::Error& e) {
        std::fprintf(stderr, "add_step_layer: error: %s\n", e.what());
        return 1;
    }
    return 0;
}
