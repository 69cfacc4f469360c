#include "heightcast/core/progress.h"

#include <cstdio>
#include <fstream>

#include <sys/resource.h>
#include <unistd.h>

namespace hc {

Progress::Progress(std::string label, uint64_t total, bool enabled)
    : label_(std::move(label)), total_(total), enabled_(enabled) {
    if (enabled_) {
        std::fprintf(stderr, "%s: ", label_.c_str());
        std::fflush(stderr);
        printUpTo(0);
    }
}

Progress::~Progress() {
    if (enabled_ && !finished_) {
        std::fputc('\n', stderr);
        std::fflush(stderr);
    }
}

void Progress::advance(uint64_t amount) {
    if (!enabled_) return;
    uint64_t done = done_.fetch_add(amount) + amount;
    int tick = total_ == 0 ? 40 : static_cast<int>(done * 40 / total_);
    if (tick > 40) tick = 40;
    if (tick > printedTick_ && tick < 40) {
        std::lock_guard lock(mutex_);
        printUpTo(tick);
    }
}

void Progress::finish() {
    if (!enabled_ || finished_) return;
    std::lock_guard lock(mutex_);
    printUpTo(40);
    std::fprintf(stderr, " - done.\n");
    std::fflush(stderr);
    finished_ = true;
}

// GDALTermProgress prints "0" at 0 %, "." every 2.5 %, the number every 10 %.
void Progress::printUpTo(int tick) {
    while (printedTick_ < tick) {
        ++printedTick_;
        if (printedTick_ % 4 == 0)
            std::fprintf(stderr, "%d", printedTick_ * 10 / 4);
        else
            std::fputc('.', stderr);
    }
    std::fflush(stderr);
}

uint64_t peakRssBytes() {
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    return static_cast<uint64_t>(usage.ru_maxrss) * 1024;  // Linux reports kilobytes
}

uint64_t currentRssBytes() {
    std::ifstream statm("/proc/self/statm");
    uint64_t sizePages = 0, residentPages = 0;
    if (!(statm >> sizePages >> residentPages)) return 0;
    return residentPages * static_cast<uint64_t>(sysconf(_SC_PAGESIZE));
}

}  // namespace hc
