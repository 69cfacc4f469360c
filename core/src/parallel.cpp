// The helper threads of parallelFor (parallel.h): one pool per process, kept between calls.
#include "heightcast/core/parallel.h"

#include <condition_variable>
#include <mutex>
#include <thread>
#include <vector>

namespace hc::detail {
namespace {

thread_local bool tInPool = false;   // this thread is one of the pool's
thread_local bool tServing = false;  // this thread's call is being served (a call nested in it must not wait on it)

// The pool serves one call at a time (`serving`); helper k runs worker k + 1 of the call whose generation it has not
// seen yet, if the call wants that many.
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
        {
            std::lock_guard lock(m_);
            while (threads_.size() < helpers) {
                const unsigned k = unsigned(threads_.size());
                threads_.emplace_back([this, k] { helper(k); });
            }
            fn_ = fn, ctx_ = ctx, wanted_ = helpers, running_ = helpers;
            ++generation_;
        }
        wake_.notify_all();
        fn(ctx, 0);
        std::unique_lock lock(m_);
        done_.wait(lock, [&] { return running_ == 0; });
        return true;
    }

private:
    void helper(unsigned k) {
        tInPool = true;
        uint64_t seen = 0;
        std::unique_lock lock(m_);
        for (;;) {
            wake_.wait(lock, [&] { return stop_ || generation_ != seen; });
            if (stop_) return;
            seen = generation_;
            if (k >= wanted_) continue;
            void (*fn)(void*, unsigned) = fn_;
            void* ctx = ctx_;
            lock.unlock();
            fn(ctx, k + 1);
            lock.lock();
            if (--running_ == 0) done_.notify_one();
        }
    }

    std::mutex serving_;  // held by the call being served
    std::mutex m_;        // the fields below
    std::condition_variable wake_, done_;
    std::vector<std::thread> threads_;
    uint64_t generation_ = 0;
    unsigned wanted_ = 0, running_ = 0;
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
