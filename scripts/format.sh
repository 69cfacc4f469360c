#!/usr/bin/env bash
# Formats every C++ file of the repository as .clang-format says (clang-format-14; scripts/check_tree.sh checks it).
set -euo pipefail
cd "$(dirname "$0")/.."
fmt=$(command -v clang-format-14 || command -v clang-format) || { echo "format.sh: bash scripts/deps.sh clang" >&2; exit 1; }
git ls-files '*.cpp' '*.h' | grep -v '^fuzz/corpus/' | xargs "$fmt" -i
