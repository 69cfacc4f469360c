// heightcast/core/heap.h: keep freed memory in the process, for programs that render frame after frame.
//
// A frame allocates and frees the same buffers again and again (at 1920 x 1080: ten float layers of 8 MB, the
// rays' directions, each cascade's textures and mipmaps). glibc's malloc serves blocks of a few MB by mmap, or gives
// the top of its heap back to the kernel after a free, so each frame's buffers came back as fresh pages to fault in
// and zero: a measurable share of every moving-camera frame (docs/benchmarks.md).
//
// keepFreedMemory() tells malloc to serve blocks up to `mmapAboveBytes` from its heap and to keep up to `keepBytes`
// free at the heap's top: a frame then reuses its predecessor's pages. The default covers a 3840 x 2160 frame (layers
// of 33 MB, directions of 100 MB). Call it once, at the start of a program that renders several frames (hc-view,
// hc-render's flights and water steps, hc-bench); peak memory grows a little, and memory freed stays with the
// process until it exits.
// A glibc that refuses the threshold asked for gets 32 MiB, the most every glibc takes. Returns false where the
// allocator is not glibc's (nothing changed) or refused even that.
#pragma once

#include <cstddef>
#include <vector>

namespace hc {

bool keepFreedMemory(size_t mmapAboveBytes = size_t(256) << 20, size_t keepBytes = size_t(1) << 30);

// Asks the kernel to back the whole 2 MiB pages inside [data, data + bytes) with transparent huge pages (madvise
// MADV_HUGEPAGE), before the memory is first touched: a buffer of hundreds of MB then faults in 512 times fewer
// pages (a 420 MB raster: 0.58 s of faults and zeroing with 4 kB pages). Advice only: nothing happens where the
// kernel has THP off or the range holds no whole huge page.
void adviseHugePages(const void* data, size_t bytes);

// Room for n values in v, with storage that is new (never touched) advised onto huge pages: a frame's layers of
// several MB then fault in as a few 2 MiB pages instead of thousands of 4 kB ones. Storage v already has is reused.
// Call it on the thread that keeps the frame (then fill on workers): a worker's blocks come from its own malloc arena,
// whose heaps glibc unmaps as soon as they are empty, whatever keepFreedMemory() asked, so each frame would fault
// and zero its layers afresh.
template <class T>
void reserveOnHugePages(std::vector<T>& v, size_t n) {
    if (v.capacity() >= n) return;
    std::vector<T>().swap(v);
    v.reserve(n);
    adviseHugePages(v.data(), n * sizeof(T));
}

// v.assign(n, value) in storage from reserveOnHugePages().
template <class T>
void assignOnHugePages(std::vector<T>& v, size_t n, const T& value) {
    reserveOnHugePages(v, n);
    v.assign(n, value);
}

}  // namespace hc
