#!/usr/bin/env bash
# Configures and builds heightcast: bash scripts/build.sh [BUILD_DIR [CMAKE_ARGS...]]. Without arguments: build/,
# Release. CMAKE_ARGS come after the defaults, so they override them (scripts/test_sanitized.sh passes
# -DCMAKE_BUILD_TYPE=Debug; scripts/test_minimal.sh the HC_WITH_* options). In CI (CI=true) warnings are errors.
# ccache is used when installed, never required.
set -euo pipefail
cd "$(dirname "$0")/.."
dir=${1:-build}
[ $# -gt 0 ] && shift
werror=OFF
[ "${CI:-}" = "true" ] && werror=ON
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
cmake -S . -B "$dir" -DCMAKE_BUILD_TYPE=Release -DHC_WERROR=$werror "${launcher[@]}" "$@" >/dev/null
cmake --build "$dir" -j"$(nproc)"
