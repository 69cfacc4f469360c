# tests/cli/steps.cmake: flood scenarios over time (issue 14, docs/design.md section 6) end to end: water steps from a
# series of levels or rasters into one grid, their pyramids, a sequence of images (and a video), a point's hydrograph,
# one step exported, the viewer playing them; and the refusals (unsorted times, series that disagree, steps that do
# not exist), each leaving nothing behind.
#
# The fixture: the bundled DEM (Hintereisferner, SRTM) flooded at 1900, 2100 and 2300 m at 0, 1 h and 2 h.
set(HEF_STEPS [[$HC_INGEST --quiet "$HC_DATA_DIR/hef_srtm.tif" -o f.hcg --tolerance 1 --max-cell 512 --water-level 1900,2100,2300 --times 0,3600,7200 >/dev/null 2>&1]])
# A point in the flooded valley at the domain's south-west corner (wet in every step), in UTM 32N.
set(HEF_VALLEY 622800,5170600)

hc_cli_test(ingest.steps_levels 0 [[water +3 steps, 0 s \.\. 7200 s. [0-9]+ \.\. [0-9]+ wet cells of [0-9]+]]
  --match [[8 per wet cell and step]] --no-match [[error|warning]] --exists f.hcg
  --check [["$HC_INFO" f.hcg --verify | grep -E '^f\.hcg: heightcast grid, format 1\.3, valid']]
  --check [["$HC_INFO" f.hcg --json | tr -d ' \n' | grep -E '"steps":.\{"step":0,"time_s":0\.0,"wet_cells":[0-9]+\},\{"step":1,"time_s":3600\.0,"wet_cells":[0-9]+\},\{"step":2,"time_s":7200\.0,"wet_cells":[0-9]+\}.,"step":0,']]
  --check [["$HC_INFO" f.hcg --step 2 | grep -E 'water_depth 0 \.\. [0-9.]+ m \(step 2\)' && "$HC_INFO" f.hcg | grep -E 'steps +3 water steps, 0 \.\. 7200 s']]
  -- ${INGEST} ${D}/hef_srtm.tif -o f.hcg --tolerance 1 --max-cell 512 --water-level 1900,2100,2300 --times 0,3600,7200)

# Times must increase, and there must be one per step: refused before any work, no file.
hc_cli_test(ingest.steps_unsorted_times nonzero [[^hc-ingest: error: --times must increase strictly: 10 s follows 20 s \(step 2\)]]
  --absent f.hcg
  -- ${INGEST} ${D}/hef_srtm.tif -o f.hcg --water-level 1900,2100,2300 --times 0,20,10)
hc_cli_test(ingest.steps_times_count nonzero [[^hc-ingest: error: --times lists 2 times for 3 water steps]]
  --absent f.hcg
  -- ${INGEST} ${D}/hef_srtm.tif -o f.hcg --water-level 1900,2100,2300 --times 0,60)
hc_cli_test(ingest.steps_glob_matches_nothing nonzero [[^hc-ingest: error: --water nope_\*\.tif: the pattern matches no file]]
  --absent f.hcg
  -- ${INGEST} ${D}/hef_srtm.tif -o f.hcg --water "nope_*.tif")

