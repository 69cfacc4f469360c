// HC_TEST_ASAN: defined where the test is built with AddressSanitizer, whose allocator replaces glibc's malloc (its
// mallopt does nothing, its page faults are its own). gcc says so with __SANITIZE_ADDRESS__, clang 14 only through
// __has_feature.
#pragma once

#if defined(__SANITIZE_ADDRESS__)
#define HC_TEST_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define HC_TEST_ASAN 1
#endif
#endif
