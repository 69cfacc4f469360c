// The helper threads of parallelFor (parallel.h): one pool per process, kept between calls.
#include "heightcast/core/parallel.h"

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <thread>
#include <vector>

namespace hc::detail {
namespace {

thread_local bool tInPool = false;   // this thread is one of the pool's
thread_local bool tServing = false;  // this thread's call is being served (a call nested in it must not wait on it)

// Waits a little on the CPU before sleeping: up to kSpin for a condition that another thread is about to make true.
// A frame makes some 50 calls, most of them a few microseconds after the last one ends; a helper asleep in the kernel
// takes tens of microseconds to wake, one still spinning well under one (hc-bench-parallel measures both; commit
// 8b54b6e has the figures). The spin is bounded so that a pool with nothing to do soon gives its cores back (to the PNG
// encoder of a flight, say).
constexpr auto kSpin = std::chrono::microseconds(50);

inline void cpuRelax() {
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#endif
}

template <class Ready>
bool spinUntil(Ready&& ready) {
    const auto until = std::chrono::steady_clock::now() + kSpin;
    for (int k = 0;; ++k) {
        if (ready()) return true;
        cpuRelax();
        if ((k & 63) == 63 && std::chrono::steady_clock::now() >= until) return ready();
    }
}

// The pool serves one call at a time (`serving`); helper k runs worker k + 1 of the call whose generation it has not
// seen yet, if the call wants that many. The generation and the helpers still running are atomics, so that a helper
// spinning after its last call (spinUntil) sees the next one without the mutex, and the caller its helpers' end; the
// condition variables serve those that went to sleep (`sleeping_`, under the mutex).
class Pool {
public:
    ~Pool() {
        {
            std::lock_guard lock(m_);
            stop_ = true;
            generation_.fetch_add(1);
        }
        wake_.notify_all();
        for (std::thread& t : threads_) t.join();
    }

    // False (and nothing run) when the pool is serving another call.
    bool run(unsigned threads, void (*fn)(void*, unsigned), void* ctx) {
        if (tInPool || tServing) return false;
        std::unique_lock serving(serving_, std::try_to_lock);
        if (!serving.owns_lock()) return false;
        struct Mark {
            Mark() { tServing = true; }
            ~Mark() { tServing = false; }
        } mark;
        const unsigned helpers = threads - 1;
        bool wake = false;
        {
            std::lock_guard lock(m_);
            while (threads_.size() < helpers) {
                const unsigned k = unsigned(threads_.size());
                threads_.emplace_back([this, k] { helper(k); });
            }
            fn_ = fn, ctx_ = ctx, wanted_ = helpers;
            running_.store(helpers);
            generation_.fetch_add(1);  // after the call's fields: a helper reads them once it sees the generation
            wake = sleeping_ > 0;
        }
        if (wake) wake_.notify_all();
        fn(ctx, 0);
        if (spinUntil([&] { return running_.load() == 0; })) return true;
        std::unique_lock lock(m_);
        done_.wait(lock, [&] { return running_.load() == 0; });
        return true;
    }

private:
    void helper(unsigned k) {
        tInPool = true;
        uint64_t seen = 0;
        for (;;) {
            if (!spinUntil([&] { return generation_.load() != seen; })) {
                std::unique_lock lock(m_);
                ++sleeping_;
                wake_.wait(lock, [&] { return generation_.load() != seen; });
                --sleeping_;
            }
            void (*fn)(void*, unsigned) = nullptr;
            void* ctx = nullptr;
            {
                std::lock_guard lock(m_);  // the call's fields, as the caller wrote them before the generation
                if (stop_) return;
                seen = generation_.load();
                if (k >= wanted_) continue;
                fn = fn_, ctx = ctx_;
            }
            fn(ctx, k + 1);
            if (running_.fetch_sub(1) == 1) {  // the last helper: the caller may be asleep
                std::lock_guard lock(m_);
                done_.notify_one();
            }
        }
    }

    std::mutex serving_;  // held by the call being served
    std::mutex m_;        // the fields below but the atomics
    std::condition_variable wake_, done_;
    std::vector<std::thread> threads_;
    std::atomic<uint64_t> generation_{0};
    std::atomic<unsigned> running_{0};
    unsigned wanted_ = 0, sleeping_ = 0;
    void (*fn_)(void*, unsigned) = nullptr;
    void* ctx_ = nullptr;
    bool stop_ = false;
};

}  // namespace

void runOnThreads(unsigned threads, void (*fn)(void*, unsigned), void* ctx) {
    static Pool pool;
    if (threads <= 1) {
        fn(ctx, 0);
        return;
    }
    if (pool.run(threads, fn, ctx)) return;
    std::vector<std::thread> own;
    for (unsigned t = 1; t < threads; ++t) own.emplace_back(fn, ctx, t);
    fn(ctx, 0);
    for (std::thread& t : own) t.join();
}

}  // namespace hc::detail
