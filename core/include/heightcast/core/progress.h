// heightcast/core/progress.h: GDAL-style terminal progress ("0...10...20...30...40...50...60...70...80...90...100 -
// done.").
//
// Thread-safe: workers may call advance() concurrently. Prints to stderr; silent when disabled.
#pragma once

#include <atomic>
#include <cstdint>
#include <mutex>
#include <string>

namespace hc {

class Progress {
public:
    Progress(std::string label, uint64_t total, bool enabled = true);
    ~Progress();  // finishes the line if work stopped early (no dangling output)
    Progress(const Progress&) = delete;
    Progress& operator=(const Progress&) = delete;

    void advance(uint64_t amount);
    void finish();

private:
    void printUpTo(int tick);
    std::string label_;
    uint64_t total_;
    bool enabled_;
    std::atomic<uint64_t> done_{0};
    std::mutex mutex_;
    int printedTick_ = -1;  // ticks are 0..40 (every 2.5 %), as GDALTermProgress
    bool finished_ = false;
};

// Peak resident set size of this process so far, in bytes (getrusage).
uint64_t peakRssBytes();
// Current resident set size in bytes (/proc/self/statm), 0 where unavailable.
uint64_t currentRssBytes();

}  // namespace hc
