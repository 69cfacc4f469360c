// ranks_check RANK [outside]: a program that runs under mpirun as hc-ingest and hc-influence do (support/on_ranks.h)
// and fails on one rank only (1-based RANK; 0: none), inside ranks::together (the others reach the same agreement point
// and stop there with the same error, reported once by rank 1) or, with `outside`, where no other rank waits for it (it
// reports with its own name and stops every rank). After the agreement, a collective the ranks only reach together: a
// disagreement would hang there, and the test's timeout would fail it. The MPI tests (mpi.cmake) run it.
// ranks_check in-memory: every rank builds a grid in memory (ingest::buildGrid), which ranks do not do (each writes its
// own cells into a file): every rank refuses it alike, none waits for the others.
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "heightcast/ingest/build.h"
#include "heightcast/support/on_ranks.h"

int main(int argc, char** argv) {
    return hc::cli::runOnRanks("ranks_check", argc, argv, [&] {
        namespace ranks = hc::ranks;
        if (argc > 1 && std::string(argv[1]) == "in-memory") {
            hc::ingest::Raster r;
            r.width = r.height = 64;
            r.pixelSizeM = 10;
            for (size_t i = 0; i < r.width * r.height; ++i) r.values.push_back(float(i % 97));
            (void)hc::ingest::buildGrid(r, nullptr, hc::ingest::BuildOptions{});
            std::printf("ranks_check: built in memory\n");
            return 0;
        }
        const int failing = argc > 1 ? std::atoi(argv[1]) : 0;
        const bool outside = argc > 2 && std::string(argv[2]) == "outside";
        if (outside && ranks::rank() + 1 == failing) throw hc::Error("failed alone, outside together");
        ranks::together([&] {
            if (!outside && ranks::rank() + 1 == failing) throw hc::Error("failed inside together");
        });
        const auto all = ranks::allGatherVectors(std::vector<int>{ranks::rank()});
        if (ranks::rank() == 0) std::printf("ranks_check: %zu ranks agreed\n", all.size());
        return 0;
    });
}
