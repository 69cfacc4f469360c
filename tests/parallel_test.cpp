// parallelFor (core/parallel.h) on its pool of kept threads: every index once, worker numbers private to one thread at
// a time (the callers index per-worker scratch by them), with its threads busy or asleep when a call comes, calls
// nested in a worker or in the caller's own share, calls from several threads at once, and the first exception
// rethrown in the caller with the pool still usable after it.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <stdexcept>
#include <thread>
#include <vector>

#include "heightcast/core/parallel.h"

namespace {

// Runs parallelFor over `count` items on `threads` workers and checks each item came once and no worker number ran
// on two threads at once.
void checkOneCall(size_t count, size_t chunk, unsigned threads) {
    std::vector<std::atomic<int>> seen(count);
    std::vector<std::atomic<int>> busy(std::max(1u, threads));
    std::atomic<bool> overlap{false}, outOfRange{false};
    hc::parallelFor(count, chunk, threads, [&](size_t b, size_t e, unsigned worker) {
        if (worker >= busy.size()) {
            outOfRange = true;
            return;
        }
        if (busy[worker].fetch_add(1) != 0) overlap = true;
        for (size_t i = b; i < e; ++i) seen[i].fetch_add(1);
        busy[worker].fetch_sub(1);
    });
    EXPECT_FALSE(outOfRange);
    EXPECT_FALSE(overlap);
    for (size_t i = 0; i < count; ++i)
        ASSERT_EQ(seen[i].load(), 1) << "item " << i << " of " << count << " on " << threads << " threads";
}

}  // namespace

TEST(Parallel, EveryItemOnceAndWorkersPrivateAcrossManyCalls) {
    // Many calls in a row (the pool's threads reused), with the thread count changing between them (the pool grows to
    // the most asked for, and a call that wants fewer leaves the others idle).
    for (int round = 0; round < 200; ++round)
        for (unsigned threads : {2u, 8u, 3u, 16u, 1u}) checkOneCall(size_t(round % 7) * 37 + 1, 3, threads);
}

TEST(Parallel, CallsAfterThePoolHasSlept) {
    // Calls that find the pool's threads just done, asleep, or some of each (pauses of 0, 100 us and 2 ms).
    for (int round = 0; round < 30; ++round) {
        for (unsigned threads : {4u, 2u, 16u}) checkOneCall(100, 1, threads);
        std::this_thread::sleep_for(std::chrono::microseconds(round % 3 == 0 ? 0 : round % 3 == 1 ? 100 : 2000));
    }
}

TEST(Parallel, NestedCallsRunOnThreadsOfTheirOwn) {
    std::atomic<size_t> total{0};
    hc::parallelFor(8, 1, 4, [&](size_t b, size_t e, unsigned) {
        for (size_t i = b; i < e; ++i)
            hc::parallelFor(100, 7, 3, [&](size_t b2, size_t e2, unsigned) {
                total += e2 - b2;
            });  // in a worker and in the caller's share
    });
    EXPECT_EQ(total.load(), 800u);
}

TEST(Parallel, CallsFromSeveralThreadsAtOnce) {
    std::vector<std::thread> callers;
    std::atomic<int> failures{0};
    for (int c = 0; c < 4; ++c)
        callers.emplace_back([&] {
            for (int round = 0; round < 100; ++round) {
                std::atomic<size_t> n{0};
                hc::parallelFor(1000, 10, 4, [&](size_t b, size_t e, unsigned) { n += e - b; });
                if (n != 1000) ++failures;
            }
        });
    for (std::thread& t : callers) t.join();
    EXPECT_EQ(failures.load(), 0);
}

TEST(Parallel, FirstExceptionReachesTheCallerAndThePoolGoesOn) {
    for (int round = 0; round < 20; ++round) {
        EXPECT_THROW(hc::parallelFor(1000, 1, 4,
                                     [&](size_t b, size_t, unsigned) {
                                         if (b == 500) throw std::runtime_error("item 500");
                                     }),
                     std::runtime_error);
        checkOneCall(1000, 1, 4);
    }
}
