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
#include <string>
#include <utility>
#include <vector>

#include "asan.h"
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

#if !defined(HC_TEST_ASAN)  // under ASan the faults are not checked (below)
namespace {
// Whether the kernel backs madvise(MADV_HUGEPAGE) ranges with huge pages at their first touch: THP enabled for them,
// and allowed to compact memory to find a huge page then (defrag), so that the fault does not fall back to 4 kB pages.
bool hugePagesAtFault() {
    auto selected = [](const char* path) {
        std::FILE* f = std::fopen(path, "r");
        if (!f) return std::string();
        char line[256] = {};
        const bool read = std::fgets(line, sizeof line, f) != nullptr;
        std::fclose(f);
        const std::string s = read ? line : "";
        const size_t open = s.find('['), close = s.find(']');
        return open == std::string::npos || close == std::string::npos ? std::string()
                                                                       : s.substr(open + 1, close - open - 1);
    };
    const std::string enabled = selected("/sys/kernel/mm/transparent_hugepage/enabled");
    const std::string defrag = selected("/sys/kernel/mm/transparent_hugepage/defrag");
    return (enabled == "always" || enabled == "madvise") && (defrag == "always" || defrag == "madvise");
}
}  // namespace
#endif

// A frame's layer, assigned on huge pages: the values asked for, storage it already has kept, and a fresh 16 MiB layer
// faulted in as a few 2 MiB pages instead of 4096 of 4 kB (what a program's first frame pays: docs/benchmarks.md).
TEST(Heap, LayersAssignedOnHugePages) {
    std::vector<float> layer;
    const size_t n = size_t(4) << 20;  // 16 MiB of floats
    const long before = minorFaults();
    hc::assignOnHugePages(layer, n, 2.5f);
    const long faults = minorFaults() - before;
    ASSERT_EQ(layer.size(), n);
    EXPECT_EQ(layer.front(), 2.5f);
    EXPECT_EQ(layer.back(), 2.5f);
    const float* storage = layer.data();
    hc::assignOnHugePages(layer, n / 2, -1.0f);  // smaller: the same storage, the new values
    EXPECT_EQ(layer.data(), storage);
    ASSERT_EQ(layer.size(), n / 2);
    EXPECT_EQ(layer.back(), -1.0f);
#if defined(HC_TEST_ASAN)
    std::printf("AddressSanitizer's allocator: page faults not checked (%ld)\n", faults);
#else
    if (!hugePagesAtFault())
        GTEST_SKIP() << "this kernel does not give huge pages at the first touch of a madvised range";
    // 4096 faults with 4 kB pages; with 2 MiB ones 8, plus the unaligned ends (at most 2 x 511 small pages). Half of
    // 4096 tells the two apart on any alignment.
    EXPECT_LT(faults, 2048) << "a fresh 16 MiB layer took " << faults << " page faults";
#endif
}
