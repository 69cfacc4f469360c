#!/usr/bin/env bash
# The main job on the bundled real DEM (data/hef_srtm.tif, Hintereisferner, Oetztal Alps, SRTM 3"):
# install dependencies, build, ingest it with a flood rising over two hours (bathtub levels 1900 to 2100 m,
# five water steps) into an adaptive grid, build its influence cache and each step's surface pyramid, export
# the smooth surface at 2000 m (GeoTIFF elevation, EXR water depth, VDB level sets), probe it (a point's
# hydrograph), render it (an overview and a view up the flooded valley: PNG + EXR layers; the flood rising as
# an image sequence and an MP4), and print where everything is and how long each stage took; with a display
# (and not in CI), open the interactive viewer hc-view on the grid (Space plays the steps).
set -euo pipefail
cd "$(dirname "$0")/.."
now() { date +%s.%N; }
t0=$(now); bash scripts/deps.sh; t1=$(now)
bash scripts/build.sh; t2=$(now)
mkdir -p out
./build/bin/hc-ingest data/hef_srtm.tif -o out/hef.hcg --tolerance 1 --max-cell 512 \
  --water-level 1900,1950,2000,2050,2100 --times 0,1800,3600,5400,7200; t3=$(now)
./build/bin/hc-info out/hef.hcg; t4=$(now)
./build/bin/hc-info out/hef.hcg --json > out/hef.json
./build/bin/hc-info out/hef.hcg --cells-csv out/hef_cells.csv >/dev/null
./build/bin/hc-influence out/hef.hcg; t5=$(now)
./build/bin/hc-export out/hef.hcg --step 2 --resolution 30 -o out/hef_elevation.tif
./build/bin/hc-export out/hef.hcg --step 2 --resolution 30 --layer water_depth -o out/hef_water_depth.exr
./build/bin/hc-export out/hef.hcg --step 2 --resolution 60 -o out/hef.vdb; t6=$(now)
# The smooth surface (UTM 32N): elevation on the Hintereisferner (10.7528 E, 46.7975 N), and the water depth
# over time (every step: x,y,step,time_s,value) in the flooded valley at the domain's south-west corner.
./build/bin/hc-probe out/hef.hcg --xy 633759,5184153
./build/bin/hc-probe out/hef.hcg --xy 622800,5170600 --layer water_depth --all-steps; t7=$(now)
./build/bin/hc-render out/hef.hcg --step 2 -o out/hef_overview.png --exr out/hef_overview.exr --timings out/hef_overview_timings.json \
  --size 1280x720
./build/bin/hc-render out/hef.hcg --step 2 -o out/hef_valley.png --size 1280x720 --cells \
  --look-at 626000,5172000,3200,634000,5184000,2400,60
# The flood rising: one image per step from one camera (out/hef_flood_0000.png ...) and, with ffmpeg, a video.
video=(); command -v ffmpeg >/dev/null && video=(--video out/hef_flood.mp4 --fps 2)
./build/bin/hc-render out/hef.hcg --steps 0:4 -o out/hef_flood.png --size 960x540 "${video[@]}" \
  --look-at 626000,5172000,3200,634000,5184000,2400,60; t8=$(now)
echo
echo "outputs:"
echo "  grid              $(pwd)/out/hef.hcg"
echo "  grid summary      $(pwd)/out/hef.json"
echo "  cells             $(pwd)/out/hef_cells.csv"
echo "  influence cache   $(pwd)/out/hef.hci"
echo "  smooth surface    $(pwd)/out/hef_elevation.tif (GeoTIFF), $(pwd)/out/hef_water_depth.exr (EXR), $(pwd)/out/hef.vdb (OpenVDB)"
echo "  images            $(pwd)/out/hef_overview.png (+ .exr layers, _timings.json), $(pwd)/out/hef_valley.png (cell outlines)"
echo "  flood rising      $(pwd)/out/hef_flood_0000.png .. _0004.png (0 to 2 h)$( [ ${#video[@]} -gt 0 ] && echo ", $(pwd)/out/hef_flood.mp4")"
echo "stage timings (s):"
awk -v a="$t0" -v b="$t1" -v c="$t2" -v d="$t3" -v e="$t4" -v f="$t5" -v g="$t6" -v h="$t7" -v i="$t8" 'BEGIN {
  printf "  dependencies  %7.2f\n  build         %7.2f\n  ingest        %7.2f\n  validate      %7.2f\n", b-a, c-b, d-c, e-d
  printf "  influence     %7.2f\n  export        %7.2f\n  probe         %7.2f\n  render (x7)   %7.2f\n", f-e, g-f, h-g, i-h }'
# With a display (and not in CI), fly over the result: the interactive viewer (H in the window lists the controls).
if { [ -n "${DISPLAY:-}" ] || [ -n "${WAYLAND_DISPLAY:-}" ]; } && [ -z "${CI:-}" ]; then
  echo
  echo "opening the viewer on out/hef.hcg (H: controls, Esc: quit; bookmarks in out/hef.bookmarks.json)"
  ./build/bin/hc-view out/hef.hcg --look-at 626000,5172000,3200,634000,5184000,2400,60 || echo "hc-view failed (exit $?): the images above are complete"
fi
