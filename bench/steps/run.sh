#!/usr/bin/env bash
# bench/steps/run.sh WORKDIR [SIDE_PX [STEPS]]: the issue-14 flood-scenario benchmark. A real terrain (South Glacier,
# 20 m, mirrored to SIDE_PX x SIDE_PX by bench/scale/make_raster.sh; default 2048) and a flood rising over STEPS
# water steps (default 100), given as one NetCDF variable over time (CF "seconds since", one band per time, as a
# simulation writes its results): water-surface levels rising by equal steps from 1700 m to 2200 m, each a 256 x 256
# raster over the terrain's extent (coarser than the terrain, as simulation output often is; hc-ingest resamples it).
# Each tool runs in its own process under /usr/bin/time -v:
#   hc-ingest TERRAIN -o dry.hcg                        the terrain alone (the static part's size without water)
#   hc-ingest TERRAIN --water-surface run.nc -o f.hcg   the scenario: one structure, STEPS steps
#   hc-influence f.hcg --no-pyramid                     the lists (shared by every step)
#   hc-influence f.hcg --no-lists                       every step's pyramid (f.step0000.hcp whole, the later ones water)
#   hc-render f.hcg --steps 0:STEPS-1 --backend cpu     one 1280x720 image per step from one camera: the per-step
#                                                       switch (read the step, its pyramid, a new scene) and frame
#   hc-view f.hcg --play --frames 21 --backend cpu      (under xvfb-run, where installed) the viewer's last switch
# and prints a markdown table (also WORKDIR/steps.csv; logs WORKDIR/<stage>.log and .time). HC_BIN (default
# build/bin) is where the tools are; HC_STEPS_TOLERANCE (default 1) the ingest tolerance in metres. Flat levels are a bathtub-like flood, not a simulation: the figures measure the
# file layout, I/O and per-step work, which depend on the wet cells per step, not on how the water got there.
set -uo pipefail

