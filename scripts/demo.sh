#!/usr/bin/env bash
# The main job on the bundled real DEM (data/hef_srtm.tif, Hintereisferner, Oetztal Alps, SRTM 3"):
# install dependencies, build, ingest it with a bathtub flood at 2000 m into an adaptive grid, check
# the grid file, and print where everything is and how long each stage took.
set -euo pipefail
cd "$(dirname "$0")/.."
now() { date +%s.%N; }
t0=$(now); bash scripts/deps.sh; t1=$(now)
bash scripts/build.sh; t2=$(now)
mkdir -p out
./build/bin/hc-ingest data/hef_srtm.tif -o out/hef.hcg --tolerance 1 --max-cell 512 --water-level 2000; t3=$(now)
./build/bin/hc-info out/hef.hcg; t4=$(now)
./build/bin/hc-info out/hef.hcg --json > out/hef.json
./build/bin/hc-info out/hef.hcg --cells-csv out/hef_cells.csv >/dev/null
echo
echo "outputs:"
echo "  grid        $(pwd)/out/hef.hcg"
echo "  summary     $(pwd)/out/hef.json"
echo "  cells       $(pwd)/out/hef_cells.csv"
echo "stage timings (s):"
awk -v a="$t0" -v b="$t1" -v c="$t2" -v d="$t3" -v e="$t4" 'BEGIN {
  printf "  dependencies  %7.2f\n  build         %7.2f\n  ingest        %7.2f\n  validate      %7.2f\n", b-a, c-b, d-c, e-d }'
