#!/usr/bin/env bash
# The whole test suite again, built with AddressSanitizer + UndefinedBehaviorSanitizer and live asserts, in
# build-asan/. One build serves as CI's sanitizer build and its "asserts live" Debug build: CMAKE_BUILD_TYPE=Debug
# (no NDEBUG) at -O1 (-O0 under ASan makes the render tests several times slower), plus _GLIBCXX_ASSERTIONS
# (bounds-checked operator[] in the standard library). tests/asserts_live_test.cpp fails the run if asserts were
# compiled out. Any sanitizer finding aborts its test (-fno-sanitize-recover=undefined, halt_on_error).
# LeakSanitizer stays on except where a test sets ASAN_OPTIONS=detect_leaks=0 itself (the GL and viewer tests:
# LSan crashes inside Mesa's llvmpipe, DESIGN.md section 9).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/deps.sh
bash scripts/build.sh build-asan -DCMAKE_BUILD_TYPE=Debug -DCMAKE_CXX_FLAGS_DEBUG="-O1 -g -D_GLIBCXX_ASSERTIONS" -DHC_SANITIZE=ON
# abort_on_error: a finding ends the process with SIGABRT, which CTest reports as a failure with the report above it.
export ASAN_OPTIONS="${ASAN_OPTIONS:-abort_on_error=1:strict_string_checks=1:detect_stack_use_after_return=1:check_initialization_order=1}"
export UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}"
ctest --test-dir build-asan -j"$(nproc)" --output-on-failure