if(HC_GDAL_CREATE)
  # Water surface rasters on the DEM's own grid at 2000, 2100 and 2200 m, named so that a plain sort would put s_10
  # before s_2: the glob takes them in natural order, so the wet cells grow from step to step.
  set(SERIES [[for l in 1:2000 2:2100 10:2200
do gdal_create -q -if "$HC_DATA_DIR/hef_srtm.tif" -ot Float32 -burn ${l#*:} s_${l%%:*}.tif || exit 1
done]])
  hc_cli_test(ingest.steps_series_glob 0 [[water +3 steps, 0 s \.\. 2 s \(the step index: no --times given\)]]
    --setup ${SERIES} --exists f.hcg --no-match [[error]]
    --check [["$HC_INFO" f.hcg --json | tr -d ' \n' | grep -oE '"wet_cells":[0-9]+' | cut -d: -f2 > wet.txt
             sort -n -c wet.txt && test "$(sort -u wet.txt | wc -l)" = 3 && cat wet.txt]]
    -- ${INGEST} ${D}/hef_srtm.tif -o f.hcg --tolerance 1 --max-cell 512 --water-surface "s_*.tif")
  # A step on another grid (the same surface, but with a coarser pixel) is refused naming both files, and nothing is written.
  hc_cli_test(ingest.steps_series_disagree nonzero [[hc-ingest: error: s_odd\.tif: size [0-9]+ x [0-9]+ px differs from the series' first step s_1\.tif]]
    --setup ${SERIES} --setup [[gdal_translate -q -outsize 50% 50% s_2.tif s_odd.tif]] --absent f.hcg
    -- ${INGEST} ${D}/hef_srtm.tif -o f.hcg --water-surface s_1.tif,s_odd.tif)
  # A NetCDF variable over time (CF), as a simulation writes its results: GDAL reads one band per time; each band is a
  # step at the file's time (hours here). The same three levels as above: the same wet cells per step as three files.
  set(NETCDF_SERIES [[for l in 1:2000 2:2100 10:2200
do gdal_create -q -if "$HC_DATA_DIR/hef_srtm.tif" -ot Float32 -burn ${l#*:} s_${l%%:*}.tif || exit 1
done
gdalbuildvrt -q -separate stack.vrt s_1.tif s_2.tif s_10.tif &&
mk() { gdal_translate -q -of netCDF -mo 'NETCDF_DIM_EXTRA={time}' -mo 'NETCDF_DIM_time_DEF={3,6}' -mo "NETCDF_DIM_time_VALUES={$1}" -mo "time#units=$2" stack.vrt "$3"
}
mk 0,1.5,3 'hours since 2024-06-01 00:00:00' run.nc && mk 0,1,2 'months since 2024-06-01' months.nc && mk 0,2,1 'seconds since 2024-06-01' back.nc]])
  hc_cli_test(ingest.steps_netcdf_time 0 [[water +3 steps, 0 s \.\. 10800 s. [0-9]+ \.\. [0-9]+ wet cells]]
    --setup ${NETCDF_SERIES} --exists f.hcg --no-match [[error|warning|step index]]
    --check [["$HC_INFO" f.hcg --json | tr -d ' \n' | grep -oE '"time_s":[0-9.]+' | tr '\n' ' ' | grep -x '"time_s":0.0 "time_s":5400.0 "time_s":10800.0 ']]
    --check [["$HC_INGEST" --quiet "$HC_DATA_DIR/hef_srtm.tif" -o g.hcg --tolerance 1 --max-cell 512 --water-surface s_1.tif,s_2.tif,s_10.tif
             "$HC_INFO" f.hcg --json | tr -d ' \n' | grep -oE '"wet_cells":[0-9]+' > a.txt
             "$HC_INFO" g.hcg --json | tr -d ' \n' | grep -oE '"wet_cells":[0-9]+' > b.txt
             cat a.txt && cmp a.txt b.txt]]
    -- ${INGEST} ${D}/hef_srtm.tif -o f.hcg --tolerance 1 --max-cell 512 --water-surface run.nc)
  # Time units that are not CF's fixed lengths (months): the step index, said in a warning.
  hc_cli_test(ingest.steps_netcdf_months 0 [[warning: months\.nc: the time dimension has no CF time units \(months since 2024-06-01\): the step index is taken as time]]
    --setup ${NETCDF_SERIES} --exists f.hcg
    --check [["$HC_INFO" f.hcg --json | tr -d ' \n' | grep -oE '"time_s":[0-9.]+' | tr '\n' ' ' | grep -x '"time_s":0.0 "time_s":1.0 "time_s":2.0 ']]
    -- ${INGEST} ${D}/hef_srtm.tif -o f.hcg --tolerance 1 --max-cell 512 --water-surface months.nc --quiet)
  # Times that go back, and a raster of several bands with no time dimension: refused, nothing written.
  hc_cli_test(ingest.steps_netcdf_unsorted nonzero [[^hc-ingest: error: back\.nc: the times of its time dimension do not increase: step 2 at 1 s follows 2 s]]
    --setup ${NETCDF_SERIES} --absent f.hcg
    -- ${INGEST} ${D}/hef_srtm.tif -o f.hcg --water-surface back.nc)
  hc_cli_test(ingest.steps_bands_without_time nonzero [[^hc-ingest: error: stack\.vrt: has 3 bands and no time dimension: which is the water\?]]
    --setup ${NETCDF_SERIES} --absent f.hcg
    -- ${INGEST} ${D}/hef_srtm.tif -o f.hcg --water-surface stack.vrt)
  hc_cli_test(ingest.steps_list_of_multiband nonzero [[^hc-ingest: error: stack\.vrt: has 3 bands: each file of a series of water rasters is one step of one band]]
    --setup ${NETCDF_SERIES} --absent f.hcg
    -- ${INGEST} ${D}/hef_srtm.tif -o f.hcg --water-surface s_1.tif,stack.vrt)
endif()

# One pyramid per step, each built from the lists that serve all steps.
# The first step's pyramid is whole; the later steps' hold their water only, in the tiles where it is drawn (smaller).
hc_cli_test(influence.steps 0 [[step 2 +at 7200 s, [0-9]+ wet cells.*pyramid +-> f\.step0002\.hcp]]
  --setup ${HEF_STEPS} --exists f.hci --exists f.step0000.hcp --exists f.step0001.hcp --exists f.step0002.hcp --absent f.hcp
  --match [[2 channels \(water level, wet share. the terrain is step 0's\), in the tiles where water is drawn]]
  --check [[for k in 1 2
do test "$(stat -c %s f.step000$k.hcp)" -lt "$(stat -c %s f.step0000.hcp)" || exit 1
done]]
  --no-match [[error:|warning]]
  -- ${INFLUENCE} f.hcg --quiet)
hc_cli_test(influence.steps_named_pyramid nonzero [[^hc-influence: error: -p names one pyramid file but f\.hcg has 3 water steps: add --step K]]
  --setup ${HEF_STEPS} --absent p.hcp --absent f.hci
  -- ${INFLUENCE} f.hcg -p p.hcp)

# A sequence: one image per step from the same camera, each with its own step's pyramid; the water differs.
hc_cli_test(render.steps_sequence 0 [[steps 0\.\.2 -> f_0000\.png.*  +2 +7200 +[0-9]+ .*f_0002\.png]]
  --setup ${HEF_STEPS} --setup [[$HC_INFLUENCE f.hcg --quiet >/dev/null]]
  --exists f_0000.png --exists f_0001.png --exists f_0002.png --absent f.png --no-match [[error|not used]]
  --check "'${PNG_CHECK}' f_0000.png && '${PNG_CHECK}' f_0002.png && ! cmp -s f_0000.png f_0002.png"
  -- ${RENDER} f.hcg -o f.png --steps 0:2 --size 320x180 --texels 128 --backend cpu)
# On GL a sequence keeps one context and hands it each step's scene (GlRenderer::setScene), and reads back the picture
# alone: every step's image is the same bytes as that step rendered on its own (a fresh renderer, every layer read
# back), out of core (the step pyramids' tiles in the atlas) and in memory (--cache: the cells with the step's water).
if(HC_WITH_GL)
  set(HEF_CAMERA --camera 624745.367,5156520.380,23220.029,20,-35,45 --size 320x180 --texels 128 --backend gl)
  string(REPLACE ";" " " HEF_CAMERA_TEXT "${HEF_CAMERA}")
  hc_cli_test(render.steps_sequence_gl_one_context 0 [[steps 0\.\.2 -> q_0000\.png.*total .* for 3 steps]]
    --setup ${HEF_STEPS} --setup [[$HC_INFLUENCE f.hcg --quiet >/dev/null]] --no-match [[error]]
    --check "for cache in '' '--cache f.hci'
do '${RENDER}' f.hcg -o c.png --steps 0:2 ${HEF_CAMERA_TEXT} $cache >/dev/null || exit 1
for k in 0 1 2
do '${RENDER}' f.hcg -o s.png --step $k ${HEF_CAMERA_TEXT} $cache >/dev/null && cmp c_000$k.png s.png || exit 1
done
done"
    -- ${RENDER} f.hcg -o q.png --steps 0:2 ${HEF_CAMERA})
endif()
# A later step's water pyramid takes the terrain from the first step's: used together, or, without the first, not at all.
hc_cli_test(render.step_water_pyramid 0 [[using surface pyramid f\.step0002\.hcp \(water. terrain from f\.step0000\.hcp\)]]
  --setup ${HEF_STEPS} --setup [[$HC_INFLUENCE f.hcg --quiet >/dev/null]] --exists f.png
  --check "mkdir -p alone && cp f.hcg f.hci f.step0002.hcp alone/ && cd alone && '${RENDER}' f.hcg -o a.png --step 2 --size 160x90 --texels 64 --backend cpu 2>&1 | grep -F \"f.step0002.hcp holds this step's water only and its base, the first step's pyramid, is not usable (f.step0000.hcp: no such file): not used\""
  -- ${RENDER} f.hcg -o f.png --step 2 --size 320x180 --texels 128 --backend cpu)
hc_cli_test(render.step_out_of_range nonzero [[^hc-render: error: f\.hcg: has no step 3: it holds 3 water steps \(0\.\.2\)]]
  --setup ${HEF_STEPS} --absent f.png
  -- ${RENDER} f.hcg -o f.png --step 3 --size 320x180 --backend cpu)
hc_cli_test(render.steps_out_of_range nonzero [[^hc-render: error: --steps 1:3: f\.hcg has 3 water steps]]
  --setup ${HEF_STEPS} --absent f_0001.png
  -- ${RENDER} f.hcg -o f.png --steps 1:3 --size 320x180 --backend cpu)
if(HC_FFMPEG)
  hc_cli_test(render.steps_video 0 [[video +v\.mp4 \(2 steps per second\)]]
    --setup ${HEF_STEPS} --exists v.mp4 --absent v.mp4.partial --no-match [[error]]
    --check [[test "$(ffprobe -v error -count_frames -show_entries stream=nb_read_frames -of csv=p=0 v.mp4)" = 3]]
    --check [[test "$(ffprobe -v error -show_entries stream=width,height,r_frame_rate -of csv=p=0 v.mp4)" = 322,182,2/1]]
    -- ${RENDER} f.hcg -o f.png --steps 0:2 --video v.mp4 --fps 2 --size 321x181 --texels 128 --backend cpu)
  # The frames go to ffmpeg down a pipe as they come: an ffmpeg that stops reading (here one that exits at once) is
  # said, and no video is left, partial or whole; the run stops, and the images written so far stay.
  hc_cli_test(render.steps_video_ffmpeg_fails nonzero [[hc-render: error: v\.mp4: ffmpeg (stopped reading the frames|failed).*the images written so far stay]]
    --setup ${HEF_STEPS} --setup [[mkdir bin && printf '#!/bin/sh\nexit 3\n' > bin/ffmpeg && chmod +x bin/ffmpeg]]
    --absent v.mp4 --absent v.mp4.partial --exists f_0000.png --allow-new-files
    -- env PATH=./bin:/usr/bin:/bin ${RENDER} f.hcg -o f.png --steps 0:2 --video v.mp4 --size 320x180 --texels 128 --backend cpu)
else()
  hc_cli_test(render.steps_video_without_ffmpeg nonzero [[^hc-render: error: --video: ffmpeg is not installed]]
    --setup ${HEF_STEPS} --absent v.mp4 --absent f_0000.png
    -- ${RENDER} f.hcg -o f.png --steps 0:2 --video v.mp4 --size 320x180 --backend cpu)
endif()
hc_cli_test(render.video_needs_steps nonzero [[^hc-render: error: --video needs --steps A:B]]
  --absent v.mp4
  -- ${RENDER} f.hcg -o f.png --video v.mp4)

# The hydrograph: the water surface at the valley point is each step's level (1 cm: float32 storage), the times the
# file's; out of core and with the cache the same bits.
hc_cli_test(probe.hydrograph 0 [[hc-probe: 3 steps, 1 point each]]
  --setup ${HEF_STEPS} --exists h.csv --no-match [[error]] --check [[head -n 1 h.csv | grep -x 'x,y,step,time_s,value']]
  --check [[awk -F, 'NR > 1 { want = 1900 + 200 * $3
                             t = 3600 * $3
                             e = $5 - want
                             if (e < 0) e = -e
                             if ($4 != t || e > 0.01) { print "line " NR ": " $0
                                                        bad = 1 }
                             n++ }
                   END { exit bad || n != 3 }' h.csv]]
  --check [[$HC_PROBE f.hcg --xy 622800,5170600 --layer water_surface --all-steps --cache f.hci 2>/dev/null | cmp - h.csv]]
  --check [[cat h.csv]]
  -- ${PROBE} f.hcg --xy ${HEF_VALLEY} --layer water_surface --all-steps -o h.csv)
hc_cli_test(probe.step_out_of_range nonzero [[^hc-probe: error: f\.hcg: has no step 9: it holds 3 water steps \(0\.\.2\)]]
  --setup ${HEF_STEPS}
  -- ${PROBE} f.hcg --xy ${HEF_VALLEY} --step 9)

# One step exported: the flooded valley's water surface lies at that step's level (1 cm).
hc_cli_test(export.step 0 [[-> s\.tif]]
  --setup ${HEF_STEPS} --exists s.tif
  --check [[gdalinfo -stats s.tif > info.txt 2>&1
            awk -F= '/STATISTICS_MINIMUM/ { lo = $2 } /STATISTICS_MAXIMUM/ { hi = $2 }
                     END { print "water surface " lo " .. " hi
                           exit !(lo != "" && lo > 2299.99 && hi < 2300.01) }' info.txt]]
  -- ${EXPORT} f.hcg --step 2 --layer water_surface --resolution 200 -o s.tif --quiet)

# The viewer plays the steps: each scripted frame after the first shows the next step (the water read again, the
# terrain's lists kept); the last frame is of step 2 and shows terrain.
if(HC_WITH_GL AND HC_XVFB_RUN)
  hc_cli_test(view.play_steps 0 [[step +2 of 3 \(last switch [0-9.]+ ms]]
    --setup ${HEF_STEPS} --exists shot.png --no-match [[error|warning]]
    --check "'${PNG_CHECK}' shot.png"
    -- ${HC_XVFB_RUN} -a -s "-screen 0 1280x1024x24" $<TARGET_FILE:hc-view> f.hcg --backend cpu --frames 3 --play --screenshot shot.png --size 480x300 --texels 128)
  # On the GL backend (llvmpipe under Xvfb) the renderer is handed each step's scene, its shaders compiled once.
  hc_cli_test(view.play_steps_gl 0 [[step +2 of 3 \(last switch [0-9.]+ ms]]
    --setup ${HEF_STEPS} --exists shot.png --no-match [[error|warning]]
    --check "'${PNG_CHECK}' shot.png"
    -- ${HC_XVFB_RUN} -a -s "-screen 0 1280x1024x24" $<TARGET_FILE:hc-view> f.hcg --backend gl --frames 3 --play --screenshot shot.png --size 480x300 --texels 128)
  hc_cli_test(view.play_needs_frames nonzero [[^hc-view: error: --play needs --frames N]]
    -- $<TARGET_FILE:hc-view> f.hcg --play)
endif()
