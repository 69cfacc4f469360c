#!/usr/bin/env bash
# The whole test suite: install dependencies, build, run every test through CTest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/deps.sh
bash scripts/build.sh
ctest --test-dir build -j"$(nproc)" --output-on-failure
