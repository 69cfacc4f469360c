// heightcast/support/on_ranks.h: main() of a tool that runs as one process or as the ranks of `mpirun -np N`
// (hc-ingest, hc-influence; core/ranks/ranks.h, docs/design.md section 7).
//
// Under mpirun: rank 0 prints what one process prints (the other ranks' standard output is dropped; each says its
// share once on stderr, "rank K/N"), an error every rank raised together (ranks::RanksError) is reported once by
// rank 0 and every rank exits 1, and an error one rank saw alone is reported with its rank and stops every rank
// (MPI_Abort) after that rank's atomic writers removed their temporaries (the stack is unwound first).
#pragma once

#include <cstdio>
#include <functional>

#include "heightcast/support/cli.h"
#include "heightcast/core/ranks.h"

namespace hc::cli {

inline int runOnRanks(const char* program, int& argc, char**& argv, const std::function<int()>& body) {
    std::optional<ranks::Session> session;
    return run(program, [&]() -> int {
        session.emplace(argc, argv);
        if (ranks::rank() != 0 && !std::freopen("/dev/null", "w", stdout))
            throw Error("cannot silence standard output");
        try {
            return body();
        } catch (const ranks::RanksError&) {
            if (ranks::rank() != 0) return 1;  // rank 0 says it
            throw;
        } catch (const std::exception& e) {
            if (!ranks::distributed()) throw;
            std::fprintf(stderr, "%s: error: %s: %s\n", program, ranks::name().c_str(), e.what());
            std::fflush(stderr);
            ranks::abortAll(1);
            return 1;
        }
    });
}

}  // namespace hc::cli
