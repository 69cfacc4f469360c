// heightcast/core/timer.h: the one wall-clock timer every stage, tool and benchmark uses.
//
// A Stopwatch starts when made; seconds() is the time since then (or since the last restart()), monotonic
// (std::chrono::steady_clock), so a clock change during a run never gives a negative or jumped figure.
#pragma once

#include <chrono>

namespace hc {

class Stopwatch {
public:
    using Clock = std::chrono::steady_clock;
    Stopwatch() : start_(Clock::now()) {}
    // Seconds since construction or the last restart().
    double seconds() const { return std::chrono::duration<double>(Clock::now() - start_).count(); }
    // Milliseconds, for per-frame figures.
    double milliseconds() const { return seconds() * 1e3; }
    // Returns seconds() and starts again: one call per stage of a sequence.
    double lap() {
        const Clock::time_point now = Clock::now();
        const double s = std::chrono::duration<double>(now - start_).count();
        start_ = now;
        return s;
    }
    void restart() { start_ = Clock::now(); }

private:
    Clock::time_point start_;
};

}  // namespace hc
