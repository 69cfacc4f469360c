// keepFreedMemory (core/heap.h): frame after frame, the buffers a frame allocates reuse its predecessor's pages instead
// of faulting fresh ones in from the kernel.
#include <gtest/gtest.h>

#include <sys/resource.h>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include <cstdint>
#include <cstdio>
#include <memory>
#include <utility>
#include <vector>

#include "heightcast/core/heap.h"

namespace {

long minorFaults() {
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return u.ru_minflt;
}

// One frame's allocations as renderFrame makes them at width x height: the ten float layers, the image, the rays'
// directions and three cascades' textures (4.2 MB each), every byte written, freed in another order than allocated
// (the textures first, the layers last, as the caller drops its Frame). Returns the minor page faults taken.
[[maybe_unused]] long oneFrame(size_t width, size_t height) {
    const long before = minorFaults();
    const size_t pixels = width * height;
    std::vector<std::vector<float>> layers;
    for (int i = 0; i < 10; ++i) layers.emplace_back(pixels, 0.0f);
    std::vector<uint8_t> rgb(3 * pixels, 1);
    auto dirs = std::make_unique<std::vector<float>>(3 * pixels, 1.0f);
    std::vector<std::vector<float>> textures;
    for (int k = 0; k < 3; ++k) textures.emplace_back(1025 * 1025, 2.0f);
    textures.clear();
    dirs.reset();
    rgb = {};
    layers.clear();
    return minorFaults() - before;
}

// Six frames of one size: the faults of the first, and the most of any after the second.
[[maybe_unused]] std::pair<long, long> faultsOfFrames(size_t width, size_t height) {
    const long first = oneFrame(width, height);
    oneFrame(width, height);
    long later = 0;
    for (int f = 0; f < 4; ++f) later = std::max(later, oneFrame(width, height));
    return {first, later};
}

}  // namespace

// Without keepFreedMemory this machine's glibc (2.36) took about 31,000 faults in every 1920 x 1080 frame of this
// pattern and 108,000 in every 3840 x 2160 one, as many as in the first (tried: the 1920 x 1080 frames then took 350 ms
// against 70 ms); with it, none after the heap has grown once. At 3840 x 2160 the layers are 33 MB, over the 32 MiB
// that glibc's own thresholds stop at.
// AddressSanitizer: gcc says so with __SANITIZE_ADDRESS__, clang 14 only through __has_feature.
#if defined(__SANITIZE_ADDRESS__)
#define HC_TEST_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define HC_TEST_ASAN 1
#endif
#endif

TEST(Heap, FramesReuseTheirPredecessorsPages) {
#if defined(HC_TEST_ASAN)
    GTEST_SKIP() << "AddressSanitizer's allocator replaces glibc's malloc, and its mallopt does nothing";
#elif defined(__GLIBC__)
    ASSERT_TRUE(hc::keepFreedMemory());
    // Setting the default threshold again, to learn whether this glibc took it (it changes nothing when it did).
    const bool large = mallopt(M_MMAP_THRESHOLD, 256 << 20) == 1;
    for (auto [width, height] : {std::pair<size_t, size_t>{1920, 1080}, {3840, 2160}}) {
        if (width > 1920 && !large) {
            std::printf(
                "this glibc caps the threshold at 32 MiB: 3840 x 2160 frames fault their layers in every time\n");
            continue;
        }
        const auto [first, later] = faultsOfFrames(width, height);
        // A frame touches 55 bytes a pixel and 12.6 MB of textures: at 1920 x 1080 about 31,000 pages of 4 KiB the
        // first time, at least the ten layers' 40 bytes a pixel. Reused, it faults at most a few pages (the vectors'
        // bookkeeping, a neighbour's growth); 1 % of the first frame's faults leaves room for those.
        EXPECT_GT(first, long(width * height * 40 / 4096))
            << width << " x " << height << ": the first frame should fault its pages in";
        EXPECT_LT(later, first / 100) << width << " x " << height << ": frames after the second faulted " << later
                                      << " pages against " << first << " for the first";
    }
#else
    EXPECT_FALSE(hc::keepFreedMemory());
#endif
}

TEST(Heap, RefusesValuesMallocCannotTake) {
    // mallopt takes an int: larger values are refused, and nothing is changed.
    EXPECT_FALSE(hc::keepFreedMemory(size_t(1) << 40, size_t(1) << 30));
    EXPECT_FALSE(hc::keepFreedMemory(size_t(32) << 20, size_t(1) << 40));
}
