// keepFreedMemory (core/heap.h): frame after frame, the buffers a frame allocates reuse its predecessor's pages instead
// of faulting fresh ones in from the kernel.
#include <gtest/gtest.h>

#include <sys/resource.h>

#include <memory>
#include <vector>

#include "heightcast/core/heap.h"

namespace {

long minorFaults() {
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return u.ru_minflt;
}

// One frame's allocations as renderFrame makes them at 1920 x 1080: the eleven float layers (8.3 MB each), the rays'
// directions (24.9 MB) and three cascades' textures (4.2 MB each), every byte written, freed in another order than
// allocated (the textures first, the layers last, as the caller drops its Frame). Returns the minor page faults taken.
long oneFrame() {
    const long before = minorFaults();
    const size_t pixels = 1920 * 1080;
    std::vector<std::vector<float>> layers;
    for (int i = 0; i < 11; ++i) layers.emplace_back(pixels, 0.0f);
    auto dirs = std::make_unique<std::vector<float>>(3 * pixels, 1.0f);
    std::vector<std::vector<float>> textures;
    for (int k = 0; k < 3; ++k) textures.emplace_back(1025 * 1025, 2.0f);
    textures.clear();
    dirs.reset();
    layers.clear();
    return minorFaults() - before;
}

}  // namespace

// Without keepFreedMemory this machine's glibc (2.36) took about 31,400 faults in every frame of this pattern, as many as
// in the first (tried: the frames then took 350 ms against 70 ms); with it, none after the heap has grown once.
TEST(Heap, FramesReuseTheirPredecessorsPages) {
#if defined(__SANITIZE_ADDRESS__)
    GTEST_SKIP() << "AddressSanitizer's allocator replaces glibc's malloc, and its mallopt does nothing";
#elif defined(__GLIBC__)
    ASSERT_TRUE(hc::keepFreedMemory());
    const long first = oneFrame();
    oneFrame();
    long later = 0;
    for (int f = 0; f < 4; ++f) later = std::max(later, oneFrame());
    // A frame touches 130 MB: about 32,000 pages of 4 KiB the first time. Reused, it faults at most a few pages
    // (the vectors' bookkeeping, a neighbour's growth); 1 % of the first frame's faults leaves room for those.
    EXPECT_GT(first, 20000) << "the first frame should fault its pages in";
    EXPECT_LT(later, first / 100) << "frames after the second faulted " << later << " pages against " << first << " for the first";
#else
    EXPECT_FALSE(hc::keepFreedMemory());
#endif
}

TEST(Heap, RefusesValuesMallocCannotTake) {
    // mallopt takes an int: larger values are refused, and nothing is changed.
    EXPECT_FALSE(hc::keepFreedMemory(size_t(1) << 40, size_t(1) << 30));
    EXPECT_FALSE(hc::keepFreedMemory(size_t(32) << 20, size_t(1) << 40));
}
