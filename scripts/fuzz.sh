#!/usr/bin/env bash
# Builds the libFuzzer targets (fuzz/: clang, ASan + UBSan, in the sanitizer build build-asan/ with the tests:
# scripts/build_sanitized.sh) and smoke-runs each one: all the
# seeds of fuzz/corpus/<reader>/, then mutated inputs up to RUNS executions in all (default 20000; fuzz_ugrid a
# tenth of that: each of its inputs is a NetCDF file written and read), on a
# copy of the corpus (the repository's stays as it is). Any finding (a crash, a sanitizer report, an
# exception other than hc::Error, a leak, an input slower than 10 s) exits non-zero and leaves the
# input that caused it as build-asan/findings/crash-* (or leak-*, timeout-*).
#   scripts/fuzz.sh [RUNS]      e.g. scripts/fuzz.sh 1000000 for the long runs recorded in docs/testing.md
set -euo pipefail
cd "$(dirname "$0")/.."
runs=${1:-20000}

bash scripts/build_sanitized.sh

mkdir -p build-asan/findings
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
  if ! build-asan/bin/fuzz_$reader -runs="$n" -timeout=10 -rss_limit_mb=2048 -malloc_limit_mb=1024 \
        -artifact_prefix=build-asan/findings/ -print_final_stats=1 "${dict[@]}" "$work" 2> "$work.log"; then
    tail -n 60 "$work.log"
    echo "fuzz.sh: fuzz_$reader FOUND A PROBLEM (input in build-asan/findings/)" >&2
    status=1
  else
    grep -E '^stat::number_of_executed_units|^Done' "$work.log" || true
  fi
  rm -rf "$work" "$work.log"
done
exit $status
