#!/usr/bin/env bash
# bench/scale/run.sh RASTER WORKDIR: the issue-13 scale benchmark. Runs the toolkit's tools on one raster, each in
# its own process (a cold start: nothing shared but the OS page cache) under an address-space cap and
# /usr/bin/time -v, and records wall time, peak RSS, exit status and file sizes:
#   gdal_translate RASTER WORKDIR/copy.tif        (the yardstick of hc-ingest's time: a plain copy; deleted after)
#   hc-ingest RASTER -o WORKDIR/grid.hcg          (defaults: tolerance 0.25 m, finest = pixel, coarsest <= 96 m)
#   hc-info WORKDIR/grid.hcg --json
#   hc-influence WORKDIR/grid.hcg                 (defaults: the surface pyramid WORKDIR/grid.hcp, and the lists only
#                                                 up to 4.5 M cells; lists of 100 M cells would need ~22 GB)
#   hc-probe WORKDIR/grid.hcg --xy X,Y            (the raster's centre; out of core: the cells around the point)
#   hc-render WORKDIR/grid.hcg --size 1920x1080 --backend cpu   (one frame, the default overview camera; out of core,
#                                                 texels from the pyramid)
#   hc-render ... --fly 10 --fly-last-image       (moving frames: the median frame of a 10-frame flight, CPU backend)
#   hc-render ... --backend gl                    (the same frame on the OpenGL backend: the texels evaluated on the CPU
#                                                 from the pyramid, mipmaps, ray casting and shading as compute shaders;
#                                                 on a machine without a GPU, Mesa's llvmpipe, headless EGL)
# and prints markdown tables, also written with the raw figures to WORKDIR/scale.csv and WORKDIR/files.csv (logs: WORKDIR/<tool>.log,
# WORKDIR/<tool>.time). A tool that fails (out of memory, killed, timed out) is a row saying so, with the last
# line of its error output; the script goes on. HC_SCALE_COLD=1 (root only) drops the page cache before each tool,
# so that every one starts from the disk.
#
# The memory cap (HC_SCALE_CAP_MIB, default 12000 MiB, for every tool) is `ulimit -v`: an address-space limit,
# not an RSS one, so file mappings and untouched reservations count against it too. That makes it strict (a tool
# under it can never have more than the cap resident, so the machine's other users are safe) but it may refuse a
# tool that maps a large file and touches little of it; the table's peak RSS is the figure to compare with the
# 4 GB target. A cgroup memory limit would cap RSS instead but needs systemd or cgroup delegation, which this
# machine's shared setup does not give. HC_SCALE_TIMEOUT_S (default 1800) stops a tool that runs too long.
# HC_BIN (default build/bin) is where the tools are.
#
# Targets (issues 13 and 42, on the 2-core / 24 GB machine, up to 420 M cells): hc-ingest and hc-influence <= 480 s,
# hc-ingest <= 4x the copy, hc-render one frame from a cold start <= 5 s, hc-probe of one point and hc-info <= 1 s
# each, every tool <= 4 GB peak, all files <= 20 B per cell.
set -uo pipefail

