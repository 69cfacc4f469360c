#!/usr/bin/env bash
# bench/models/run.sh WORKDIR [SIDE_PX [STEPS]]: the model-ingest benchmark (docs/models.md). A real terrain (South
# Glacier, 20 m, mirrored to SIDE_PX x SIDE_PX by bench/scale/make_raster.sh; default 3163: 10.0 M pixels) written as a
# flood model's UGRID map with a flood rising over STEPS steps (default 100) by hc-bench-models, twice:
#   quads.nc      one square face per pixel, bed and levels per face (as a quadtree model, SFINCS or 3Di, writes them):
#                 hc-ingest takes the faces as cells (the lattice fit)
#   triangles.nc  nodes at the pixel centres, two triangles a square of them, bed and levels per node (as a finite-element
#                 model, TELEMAC or ANUGA): hc-ingest samples them (--min-cell 20: a pixel per node)
# and, for each file of HC_MODEL_FILES (a space-separated list of real model outputs, optional), hc-ingest as a user runs
# it. Each ingest runs in its own process under /usr/bin/time -v; prints a markdown table (time, peak memory, faces,
# steps, cells) and writes WORKDIR/models.csv. HC_BIN (default build/bin) is where the tools are.
set -uo pipefail

usage() { echo "usage: $0 WORKDIR [SIDE_PX (default 3163)] [STEPS (default 100)]" >&2; exit 2; }
[[ $# -ge 1 && $# -le 3 ]] || usage
work=$1
side=${2:-3163}
steps=${3:-100}
[[ $side =~ ^[0-9]+$ && $steps =~ ^[0-9]+$ && $steps -ge 1 ]] || usage
here=$(cd "$(dirname "$0")" && pwd)
bin=${HC_BIN:-$here/../../build/bin}
mkdir -p "$work"
cd "$work" || exit 1
export GDAL_PAM_ENABLED=NO

[[ -s terrain.tif ]] || bash "$here/../scale/make_raster.sh" terrain.tif "$side" || exit 1
for kind in quads triangles; do
  [[ -s $kind.nc ]] || "$bin/hc-bench-models" terrain.tif -o "$kind.nc" --faces "$kind" --steps "$steps" || exit 1
done

echo "| input | format | faces | steps | file MB | hc-ingest s | peak MB | cells |"
echo "|---|---|---|---|---|---|---|---|"
echo "input,format,faces,steps,file_mb,seconds,peak_mb,cells" > models.csv
run() {  # NAME INPUT [ARGS...]
  local name=$1 input=$2
  shift 2
  if ! /usr/bin/time -v "$bin/hc-ingest" "$input" -o "$name.hcg" --threads 0 "$@" > "$name.log" 2> "$name.time"; then
    echo "| $name | failed: $(grep -m1 'error' "$name.time") | | | | | | |"
    return
  fi
  local secs peak format faces nsteps cells mb
  secs=$(awk -F': ' '/Elapsed \(wall clock\)/ {n = split($2, t, ":"); s = 0; for (i = 1; i <= n; ++i) s = s * 60 + t[i]; print s}' "$name.time")
  peak=$(awk -F': ' '/Maximum resident set size/ {printf "%.0f", $2 / 1024}' "$name.time")
  format=$(sed -n 's/^  input        \([^:]*\):.*/\1/p' "$name.log")
  faces=$(sed -n 's/^  input        [^:]*: \([0-9]*\) faces.*/\1/p' "$name.log")
  nsteps=$(sed -n 's/^  input .*nodes, \([0-9]*\) step.*/\1/p' "$name.log")
  cells=$(sed -n 's/^  cells        \([0-9]*\).*/\1/p' "$name.log")
  mb=$(du -m "$input" | cut -f1)
  echo "| $name | $format | $faces | $nsteps | $mb | $secs | $peak | $cells |"
  echo "$name,$format,$faces,$nsteps,$mb,$secs,$peak,$cells" >> models.csv
}
run quads quads.nc
run triangles triangles.nc --min-cell 20
for f in ${HC_MODEL_FILES:-}; do run "$(basename "$f")" "$f"; done
