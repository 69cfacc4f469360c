#!/usr/bin/env bash
# Configures and builds heightcast in build/ (Release). In CI (CI=true) warnings are errors.
set -euo pipefail
cd "$(dirname "$0")/.."
werror=OFF
[ "${CI:-}" = "true" ] && werror=ON
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DHC_WERROR=$werror >/dev/null
cmake --build build -j"$(nproc)"