usage() { echo "usage: $0 RASTER WORKDIR" >&2; exit 2; }
[[ $# -eq 2 ]] || usage
raster=$1 work=$2
here=$(cd "$(dirname "$0")/../.." && pwd)
bin=${HC_BIN:-$here/build/bin}
cap_mb=${HC_SCALE_CAP_MIB:-12000}
timeout_s=${HC_SCALE_TIMEOUT_S:-1800}
[[ -r $raster ]] || { echo "run.sh: error: $raster: cannot read" >&2; exit 1; }
for t in hc-ingest hc-info hc-influence hc-probe hc-render; do
    [[ -x $bin/$t ]] || { echo "run.sh: error: $bin/$t: not built (cmake --build build --target $t)" >&2; exit 1; }
done
mkdir -p "$work"
grid=$work/grid.hcg cache=$work/grid.hci pyramid=$work/grid.hcp
rm -f "$grid" "$cache" "$pyramid" "$work/frame.png" "$work/frame_gl.png" "$work/copy.tif" "$work"/fly*.png

# The raster's size and centre (the probe point).
read -r width height cx cy < <(gdalinfo -json "$raster" | python3 -c '
import json, sys
j = json.load(sys.stdin); g = j["geoTransform"]; w, h = j["size"]
print(w, h, repr(g[0] + g[1] * w / 2 + g[2] * h / 2), repr(g[3] + g[4] * w / 2 + g[5] * h / 2))')

csv=$work/scale.csv
echo "raster_px,tool,exit,status,wall_s,peak_rss_mib,cap_mib,target_s,met,note" > "$csv"
declare -a rows

# measure NAME TARGET_S CMD...: one tool in its own capped process; appends a row.
measure() {
    local name=$1 target=$2
    shift 2
    local log=$work/$name.log tm=$work/$name.time
    echo "[$(date +%T)] $name: $*" >&2
    [[ ${HC_SCALE_COLD:-0} == 1 ]] && sync && echo 3 > /proc/sys/vm/drop_caches
    (ulimit -v $((cap_mb * 1024)) && exec /usr/bin/time -v -o "$tm" timeout -k 10 "$timeout_s" "$@") > "$log" 2>&1
    local rc=$?
    local wall rss code sig status note met
    wall=$(awk -F': ' '/Elapsed \(wall clock\)/ { n = split($2, p, ":"); s = 0; for (i = 1; i <= n; ++i) s = s * 60 + p[i]; printf "%.2f", s }' "$tm")
    rss=$(awk -F': ' '/Maximum resident set size/ { printf "%.0f", $2 / 1024 }' "$tm")
    code=$(awk -F': ' '/Exit status/ { print $2 }' "$tm")
    sig=$(sed -n 's/.*terminated by signal \([0-9]*\).*/\1/p' "$tm")
    [[ -n $code ]] || code=$rc
    if [[ -n $sig ]]; then status="killed by signal $sig"
    elif [[ $code -eq 124 ]]; then status="timed out after ${timeout_s} s"
    elif [[ $code -ge 128 ]]; then status="killed by signal $((code - 128))"
    elif [[ $code -ne 0 ]]; then status="failed"
    else status="ok"; fi
    note=""
    [[ $status != ok ]] && note=$(grep -v '^\s*$' "$log" | tail -n 1 | tr -d '\r' | tr ',|' ';/' | cut -c1-160)
    met=no
    [[ $status == ok ]] && awk -v w="$wall" -v t="$target" -v r="$rss" 'BEGIN { exit !(w <= t && r <= 4096) }' && met=yes
    echo "${width}x${height},$name,$code,$status,$wall,$rss,$cap_mb,$target,$met,$note" >> "$csv"
    rows+=("| $name | $status | $wall | $target | $rss | $met | $note |")
    echo "[$(date +%T)] $name: $status, ${wall} s, ${rss} MiB" >&2
}

measure gdal_translate 480 gdal_translate -q "$raster" "$work/copy.tif"
rm -f "$work/copy.tif"
measure hc-ingest 480 "$bin/hc-ingest" "$raster" -o "$grid"
measure hc-info 1 "$bin/hc-info" "$grid" --json
measure hc-influence 480 "$bin/hc-influence" "$grid"
measure hc-probe 1 "$bin/hc-probe" "$grid" --xy "$cx,$cy"
measure hc-render 5 "$bin/hc-render" "$grid" -o "$work/frame.png" --size 1920x1080 --backend cpu
measure hc-render-gl 5 "$bin/hc-render" "$grid" -o "$work/frame_gl.png" --size 1920x1080 --backend gl
# Moving frames: a flight of 10 frames from the overview camera (each frame keeps the texels it still sees), on the
# CPU backend; its median frame time is the figure to compare across sizes (issue 42: no slower at 420 M than 105 M).
measure hc-render-fly 60 "$bin/hc-render" "$grid" -o "$work/fly.png" --size 1920x1080 --backend cpu --fly 10 --fly-last-image
fly_median=$(sed -n 's/.*frames 1\.\.[0-9]* *render median \([0-9.]*\) ms.*/\1/p' "$work/hc-render-fly.log" | head -n 1)

# Cells from hc-info's JSON (or, if hc-info failed, from hc-ingest's summary).
cells=$(python3 -c 'import json, sys; print(json.load(open(sys.argv[1]))["cells"])' "$work/hc-info.log" 2>/dev/null ||
        awk '$1 == "cells" { print $2; exit }' "$work/hc-ingest.log")
size_of() { [[ -f $1 ]] && stat -c %s "$1" || echo ""; }
hcg=$(size_of "$grid") hcp=$(size_of "$pyramid") hci=$(size_of "$cache") tif=$(size_of "$raster")
per_cell() { [[ -n $1 && -n $cells && $cells -gt 0 ]] && awk -v b="$1" -v c="$cells" 'BEGIN { printf "%.1f", b / c }' || echo "-"; }
{
    echo "raster_px,file,bytes,cells,bytes_per_cell"
    echo "${width}x${height},grid.hcg,$hcg,$cells,$(per_cell "$hcg")"
    echo "${width}x${height},grid.hcp,$hcp,$cells,$(per_cell "$hcp")"
    echo "${width}x${height},grid.hci,$hci,$cells,$(per_cell "$hci")"
} > "$work/files.csv"

echo
echo "raster $(basename "$raster"): ${width} x ${height} px ($(awk -v n=$((width * height)) 'BEGIN { printf "%.1f", n / 1e6 }') M), $tif bytes;" \
     "grid: ${cells:-?} cells; cap ${cap_mb} MiB (ulimit -v) per tool; $(nproc) cores; load $(cut -d' ' -f1 /proc/loadavg)"
echo
echo "| tool | status | wall s | target s | peak RSS MiB | met (time and <= 4096 MiB) | error |"
echo "|---|---|---:|---:|---:|---|---|"
printf '%s\n' "${rows[@]}"
ratio=$(awk -F, '$2 == "gdal_translate" { c = $5 } $2 == "hc-ingest" { i = $5 } END { if (c > 0 && i > 0) printf "%.2f", i / c }' "$csv")
echo
echo "hc-ingest / gdal_translate copy: ${ratio:-?} (target <= 4); moving frames (CPU, 1920x1080): median ${fly_median:-?} ms"
echo
echo "| file | bytes | bytes per cell (target <= 20) |"
echo "|---|---:|---:|"
echo "| grid.hcg | ${hcg:-absent} | $(per_cell "$hcg") |"
echo "| grid.hcp | ${hcp:-absent} | $(per_cell "$hcp") |"
echo "| grid.hci | ${hci:-absent (not built by default above 4.5 M cells)} | $(per_cell "$hci") |"
[[ -n $hcg && -n $hcp ]] && echo "| all files | $((hcg + hcp + ${hci:-0})) | $(per_cell $((hcg + hcp + ${hci:-0}))) |"
echo
echo "rows written to $csv and $work/files.csv"
