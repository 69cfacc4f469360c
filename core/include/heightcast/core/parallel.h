// heightcast/core/parallel.h: a minimal parallel for-loop over an index range.
//
// Work is handed out in chunks from an atomic counter, so uneven items balance. The first exception
// thrown by any worker is rethrown in the caller after all workers stop.
//
// The helper threads are kept between calls (one pool per process, grown to the most threads asked for): a frame
// calls parallelFor some 50 times, and starting and joining threads each time cost a measurable share of a frame at
// 16 threads (docs/benchmarks.md). After a call they spin briefly for the next before they sleep (parallel.cpp). A call
// made while the pool serves another (from one of its own workers, or from a second thread of the caller's program)
// starts its own threads, as every call used to.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <exception>
#include <mutex>
#include <thread>

namespace hc {

namespace detail {
// Runs fn(ctx, w) for every w in [0, threads): w = 0 on the calling thread, the others on the pool's threads (or on
// threads of their own when the pool is busy); returns when every one has returned. fn must not throw.
void runOnThreads(unsigned threads, void (*fn)(void*, unsigned), void* ctx);
}  // namespace detail

// Number of worker threads for `requested` (0 = all hardware threads). The count is asked once: glibc reads it from
// /sys at every call (a file read in every parallelFor of 0 threads, the renderer's default).
inline unsigned resolveThreads(unsigned requested) {
    if (requested > 0) return requested;
    static const unsigned hw = std::max(1u, std::thread::hardware_concurrency());
    return hw;
}

// Calls fn(begin, end, worker) for disjoint chunks covering [0, count); worker is in [0, threads).
template <typename Fn>
void parallelFor(size_t count, size_t chunk, unsigned threads, Fn&& fn) {
    threads = resolveThreads(threads);
    if (chunk == 0) chunk = 1;
    size_t chunks = (count + chunk - 1) / chunk;
    threads = static_cast<unsigned>(std::min<size_t>(threads, std::max<size_t>(chunks, 1)));
    std::atomic<size_t> next{0};
    std::exception_ptr error;
    std::mutex errorMutex;
    auto work = [&](unsigned worker) {
        try {
            for (;;) {
                size_t c = next.fetch_add(1);
                if (c >= chunks) break;
                size_t b = c * chunk;
                fn(b, std::min(count, b + chunk), worker);
            }
        } catch (...) {
            std::lock_guard lock(errorMutex);
            if (!error) error = std::current_exception();
            next.store(chunks);
        }
    };
    if (threads <= 1) {
        work(0);
    } else {
        detail::runOnThreads(
            threads, [](void* w, unsigned worker) { (*static_cast<decltype(work)*>(w))(worker); }, &work);
    }
    if (error) std::rethrow_exception(error);
}

}  // namespace hc