usage() { echo "usage: $0 WORKDIR [SIDE_PX (default 2048)] [STEPS (default 100)]" >&2; exit 2; }
[[ $# -ge 1 && $# -le 3 ]] || usage
work=$1
side=${2:-2048}
steps=${3:-100}
[[ $side =~ ^[0-9]+$ && $steps =~ ^[0-9]+$ && $steps -ge 2 ]] || usage
here=$(cd "$(dirname "$0")" && pwd)
bin=${HC_BIN:-$here/../../build/bin}
mkdir -p "$work"
cd "$work" || exit 1
export GDAL_PAM_ENABLED=NO

# The terrain and the series.
[[ -s terrain.tif ]] || bash "$here/../scale/make_raster.sh" terrain.tif "$side" || exit 1
read -r x0 y0 x1 y1 < <(gdalinfo -json terrain.tif | python3 -c '
import json, sys
j = json.load(sys.stdin); g = j["geoTransform"]; w, h = j["size"]
print(repr(g[0]), repr(g[3] + h * g[5]), repr(g[0] + w * g[1]), repr(g[3]))')
if [[ ! -s run.nc ]]; then
  rm -rf levels && mkdir levels
  times=()
  for ((k = 0; k < steps; ++k)); do
    level=$(python3 -c "print(1700 + 500 * $k / ($steps - 1))")
    gdal_create -q -of GTiff -ot Float32 -outsize 256 256 -bands 1 -a_srs EPSG:32607 -a_ullr "$x0" "$y1" "$x1" "$y0" \
      -burn "$level" "levels/l_$k.tif" || exit 1
    times+=($((k * 600)))
  done
  files=()
  for ((k = 0; k < steps; ++k)); do files+=("levels/l_$k.tif"); done
  gdalbuildvrt -q -separate levels.vrt "${files[@]}" || exit 1
  values=$(IFS=,; echo "${times[*]}")
  gdal_translate -q -of netCDF -mo 'NETCDF_DIM_EXTRA={time}' -mo "NETCDF_DIM_time_DEF={$steps,6}" \
    -mo "NETCDF_DIM_time_VALUES={$values}" -mo 'time#units=seconds since 2024-06-01 00:00:00' levels.vrt run.nc || exit 1
fi

echo "stage,seconds,peak_rss_mib,exit" > steps.csv
run() {  # run NAME COMMAND...: timed, logged, one CSV row
  local name=$1
  shift
  /usr/bin/time -v -o "$name.time" "$@" > "$name.log" 2>&1
  local rc=$?
  local s rss
  s=$(awk -F': ' '/Elapsed \(wall clock\)/ { n = split($2, p, ":"); t = 0; for (i = 1; i <= n; ++i) t = t * 60 + p[i]; print t }' "$name.time")
  rss=$(awk -F': ' '/Maximum resident/ { printf "%.0f", $2 / 1024 }' "$name.time")
  echo "$name,$s,$rss,$rc" >> steps.csv
}
tol=${HC_STEPS_TOLERANCE:-1}
run ingest_dry "$bin/hc-ingest" terrain.tif -o dry.hcg --tolerance "$tol" --quiet
run ingest_steps "$bin/hc-ingest" terrain.tif -o f.hcg --tolerance "$tol" --water-surface run.nc
run lists "$bin/hc-influence" f.hcg --no-pyramid --quiet
run pyramids "$bin/hc-influence" f.hcg --no-lists
run render_steps "$bin/hc-render" f.hcg -o img.png --steps "0:$((steps - 1))" --size 1280x720 --backend cpu --texels 1024
if command -v xvfb-run > /dev/null && [[ -x $bin/hc-view ]]; then
  run view_play xvfb-run -a -s '-screen 0 1280x1024x24' "$bin/hc-view" f.hcg --backend cpu --frames 21 --play --size 1280x720
fi

# The table.
cells=$("$bin/hc-info" f.hcg --json | python3 -c 'import json, sys; print(json.load(sys.stdin)["cells"])')
wet=$("$bin/hc-info" f.hcg --json | python3 -c 'import json, sys; print(sum(s["wet_cells"] for s in json.load(sys.stdin)["steps"]))')
dry_cells=$("$bin/hc-info" dry.hcg --json | python3 -c 'import json, sys; print(json.load(sys.stdin)["cells"])')
fsize=$(stat -c %s f.hcg)
dsize=$(stat -c %s dry.hcg)
psize=$(cat f.step*.hcp | wc -c)
base=$(stat -c %s f.step0000.hcp)
echo
echo "Terrain: ${side}^2 px of 20 m (South Glacier, mirrored), tolerance $tol m; $steps steps, water levels 1700..2200 m, one NetCDF variable over time."
echo
echo "| stage | wall s | peak RSS MiB | exit |"
echo "|---|---|---|---|"
tail -n +2 steps.csv | while IFS=, read -r n s r rc; do echo "| $n | $s | $r | $rc |"; done
echo
python3 - "$cells" "$wet" "$dry_cells" "$fsize" "$dsize" "$psize" "$steps" "$base" <<'PY'
import sys
cells, wet, dcells, fsize, dsize, psize, steps, base = map(int, sys.argv[1:])
static = 12 * cells
print(f"- cells: {cells:,} with water steps ({dcells:,} for the dry terrain alone: wet/dry edges of every step keep cells apart)")
print(f"- grid file: {fsize / 1e6:.1f} MB = static part {static / 1e6:.1f} MB (12 B a cell) + steps {(fsize - static) / 1e6:.1f} MB")
print(f"- per step: {wet / steps:,.0f} wet cells on average, {(fsize - static) / steps / 1e3:.1f} kB a step "
      f"(8 B a wet cell: {8 * wet / steps / 1e3:.1f} kB; the rest is the step table, hashes, block checksums and alignment)")
print(f"- pyramids: {psize / 1e6:.1f} MB for {steps} steps: the first step's whole {base / 1e6:.2f} MB, each later step's water "
      f"{(psize - base) / (steps - 1) / 1e6:.2f} MB on average")
PY
python3 - <<'PY'
import re, statistics
switch, frame = [], []
for line in open("render_steps.log"):
    # hc-render's per-step line: step, time s, wet cells, switch ms, frame ms, image
    m = re.match(r"\s+(\d+)\s+[-0-9.e]+\s+\d+\s+([0-9.]+)\s+([0-9.]+)\s+\S+\.png", line)
    if m:
        switch.append(float(m.group(2))); frame.append(float(m.group(3)))
if switch:
    s = sorted(switch[1:]) or switch
    print(f"- hc-render --steps: switch to the next step median {statistics.median(s):.1f} ms (min {min(s):.1f}, max {max(s):.1f}, "
          f"{len(s)} switches); frame median {statistics.median(frame):.0f} ms")
PY
[[ -s view_play.log ]] && grep -E "^  step " view_play.log | sed 's/^ */- hc-view --play: /'
exit 0
