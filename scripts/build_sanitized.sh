#!/usr/bin/env bash
# The one sanitizer build (build-asan/), shared by scripts/test_sanitized.sh and scripts/fuzz.sh: clang 14 (so CI
# also proves the tree builds with Debian 12's clang, not only gcc 12), AddressSanitizer + UndefinedBehaviorSanitizer,
# live asserts, and the libFuzzer targets built beside the tests (HC_FUZZ). CMAKE_BUILD_TYPE=Debug (no NDEBUG) at
# -O1 (-O0 under ASan makes the render tests several times slower), plus _GLIBCXX_ASSERTIONS (bounds-checked
# operator[] in the standard library). -gline-tables-only: a sanitizer's report still names file and line, at about
# half the disk of full -g (CI's three builds share one disk).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/deps.sh clang
cxx=$(command -v clang++-14 || command -v clang++)
bash scripts/build.sh build-asan -DCMAKE_CXX_COMPILER="$cxx" -DCMAKE_BUILD_TYPE=Debug \
  -DCMAKE_CXX_FLAGS_DEBUG="-O1 -gline-tables-only -D_GLIBCXX_ASSERTIONS" -DHC_SANITIZE=ON -DHC_FUZZ=ON
