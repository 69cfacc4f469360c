#!/usr/bin/env bash
# The whole test suite again, built by clang 14 with AddressSanitizer + UndefinedBehaviorSanitizer and live asserts,
# in build-asan/ (scripts/build_sanitized.sh). One build serves as CI's clang build, its sanitizer build, its "asserts
# live" Debug build and its fuzz build. tests/asserts_live_test.cpp fails the run if asserts were compiled out. Any sanitizer finding aborts its test (-fno-sanitize-recover=undefined, halt_on_error).
# LeakSanitizer stays on except where a test sets ASAN_OPTIONS=detect_leaks=0 itself (the GL and viewer tests:
# LSan crashes inside Mesa's llvmpipe, docs/testing.md).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/build_sanitized.sh
# abort_on_error: a finding ends the process with SIGABRT, which CTest reports as a failure with the report above it.
export ASAN_OPTIONS="${ASAN_OPTIONS:-abort_on_error=1:strict_string_checks=1:detect_stack_use_after_return=1:check_initialization_order=1}"
export UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}"
ctest --test-dir build-asan -j"$(nproc)" --output-on-failure
