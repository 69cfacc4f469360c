// The helper threads of parallelFor (parallel.h): one pool per process, kept between calls.
#include "heightcast/core/parallel.h"

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <thread>
#include <vector>

namespace hc::detail {
namespace {

thread_local bool tInPool = false;   // this thread is one of the pool's
thread_local bool tServing = false;  // this thread's call is being served (a call nested in it must not wait on it)

// How long a helper that finished its share, and a caller waiting for its helpers, spin before they sleep. A frame's
// calls come in bursts (a CPU frame at 105 M cells makes about 18, separated by microseconds to milliseconds of work on
// one thread). When every helper slept between calls and the caller slept until they were done, a call of trivial work
// on 2 threads cost 43-60 us on this project's 2-core machine (a futex wake and a context switch each way, in a virtual
// machine); spinning, 0.1-0.3 us, and 26-53 us after a pause long enough for the helpers to sleep (hc-bench-parallel).
constexpr auto kSpin = std::chrono::microseconds(100);

// Spins until done() or kSpin has passed; returns done().
template <typename Done>
bool spinUntil(Done done) {
    const auto until = std::chrono::steady_clock::now() + kSpin;
    for (;;) {
        for (int k = 0; k < 64; ++k) {
            if (done()) return true;
#if defined(__x86_64__) || defined(__i386__)
            __builtin_ia32_pause();
#endif
        }
        if (std::chrono::steady_clock::now() >= until) return done();
    }
}

// The pool serves one call at a time (`serving`); helper k runs worker k + 1 of the call whose generation it has not
// seen yet, if the call wants that many. The generation and the helpers a call wants are one atomic (call_), raised
// after the call's function is written; a helper that takes part reads the function knowing that the caller waits for
// it (running_) before the next call can change it.
class Pool {
public:
    ~Pool() {
        {
            std::lock_guard lock(m_);
            stop_ = true;
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
        if (helpers >= kHelpersPerCall) return false;
        {
            std::lock_guard lock(m_);
            while (threads_.size() < helpers) {
                const unsigned k = unsigned(threads_.size());
                threads_.emplace_back([this, k] { helper(k); });
            }
            fn_ = fn, ctx_ = ctx;
            running_.store(helpers, std::memory_order_relaxed);
            call_.store(((call_.load(std::memory_order_relaxed) / kHelpersPerCall) + 1) * kHelpersPerCall + helpers, std::memory_order_release);
        }
        wake_.notify_all();  // the sleeping ones (no system call where none sleeps)
        fn(ctx, 0);
        if (spinUntil([&] { return running_.load(std::memory_order_acquire) == 0; })) return true;
        std::unique_lock lock(m_);
        done_.wait(lock, [&] { return running_.load(std::memory_order_acquire) == 0; });
        return true;
    }

private:
    void helper(unsigned k) {
        tInPool = true;
        uint64_t seen = 0;
        for (;;) {
            // The next call: spun for a while, then slept for.
            auto fresh = [&] { return stop_.load(std::memory_order_acquire) || call_.load(std::memory_order_acquire) / kHelpersPerCall != seen; };
            if (!spinUntil(fresh)) {
                std::unique_lock lock(m_);
                wake_.wait(lock, fresh);
            }
            if (stop_.load(std::memory_order_acquire)) return;
            const uint64_t call = call_.load(std::memory_order_acquire);
            seen = call / kHelpersPerCall;
            if (k >= call % kHelpersPerCall) continue;
            fn_(ctx_, k + 1);  // this call's: the caller publishes no other before running_ reaches 0
            if (running_.fetch_sub(1, std::memory_order_acq_rel) == 1) {
                std::lock_guard lock(m_);  // so that a caller about to sleep on done_ sees it
                done_.notify_one();
            }
        }
    }

    std::mutex serving_;  // held by the call being served
    std::mutex m_;        // the threads, the calls' publication, the sleeps
    std::condition_variable wake_, done_;
    std::vector<std::thread> threads_;
    static constexpr uint64_t kHelpersPerCall = 1 << 16;  // call_: generation * kHelpersPerCall + the helpers it wants
    std::atomic<uint64_t> call_{0};
    std::atomic<unsigned> running_{0};
    void (*fn_)(void*, unsigned) = nullptr;
    void* ctx_ = nullptr;
    std::atomic<bool> stop_{false};
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
