#!/usr/bin/env bash
# Builds the libFuzzer targets (fuzz/: clang, ASan + UBSan, in build-fuzz/) and smoke-runs each one: all the
# seeds of fuzz/corpus/<reader>/, then mutated inputs up to RUNS executions in all (default 20000; fuzz_ugrid a
# tenth of that: each of its inputs is a NetCDF file written and read), on a
# copy of the corpus (the repository's stays as it is). Any finding (a crash, a sanitizer report, an
# exception other than hc::Error, a leak, an input slower than 10 s) exits non-zero and leaves the
# input that caused it as build-fuzz/findings/crash-* (or leak-*, timeout-*).
#   scripts/fuzz.sh [RUNS]      e.g. scripts/fuzz.sh 1000000 for the long runs recorded in README.md
set -euo pipefail
cd "$(dirname "$0")/.."
runs=${1:-20000}

# clang and libFuzzer (in libclang-rt-14-dev on Debian 12), installed only when missing, as deps.sh does.
packages=(clang libclang-rt-14-dev)
installed() { dpkg-query -W -f='${Status}' "$1" 2>/dev/null | grep -q "install ok installed"; }
missing=()
for p in "${packages[@]}"; do installed "$p" || missing+=("$p"); done
if [ ${#missing[@]} -gt 0 ]; then
  sudo=""
  [ "$(id -u)" -ne 0 ] && sudo="sudo"
  $sudo apt-get update -qq
  echo "fuzz.sh: installing ${missing[*]}"
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi
cxx=$(command -v clang++-14 || command -v clang++)
cc=$(command -v clang-14 || command -v clang)

launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
cmake -S . -B build-fuzz -DCMAKE_C_COMPILER="$cc" -DCMAKE_CXX_COMPILER="$cxx" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
      -DHC_FUZZ=ON -DHC_BUILD_TESTS=OFF -DHC_WITH_MPI=OFF "${launcher[@]}" >/dev/null
cmake --build build-fuzz -j "$(nproc)" --target fuzz

mkdir -p build-fuzz/findings
status=0
for reader in hcg hci hcp bookmarks points ugrid selafin 2dm; do
  work=$(mktemp -d)
  cp fuzz/corpus/$reader/* "$work/"
  dict=()
  [ -f fuzz/$reader.dict ] && dict=(-dict=fuzz/$reader.dict)
  # fuzz_ugrid writes and reads a NetCDF file per input (about 80 a second, against thousands for the others):
  # a tenth of the runs keeps its share of CI's time near the others'.
  n=$runs
  [ "$reader" = ugrid ] && n=$(( (runs + 9) / 10 ))
  echo "fuzz.sh: fuzz_$reader, $n executions from $(ls "$work" | wc -l) seeds"
  if ! build-fuzz/bin/fuzz_$reader -runs="$n" -timeout=10 -rss_limit_mb=2048 -malloc_limit_mb=1024 \
        -artifact_prefix=build-fuzz/findings/ -print_final_stats=1 "${dict[@]}" "$work" 2> "$work.log"; then
    tail -n 60 "$work.log"
    echo "fuzz.sh: fuzz_$reader FOUND A PROBLEM (input in build-fuzz/findings/)" >&2
    status=1
  else
    grep -E '^stat::number_of_executed_units|^Done' "$work.log" || true
  fi
  rm -rf "$work" "$work.log"
done
exit $status
