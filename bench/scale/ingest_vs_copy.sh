#!/usr/bin/env bash
# bench/scale/ingest_vs_copy.sh RASTER...: hc-ingest against its yardstick, a gdal_translate copy of the same raster
# (issue 42: hc-ingest <= 4x the copy). For each raster, ROUNDS rounds (default 2) of: the copy, then hc-ingest with
# default options, and HC_BASE (another hc-ingest binary, e.g. an earlier build) when it is set; each from a cold page
# cache (root: the cache is dropped before every command; otherwise warm, and the table says so). Prints one line a
# command and a markdown table of the best round: seconds, peak RSS and the ratio to the copy.
# The copy is not fsynced (gdal_translate never does); hc-ingest fsyncs its grid before renaming it into place.
set -euo pipefail
[[ $# -ge 1 ]] || { echo "usage: $0 RASTER..." >&2; exit 2; }
here=$(cd "$(dirname "$0")/../.." && pwd)
ingest=${HC_BIN:-$here/build/bin}/hc-ingest
rounds=${ROUNDS:-2}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cold=warm
[[ $(id -u) -eq 0 ]] && cold=cold
declare -A best
run() {  # NAME RASTER CMD...
    local name=$1 raster=$2
    shift 2
    [[ $cold == cold ]] && sync && echo 3 > /proc/sys/vm/drop_caches
    /usr/bin/time -f "%e %M" -o "$work/t" "$@" > /dev/null 2> "$work/err" || { cat "$work/err" >&2; exit 1; }
    read -r s kb < "$work/t"
    rm -f "$work/copy.tif" "$work/grid.hcg"
    echo "$(basename "$raster") $name: $s s, $((kb / 1024)) MiB ($cold)"
    local key="$raster|$name"
    if [[ -z ${best[$key]:-} ]] || awk -v a="$s" -v b="${best[$key]%% *}" 'BEGIN { exit !(a < b) }'; then
        best[$key]="$s $((kb / 1024))"
    fi
}
for raster in "$@"; do
    for ((r = 1; r <= rounds; ++r)); do
        run copy "$raster" gdal_translate -q "$raster" "$work/copy.tif"
        run hc-ingest "$raster" "$ingest" "$raster" -o "$work/grid.hcg" --quiet
        [[ -n ${HC_BASE:-} ]] && run base "$raster" "$HC_BASE" "$raster" -o "$work/grid.hcg" --quiet
    done
done
echo
echo "| raster | copy s, MiB | hc-ingest s, MiB | hc-ingest / copy |${HC_BASE:+ base s, MiB | base / copy |}"
echo "|---|---|---|---|${HC_BASE:+---|---|}"
for raster in "$@"; do
    read -r c cm <<< "${best[$raster|copy]}"
    read -r i im <<< "${best[$raster|hc-ingest]}"
    line="| $(basename "$raster") | $c, $cm | $i, $im | $(awk -v a="$i" -v b="$c" 'BEGIN { printf "%.2f", a / b }') |"
    if [[ -n ${HC_BASE:-} ]]; then
        read -r b bm <<< "${best[$raster|base]}"
        line+=" $b, $bm | $(awk -v a="$b" -v c="$c" 'BEGIN { printf "%.2f", a / c }') |"
    fi
    echo "$line"
done
