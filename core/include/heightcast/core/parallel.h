// heightcast/core/parallel.h: a minimal parallel for-loop over an index range.
//
// Work is handed out in chunks from an atomic counter, so uneven items balance. The first exception
// thrown by any worker is rethrown in the caller after all workers stop.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace hc {

// Number of worker threads for `requested` (0 = all hardware threads).
inline unsigned resolveThreads(unsigned requested) {
    if (requested > 0) return requested;
    unsigned hw = std::thread::hardware_concurrency();
    return hw == 0 ? 1 : hw;
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
        std::vector<std::thread> pool;
        for (unsigned t = 1; t < threads; ++t) pool.emplace_back(work, t);
        work(0);
        for (auto& t : pool) t.join();
    }
    if (error) std::rethrow_exception(error);
}

}  // namespace hc
