#!/usr/bin/env bash
# bench/mpi/run.sh RASTER WORKDIR [RANKS...]: strong scaling of the preprocessing under MPI (issue 15, docs/design.md
# section 13) on this machine. For hc-ingest and hc-influence (lists and pyramid; --no-lists with HC_MPI_NO_LISTS=1):
# one process with every core (the tools as they run without mpirun), then `mpirun -np N` for each N of RANKS (default
# 1 2 3) with one thread a rank, so that N ranks use N cores (3 on a 2-core machine: oversubscribed). Every output is
# compared byte for byte with the one-process run (a difference stops the script). Prints a Markdown table: wall
# time of the whole command, the slowest rank's own building time, and the largest peak RSS of any rank.
# HC_MPI_INGEST_ONLY=1 stops after hc-ingest.
#
# Needs a build with MPI (scripts/build.sh, HC_WITH_MPI found) and mpirun (openmpi-bin). Run as root, mpirun needs
# OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 (set here). Make the raster with bench/scale/make_raster.sh.
set -euo pipefail
[[ $# -ge 2 ]] || { echo "usage: $0 RASTER WORKDIR [RANKS...]" >&2; exit 2; }
raster=$(realpath "$1")
work=$2
shift 2
rankCounts=(1 2 3)
[[ $# -gt 0 ]] && rankCounts=("$@")
bin=${HC_BIN:-$(cd "$(dirname "$0")/../.." && pwd)/build/bin}
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
lists=()
[[ ${HC_MPI_NO_LISTS:-0} = 1 ]] && lists=(--no-lists)
mkdir -p "$work"
cd "$work"

# wall seconds of a command (stdout+stderr to LOG)
timed() {
  local log=$1
  shift
  local t0 t1
  t0=$(date +%s.%N)
  "$@" > "$log" 2>&1 || { cat "$log" >&2; exit 1; }
  t1=$(date +%s.%N)
  echo "$t1 $t0" | awk '{ printf "%.2f", $1 - $2 }'
}
# the largest "peak N MB resident" a rank logged (or the one process printed)
peak() { grep -oE 'peak [0-9.]+ MB resident' "$1" | awk '{ if ($2 > m) m = $2 } END { printf "%.0f", m }'; }
# the slowest rank's own seconds: hc-ingest "..., S s" after "cells written"; hc-influence "in S s" summed per rank
ingestRank() { grep -oE 'cells written, [0-9.]+ s' "$1" | awk '{ if ($3 > m) m = $3 } END { if (NR) printf "%.2f", m
                                                                                                else printf "- (one rank runs as one process)" }'; }
influenceRank() { grep -E 'rank [0-9]+/[0-9]+: [0-9]+ nodes' "$1" | awk '{ s = 0
  for (i = 1; i <= NF; ++i) if ($i == "in" && $(i + 2) ~ /^s/) s += $(i + 1)
  if (s > m) m = s } END { if (NR) printf "%.2f", m
                             else printf "- (one rank runs as one process)" }'; }

echo "| tool | run | wall s | slowest rank's building s | peak RSS of a rank MB | same bytes |"
echo "|---|---|---|---|---|---|"
t=$(timed ingest_one.log "$bin/hc-ingest" "$raster" -o one.hcg)
echo "| hc-ingest | one process, all cores | $t | - | $(peak ingest_one.log) | (reference) |"
for n in "${rankCounts[@]}"; do
  t=$(timed "ingest$n.log" mpirun -np "$n" "$bin/hc-ingest" "$raster" -o "g$n.hcg" --threads 1)
  cmp one.hcg "g$n.hcg"
  echo "| hc-ingest | mpirun -np $n, 1 thread a rank | $t | $(ingestRank "ingest$n.log") | $(peak "ingest$n.log") | yes |"
done
[[ ${HC_MPI_INGEST_ONLY:-0} = 1 ]] && exit 0
t=$(timed influence_one.log "$bin/hc-influence" one.hcg "${lists[@]}")
echo "| hc-influence ${lists[*]} | one process, all cores | $t | - | $(peak influence_one.log) | (reference) |"
for n in "${rankCounts[@]}"; do
  cp one.hcg "g$n.hcg"
  t=$(timed "influence$n.log" mpirun -np "$n" "$bin/hc-influence" "g$n.hcg" --threads 1 "${lists[@]}")
  for f in one.*.hcp one.hcp one.hci; do
    [[ -e $f ]] || continue
    cmp "$f" "g$n${f#one}"
  done
  echo "| hc-influence ${lists[*]} | mpirun -np $n, 1 thread a rank | $t | $(influenceRank "influence$n.log") | $(peak "influence$n.log") | yes |"
done
