// hc-bench-parallel: what one call of parallelFor (core/parallel.h) costs beyond its work, on the pool of kept
// threads: a CPU frame at 105 M cells makes about 18 calls, many of them short, so that each call's start and end is a
// fixed cost of every frame.
//
// One table: per thread count, the microseconds a call of parallelFor over `threads` chunks of trivial work takes,
// the best of three runs of --calls calls each, in three rhythms: calls back to back; each after a pause of 20 us on
// the calling thread (a pool whose threads spin after a call would still have them awake); each after a pause of
// 1 ms. The pause is not counted.
// Why a program and not a test: the figures depend on the machine; tests never time anything.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>

#include "bench_common.h"
#include "heightcast/core/error.h"
#include "heightcast/core/parallel.h"

namespace {

const char* kUsage = R"(usage: hc-bench-parallel [options]

The cost of one parallelFor call beyond its work (the pool of kept threads, core/parallel.h), in microseconds a call:
back to back, after a pause of 20 us, after a pause of 1 ms (the pool's threads sleep between calls). Best of 3 runs.

  --threads LIST   thread counts, comma-separated; 0 = all cores (default 2,0)
  --calls N        calls a run (default 20000; a tenth of it after 1 ms pauses)
  --help           this text
)";

// Microseconds a call, the best of three runs of `calls` calls, each call after `pause` on this thread (not counted).
double perCallUs(unsigned threads, int calls, std::chrono::microseconds pause) {
    const unsigned workers = hc::resolveThreads(threads);
    std::vector<double> sink(size_t(workers) * 16, 0.0);  // a cache line a worker
    double best = 1e300;
    for (int run = 0; run < 3; ++run) {
        std::chrono::duration<double, std::micro> spent{0};
        for (int c = 0; c < calls; ++c) {
            if (pause.count()) {
                const auto until = std::chrono::steady_clock::now() + pause;
                while (std::chrono::steady_clock::now() < until) {
                }
            }
            const auto t0 = std::chrono::steady_clock::now();
            hc::parallelFor(workers, 1, threads, [&](size_t b, size_t e, unsigned w) {
                for (size_t i = b; i < e; ++i) sink[size_t(w) * 16] += double(i);
            });
            spent += std::chrono::steady_clock::now() - t0;
        }
        best = std::min(best, spent.count() / calls);
    }
    if (sink[0] < 0) std::puts("");  // keeps the work
    return best;
}

}  // namespace

int main(int argc, char** argv) {
    try {
        std::vector<unsigned> threads = {2, 0};
        int calls = 20000;
        for (int i = 1; i < argc; ++i) {
            const std::string a = argv[i];
            auto value = [&]() -> std::string {
                if (i + 1 >= argc) throw hc::Error(a + ": a value is missing");
                return argv[++i];
            };
            if (a == "--help" || a == "-h") {
                std::fputs(kUsage, stdout);
                return 0;
            } else if (a == "--threads") {
                threads.clear();
                for (const std::string& t : hc::bench::splitList(value(), "--threads")) {
                    char* end = nullptr;
                    const long n = std::strtol(t.c_str(), &end, 10);
                    if (*end || n < 0 || n > 4096)
                        throw hc::Error("--threads: '" + t + "' is not a thread count (0 .. 4096)");
                    threads.push_back(unsigned(n));
                }
            } else if (a == "--calls") {
                const std::string v = value();
                char* end = nullptr;
                const long n = std::strtol(v.c_str(), &end, 10);
                if (v.empty() || *end || n < 10 || n > 100000000)
                    throw hc::Error("--calls: '" + v + "' is not a count (10 .. 1e8)");
                calls = int(n);
            } else {
                throw hc::Error("unknown option " + a + " (see --help)");
            }
        }
        std::printf("hc-bench-parallel: %u hardware threads, load average %s, %d calls a run, best of 3\n",
                    std::thread::hardware_concurrency(), hc::bench::loadAverage().c_str(), calls);
        std::printf("%8s %16s %22s %22s\n", "threads", "back to back us", "after 20 us pauses us",
                    "after 1 ms pauses us");
        for (const unsigned t : threads) {
            const double b2b = perCallUs(t, calls, std::chrono::microseconds(0));
            const double shortPause = perCallUs(t, calls, std::chrono::microseconds(20));
            const double longPause = perCallUs(t, std::max(10, calls / 10), std::chrono::microseconds(1000));
            std::printf("%8u %16.2f %22.2f %22.2f\n", hc::resolveThreads(t), b2b, shortPause, longPause);
        }
        return 0;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "hc-bench-parallel: error: %s\n", e.what());
        return 1;
    }
}
