#include "heightcast/core/heap.h"

#include <climits>
#include <cstdint>

#include <sys/mman.h>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace hc {

bool keepFreedMemory(size_t mmapAboveBytes, size_t keepBytes) {
#if defined(__GLIBC__)
    if (mmapAboveBytes > size_t(INT_MAX) || keepBytes > size_t(INT_MAX)) return false;  // mallopt takes an int
    // Either setting also stops malloc from raising its thresholds on its own (glibc's "dynamic" thresholds). Some
    // glibc versions refuse a threshold above 32 MiB (DEFAULT_MMAP_THRESHOLD_MAX); Debian 12's 2.36 takes larger ones.
    const int mmapMax = 32 << 20;
    const bool threshold = mallopt(M_MMAP_THRESHOLD, int(mmapAboveBytes)) == 1 ||
                           (mmapAboveBytes > size_t(mmapMax) && mallopt(M_MMAP_THRESHOLD, mmapMax) == 1);
    return threshold && mallopt(M_TRIM_THRESHOLD, int(keepBytes)) == 1;
#else
    (void)mmapAboveBytes, (void)keepBytes;
    return false;
#endif
}

void adviseHugePages(const void* data, size_t bytes) {
#if defined(MADV_HUGEPAGE)
    const size_t huge = size_t(2) << 20;
    const uintptr_t begin = (uintptr_t(data) + huge - 1) & ~(huge - 1), end = (uintptr_t(data) + bytes) & ~(huge - 1);
    if (end > begin) ::madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE);
#else
    (void)data, (void)bytes;
#endif
}

}  // namespace hc
