# tests/cli/mpi.cmake: preprocessing on the ranks of mpirun (issue 15, docs/design.md section 7). `mpirun -np N` with
# N = 1, 2, 3 on this one machine (oversubscribed: more ranks than cores) must write the very bytes one process
# writes, for hc-ingest and hc-influence (lists and every step's pyramid), on three kinds of grid: a raster with
# holes (interior nodata burnt into the bundled DEM, and the rotated footprint's edges), water steps (a rising flood
# over it), and a rotated quadtree mesh. Each rank logs its share once ("rank K/N"); a failure is reported once, by
# rank 1, and leaves nothing behind. A build without MPI refuses mpirun with several processes.
#
# mpirun refuses to run as root unless told (CI runs as root): OMPI_ALLOW_RUN_AS_ROOT=1 and
# OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 say so, for these tests only.
if(NOT HC_MPIEXEC)
  message(STATUS "tests/cli: no mpirun (Debian: openmpi-bin): the MPI tests are left out")
  return()
endif()

if(NOT HC_WITH_MPI)
  # Built without MPI: several ranks would each do all the work and race for the output. Refused, nothing written.
  hc_cli_test(mpi.refused_without_mpi nonzero [[this build has no MPI \(HC_WITH_MPI=OFF or no MPI found\)]]
    --absent g.hcg
    -- env OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1 ${HC_MPIEXEC} -np 2 ${INGEST} ${D}/hef_srtm.tif -o g.hcg)
  return()
endif()

# VAR: a bash script running hc-ingest INPUT on 2 and 3 ranks into g2.hcg and g3.hcg, their logs in g2.txt and g3.txt
# (printed if a run fails; g3.txt printed in any case, for the test's regexes).
function(hc_mpi_ingest_runs var input)
  set(${var} "for n in 2 3\ndo if ! \"$HC_MPIRUN\" -np $n \"$HC_INGEST\" ${input} -o g$n.hcg > g$n.txt 2>&1\nthen cat g$n.txt\nexit 1\nfi\ndone\ncat g3.txt"
      PARENT_SCOPE)
endfunction()
hc_mpi_ingest_runs(MOSAIC_RUNS mosaic.vrt)
hc_mpi_ingest_runs(GEO_RUNS geo.vrt)

function(hc_mpi_test name)
  hc_cli_test(${name} ${ARGN})
  set_property(TEST cli.${name} APPEND PROPERTY ENVIRONMENT
               "OMPI_ALLOW_RUN_AS_ROOT=1;OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1;OMPI_MCA_rmaps_base_oversubscribe=1;HC_MPIRUN=${HC_MPIEXEC}")
  if(HC_SANITIZE)  # OpenMPI's own allocations outlive MPI_Finalize: LeakSanitizer would fail every rank
    set_property(TEST cli.${name} APPEND PROPERTY ENVIRONMENT ASAN_OPTIONS=detect_leaks=0)
  endif()
  set_property(TEST cli.${name} PROPERTY TIMEOUT 300)
  set_property(TEST cli.${name} PROPERTY LABELS "cli;mpi")
  # Three ranks and their threads on a 2-core machine: run these alone, not beside the rest of the suite.
  set_property(TEST cli.${name} PROPERTY RUN_SERIAL TRUE)
endfunction()

# The fixture: the bundled DEM with two interior holes burnt in (the nodata value inside two WGS 84 boxes), flooded at
# 2500 and 2700 m (two water steps), with a tolerance that makes cells of three sizes. The reference is one process.
set(HOLES_INPUT [[gdal_translate -q -a_nodata -32768 "$HC_DATA_DIR/hef_srtm.tif" holes.tif &&
printf 'id,WKT\n1,"POLYGON((10.70 46.75,10.78 46.75,10.78 46.82,10.70 46.82,10.70 46.75))"\n2,"POLYGON((10.80 46.85,10.83 46.85,10.83 46.88,10.80 46.88,10.80 46.85))"\n' > holes.csv &&
gdal_rasterize -q -burn -32768 holes.csv holes.tif 2>/dev/null]])
set(HOLES_ARGS "holes.tif --tolerance 15 --max-cell 1024 --water-level 2500,2700")

if(HC_GDAL_CREATE)  # gdal-bin's gdal_rasterize makes the holes
  # hc-ingest: the same bytes from 1, 2 and 3 ranks (and the interior holes are there: fewer valid pixels than the
  # working raster has, and holes.tif's own count of nodata pixels is not 0). Each rank reads only its windows, and
  # floods them for each level: the components below the level that meet across its windows' edges are joined over
  # the ranks, and seeded where they meet a hole or the raster's edge (the same flood as the whole raster's). The source
  # is geographic (resampled to UTM); the ranks write their own cells into the file in place and check their share of
  # the source's rows against it afterwards: the same summary as one process.
  hc_mpi_test(mpi.ingest_holes_steps 0 [[rank 3/3: [0-9]+ windows? read, [0-9]+ px \([0-9.]+ % of the raster\), [0-9]+ tiles of [0-9]+\^2 px built, [0-9]+ units, [0-9]+ cells written]]
    --setup "${HOLES_INPUT} && $HC_INGEST ${HOLES_ARGS} -o one.hcg > one.txt 2>&1"
    --match [[rank 1/2: ]] --match [[rank 2/2: ]] --match [[rank 1/3: water steps: the depths of its [1-9][0-9]* cells in 2 steps]]
    --match [[rank 3/3: its [0-9]+ cells \([0-9.]+ MB\) written into the output in place]]
    --match [[rank 2/3: [0-9]+ source pixels of its rows checked against the cells under them]]
    --no-match [[rank 4/3|error:|warning|every rank reads the whole raster]]
    --check [[for n in 1 2 3
do cmp one.hcg g$n.hcg || exit 1
done
"$HC_INFO" one.hcg | grep -E 'steps +2 water steps'
grep -E 'vs source +max [0-9.e+]+ m, RMS [0-9.e+]+ m against the [0-9]+ valid source pixels' g3.txt
grep -E '^  |warning' one.txt | grep -vE '^ +(time|memory) ' > a.txt
grep -E '^  |warning' g3.txt | grep -vE '^ +(time|memory) ' > b.txt
diff a.txt b.txt
gdalinfo -stats holes.tif | grep -E 'STATISTICS_VALID_PERCENT=([0-8][0-9]|9[0-8])\.']]
    -- ${HC_BASH} -c [[for n in 1 2 3
do if ! "$HC_MPIRUN" -np $n "$HC_INGEST" holes.tif --tolerance 15 --max-cell 1024 --water-level 2500,2700 -o g$n.hcg > g$n.txt 2>&1
then cat g$n.txt
exit 1
fi
done
cat g3.txt g2.txt]])

  # The ranks' floods against the whole raster's at 21 levels, from below the valley floor to above every summit (closed
  # depressions that fill from a certain level on, the two holes as seeds): the same bytes from 1 and 3 ranks, and the
  # wet cells grow with the level.
  hc_mpi_test(mpi.ingest_levels_windows_many 0 [[steps +21 water steps]]
    --setup "${HOLES_INPUT}" --no-match [[error:|warning]]
    --check [[cmp one.hcg g3.hcg
"$HC_INFO" --json g3.hcg | tr -d ' \n' | grep -oE '"wet_cells":[0-9]+' | cut -d: -f2 > wet.txt
sort -n -c wet.txt && test "$(sort -u wet.txt | wc -l)" -gt 15]]
    -- ${HC_BASH} -c [[L=$(seq -s, 2000 75 3500)
"$HC_INGEST" --quiet holes.tif --tolerance 5 --water-level $L -o one.hcg || exit 1
"$HC_MPIRUN" -np 3 "$HC_INGEST" --quiet holes.tif --tolerance 5 --water-level $L -o g3.hcg || exit 1
"$HC_INFO" g3.hcg]])

  # Water steps over a projected source (no trace of a resampling to paint): every rank writes its own cells into the
  # file in place, and computes the steps' depths of its own cells, whose wet ones rank 1 writes. The same bytes.
  hc_mpi_test(mpi.ingest_steps_in_place 0 [[rank 3/3: its [0-9]+ cells \([0-9.]+ MB\) written into the output in place]]
    --setup "$HC_INGEST --quiet $HC_DATA_DIR/south_glacier_utm7.tif --water-level 2200,2400,2600 -o one.hcg"
    --match [[rank 2/2: its [0-9]+ cells .* written into the output in place]] --no-match [[error:|warning]]
    --match [[rank 1/3: water steps: the depths of its [1-9][0-9]* cells in 3 steps]]
    --match [[rank 3/3: water steps: the depths of its [1-9][0-9]* cells in 3 steps]]
    --check [[for n in 2 3
do cmp one.hcg g$n.hcg || exit 1
done
"$HC_INFO" --verify g3.hcg | grep -E 'steps +3 water steps']]
    -- ${HC_BASH} -c [[for n in 2 3
do "$HC_MPIRUN" -np $n "$HC_INGEST" "$HC_DATA_DIR/south_glacier_utm7.tif" --water-level 2200,2400,2600 -o g$n.hcg || exit 1
done]])

  # A --t_srs warp of a geographic source split at 180 degrees (etopo1_1deg moved 90 degrees east, to PDC Mercator):
  # each rank warps both pieces into its windows, floods its windows for the levels, and writes its cells in place.
  # The same bytes and summary as one process. Into EPSG:3857, whose edge is at 180 degrees, the halves would lie at
  # the map's opposite edges: refused as one process refuses it (the valid pixels counted over every rank's windows,
  # before anything is written), once, and no file is left.
  hc_mpi_test(mpi.ingest_across_180_windows 0 [[rank 3/3: water steps: the depths of its [1-9][0-9]* cells in 2 steps]]
    --setup [[gdal_translate -q -a_ullr -90.5 90.5 270.5 -90.5 "$HC_DATA_DIR/etopo1_1deg.tif" east.tif &&
"$HC_INGEST" east.tif --t_srs EPSG:3832 --water-level 0,200 -o one.hcg > one.txt 2>&1 &&
gdal_translate -q -a_srs EPSG:4326 -a_ullr 178 46 182 44 "$HC_DATA_DIR/hef_srtm.tif" across.tif]]
    --match [[rank 2/3: [0-9]+ windows? read, [0-9]+ px]] --match [[rank 3/3: its [0-9]+ cells .* written into the output in place]]
    --no-match [[every rank reads the whole raster]]
    --check [[cmp one.hcg g2.hcg && cmp one.hcg g3.hcg
grep -E 'split at 180 degrees' g3.txt
grep -E '^  |warning' one.txt | grep -vE '^ +(time|memory) ' > a.txt
grep -E '^  |warning' g3.txt | grep -vE '^ +(time|memory) ' > b.txt
diff a.txt b.txt]]
    --check [[if "$HC_MPIRUN" -np 3 "$HC_INGEST" across.tif --t_srs EPSG:3857 -o no.hcg > no.txt 2>&1
then exit 1
fi
test ! -e no.hcg && cat no.txt
test "$(grep -c 'error: .*across.tif: crosses 180 degrees of longitude, which is an edge of EPSG:3857' no.txt)" = 1]]
    -- ${HC_BASH} -c [[for n in 2 3
do if ! "$HC_MPIRUN" -np $n "$HC_INGEST" east.tif --t_srs EPSG:3832 --water-level 0,200 -o g$n.hcg > g$n.txt 2>&1
then cat g$n.txt
exit 1
fi
done
cat g2.txt g3.txt]])

  # Water steps from rasters are read window by window: each rank warps only its windows of every step raster onto the
  # working raster (the whole raster's pixel coordinates, the kernel's scale fixed), makes the merge masks of its own
  # nodes and the depths of its own cells. Over the bundled geographic DEM (resampled to UTM): a depth series in UTM at
  # 30 m with a nodata value and negative depths (a warning, counted over the ranks), the same depths at 21 m (finer
  # than the working pixel: the kernel widens), and water surfaces as a NetCDF variable over time (bands). The same
  # bytes and the same summary as one process.
  set(WATER_WINDOWS_INPUT [[gdalwarp -q -t_srs EPSG:32632 -tr 30 30 -r bilinear "$HC_DATA_DIR/hef_srtm.tif" utm30.tif &&
gdal_translate -q -scale 2000 3800 300 -1500 -ot Float32 -a_nodata -9999 utm30.tif depth.tif &&
gdal_translate -q -a_ullr 633000 5190000 650000 5170000 -outsize 800 800 -r bilinear depth.tif fine.tif &&
for l in 1:2000 2:2100 3:2200
do gdal_create -q -if "$HC_DATA_DIR/hef_srtm.tif" -ot Float32 -burn ${l#*:} s_${l%%:*}.tif || exit 1
done
gdalbuildvrt -q -separate stack.vrt s_1.tif s_2.tif s_3.tif &&
gdal_translate -q -of netCDF -mo 'NETCDF_DIM_EXTRA={time}' -mo 'NETCDF_DIM_time_DEF={3,6}' -mo 'NETCDF_DIM_time_VALUES={0,1.5,3}' -mo 'time#units=hours since 2024-06-01 00:00:00' stack.vrt run.nc]])
  hc_mpi_test(mpi.ingest_water_windows 0 [[rank 3/3: water steps: the depths of its [1-9][0-9]* cells in 3 steps]]
    --setup "${WATER_WINDOWS_INPUT}"
    --match [[rank 2/3: [0-9]+ windows read, [0-9]+ px \([0-9.]+ % of the raster\)]]
    --match [[warning: depth.tif: [1-9][0-9]* pixels of negative depth taken as dry]]
    --no-match [[error:|every rank reads the whole raster]]
    --check [[for c in depth fine nc
do cmp $c.1.hcg $c.2.hcg && cmp $c.1.hcg $c.3.hcg || exit 1
grep -E '^  |warning' $c.1.txt | grep -vE '^ +(time|memory) ' > a.txt
grep -E '^  |warning' $c.3.txt | grep -vE '^ +(time|memory) ' > b.txt
diff a.txt b.txt || exit 1
done
"$HC_INFO" --verify nc.3.hcg | grep -E 'steps +3 water steps, 0 \.\. 10800 s'
"$HC_INFO" --json depth.3.hcg | tr -d ' \n' | grep -oE '"wet_cells":[1-9][0-9]*' | head -n 1]]
    -- ${HC_BASH} -c [[run() { c=$1
shift
if ! "$HC_INGEST" "$HC_DATA_DIR/hef_srtm.tif" --tolerance 2 "$@" -o $c.1.hcg > $c.1.txt 2>&1
then cat $c.1.txt
exit 1
fi
for n in 2 3
do if ! "$HC_MPIRUN" -np $n "$HC_INGEST" "$HC_DATA_DIR/hef_srtm.tif" --tolerance 2 "$@" -o $c.$n.hcg > $c.$n.txt 2>&1
then cat $c.$n.txt
exit 1
fi
done
}
run depth --water depth.tif,depth.tif --times 0,60 && run fine --water fine.tif && run nc --water-surface run.nc && cat depth.3.txt nc.3.txt]])

  # Merges above the 64-pixel tiles: every rank merges every coarse node, so the ranks' masks (each made from its own
  # windows) are combined there. A flat plain at 100 m with a 448 m square hill at 160 m whose edges lie on the tiles'
  # edges, flooded at 150 m (--water-level) and by a depth raster dry on the hill (--water): with a tolerance that
  # lets the terrain merge across the hill's edge, only the wet/dry rule keeps the tiles around it apart. Before the
  # masks were combined, ranks that did not hold the hill merged those tiles and the file was refused.
  set(PLAIN_INPUT [[gdal_create -q -outsize 2048 2048 -bands 1 -burn 100 -ot Float32 -a_srs EPSG:32633 -a_ullr 500000 5002048 502048 5000000 plain.tif &&
printf 'id,WKT\n1,"POLYGON((500896 5001344,501344 5001344,501344 5000896,500896 5000896,500896 5001344))"\n' > hill.csv &&
gdal_rasterize -q -burn 160 hill.csv plain.tif 2>/dev/null &&
gdal_create -q -if plain.tif -burn 50 depth.tif && gdal_rasterize -q -burn 0 hill.csv depth.tif 2>/dev/null]])
  hc_mpi_test(mpi.ingest_water_windows_coarse 0 [[rank 3/3: water steps: the depths of its [0-9]+ cells in 1 step]]
    --setup "${PLAIN_INPUT}" --no-match [[error:|every rank reads the whole raster]]
    --check [[for c in level raster
do cmp $c.1.hcg $c.2.hcg && cmp $c.1.hcg $c.3.hcg || exit 1
done
"$HC_INFO" level.1.hcg | grep -E 'level [789] +[0-9.]+ m +[1-9][0-9]* cells']]
    -- ${HC_BASH} -c [[run() { c=$1
shift
if ! "$HC_INGEST" plain.tif --tolerance 100 --max-cell 512 "$@" -o $c.1.hcg > $c.1.txt 2>&1
then cat $c.1.txt
exit 1
fi
for n in 2 3
do if ! "$HC_MPIRUN" -np $n "$HC_INGEST" plain.tif --tolerance 100 --max-cell 512 "$@" -o $c.$n.hcg > $c.$n.txt 2>&1
then cat $c.$n.txt
exit 1
fi
done
}
run level --water-level 150 && run raster --water depth.tif && cat level.3.txt raster.3.txt]])

  # A water raster cut short (its header whole, its second half gone): the ranks that read the missing strips fail, and
  # every rank stops with one error naming the file; no output is left.
  hc_mpi_test(mpi.ingest_water_windows_broken nonzero [[hc-ingest: error: rank [0-9]/3: broken\.tif: resampling onto the terrain: .*broken\.tif]]
    --setup [[gdal_translate -q -ot Float32 -co TILED=NO "$HC_DATA_DIR/hef_srtm.tif" w.tif && head -c $(( $(stat -c %s w.tif) / 2 )) w.tif > broken.tif && gdalinfo broken.tif > /dev/null]]
    --absent g.hcg --no-match [[Segmentation|Abort|internal]]
    -- ${HC_BASH} -c [["$HC_MPIRUN" -np 3 "$HC_INGEST" "$HC_DATA_DIR/hef_srtm.tif" --water broken.tif -o g.hcg 2>&1 | grep -v 'building quadtree'
exit ${PIPESTATUS[0]}]])

  # --t_srs (GDAL's warper): each rank warps its own windows from the source blocks they reach (the whole output's
  # pixel centres, the kernel's scale fixed), checks its share of the source's rows against the file, and the file is
  # the same bytes as one process writes, with the same summary; with water levels too (each rank floods its own
  # windows, the cells still written in place). The bundled WGS 84 DEM to Austria's Gauss-Krueger zone.
  hc_mpi_test(mpi.ingest_warped_windows 0 [[rank 3/3: [0-9]+ windows? read, [0-9]+ px \([0-9.]+ % of the raster\)]]
    --setup [["$HC_INGEST" "$HC_DATA_DIR/hef_srtm.tif" --t_srs EPSG:31254 -o one.hcg > one.txt 2>&1 &&
"$HC_INGEST" --quiet "$HC_DATA_DIR/hef_srtm.tif" --t_srs EPSG:31254 --water-level 2600,2900 -o w1.hcg]]
    --match [[rank 2/3: [0-9]+ source pixels of its rows checked against the cells under them]]
    --match [[rank 3/3: its [0-9]+ cells \([0-9.]+ MB\) written into the output in place]]
    --no-match [[error:|warps the whole source]]
    --check [[cmp one.hcg g2.hcg && cmp one.hcg g3.hcg && cmp w1.hcg w3.hcg
grep -E 'warped to MGI / Austria GK West' g3.txt
grep -E '^  |warning' one.txt | grep -vE '^ +(time|memory) ' > a.txt
grep -E '^  |warning' g3.txt | grep -vE '^ +(time|memory) ' > b.txt
diff a.txt b.txt]]
    -- ${HC_BASH} -c [[for n in 2 3
do if ! "$HC_MPIRUN" -np $n "$HC_INGEST" "$HC_DATA_DIR/hef_srtm.tif" --t_srs EPSG:31254 -o g$n.hcg > g$n.txt 2>&1
then cat g$n.txt
exit 1
fi
done
if ! "$HC_MPIRUN" -np 3 "$HC_INGEST" "$HC_DATA_DIR/hef_srtm.tif" --t_srs EPSG:31254 --water-level 2600,2900 -o w3.hcg > w3.txt 2>&1
then cat w3.txt
exit 1
fi
cat g3.txt w3.txt]])

  # hc-influence: lists and both steps' pyramids, the same bytes from 1, 2 and 3 ranks; each rank says its share once,
  # and no rank read the grid whole for its lists (its nodes' cells and their halo: fewer cells than the grid has).
  hc_mpi_test(mpi.influence_holes_steps 0 [[rank 3/3: [0-9]+ nodes, [0-9]+ cells. lists in [0-9.]+ s \([0-9]+ cells read with their halo\). [0-9]+ pyramid tiles]]
    --setup "${HOLES_INPUT} && $HC_INGEST --quiet ${HOLES_ARGS} -o one.hcg && $HC_INFLUENCE --quiet one.hcg > /dev/null"
    --match [[ranks +3 \(mpirun\): [0-9]+ nodes]] --no-match [[error:|warning]]
    --check [[for n in 1 2 3
do for f in hci step0000.hcp step0001.hcp
do cmp one.$f g$n.$f || exit 1
done
done
test "$(grep -c 'rank 2/3:' "$OUTPUT")" = 1
cells=$("$HC_INFO" one.hcg --json | tr -d ' \n' | grep -oE '"cells":[0-9]+' | head -n 1 | cut -d: -f2)
grep -oE 'rank [23]/3: .*lists in [0-9.]+ s \([0-9]+ cells read' "$OUTPUT" | grep -oE '[0-9]+ cells read' | cut -d' ' -f1 > read.txt
cat read.txt && test "$(wc -l < read.txt)" = 2 && awk -v n="$cells" '$1 >= n / 2 { bad = 1 } END { exit bad }' read.txt]]
    -- ${HC_BASH} -c [[for n in 1 2 3
do cp one.hcg g$n.hcg && "$HC_MPIRUN" -np $n "$HC_INFLUENCE" --quiet g$n.hcg || exit 1
done]])
endif()

# A mosaic of GeoTIFF tiles (a VRT, as surveys come) in a projected CRS, read window by window: each rank reads only
# the windows of its own share of the raster (nothing holds it whole), and the file is the same bytes as one process
# writes. The fixture: the bundled 20 m South Glacier DEM cut into a 2 x 2 mosaic with its south-east tile missing (a
# hole the VRT fills with the tiles' nodata), and undeclared -32768 sentinels burnt into two tiles (the ranks' counts
# are added: the warning names the same count as one process's). The summaries (valid pixels, deviations, warnings)
# are the same text but for time and memory.
set(MOSAIC_INPUT [[S="$HC_DATA_DIR/south_glacier_utm7.tif" &&
gdal_translate -q -srcwin 0 0 124 150 "$S" t0_0.tif &&
gdal_translate -q -srcwin 124 0 124 150 "$S" t124_0.tif &&
gdal_translate -q -srcwin 0 150 124 150 "$S" t0_150.tif &&
printf 'id,WKT\n1,"POLYGON((599400 6745500,599800 6745500,599800 6746000,599400 6746000,599400 6745500))"\n2,"POLYGON((600000 6742000,600400 6742000,600400 6742500,600000 6742500,600000 6742000))"\n' > boxes.csv &&
gdal_rasterize -q -burn -32768 boxes.csv t0_0.tif 2>/dev/null &&
gdal_rasterize -q -burn -32768 boxes.csv t0_150.tif 2>/dev/null &&
gdalbuildvrt -q mosaic.vrt t0_0.tif t124_0.tif t0_150.tif]])
if(HC_GDAL_CREATE)
  hc_mpi_test(mpi.ingest_mosaic_windows 0 [[rank 3/3: [0-9]+ windows? read, [0-9]+ px \([0-9.]+ % of the raster\)]]
    --setup "${MOSAIC_INPUT} && $HC_INGEST mosaic.vrt -o one.hcg > one.txt 2>&1"
    --no-match [[error:|whole raster]]
    --check [[for n in 2 3
do cmp one.hcg g$n.hcg || exit 1
done
grep -E 'hold -32768, a classic nodata sentinel' one.txt
grep -E '^  |warning' one.txt | grep -vE '^ +(time|memory) ' > a.txt
grep -E '^  |warning' g3.txt | grep -vE '^ +(time|memory) ' > b.txt
diff a.txt b.txt && grep -E 'valid' b.txt
test "$(grep -cE 'rank [1-3]/3: [0-9]+ windows? read' g3.txt)" = 3
test "$(grep -cE 'rank [23]/3: its [0-9]+ cells \([0-9.]+ MB\) written into the output in place' g3.txt)" = 2
grep -oE 'rank [1-3]/3: .*\(([0-9.]+) % of the raster' g3.txt | grep -oE '[0-9.]+ % of' | cut -d' ' -f1 > share.txt
cat share.txt && awk '$1 >= 60 || $1 <= 0 { bad = 1 } END { exit bad }' share.txt]]
    -- ${HC_BASH} -c "${MOSAIC_RUNS}")

  # A geographic mosaic (the bundled WGS 84 DEM cut into a 2 x 2 VRT, its south-east tile missing, -32768 sentinels burnt
  # into one tile), projected to UTM window by window: each rank reads the source pixels its own windows' map reaches
  # and resamples them on the whole raster's lattice, so the file is the same bytes as one process writes. The
  # summaries are the same text but for time and memory: the sentinels' count (every source pixel counted once, by
  # strips shared over the ranks) and the check of every source pixel against the cell under it (each rank its strips,
  # against the file's regions under them): the same counts, the same largest deviation, the same RMS to 4 digits.
  set(GEO_MOSAIC [[S="$HC_DATA_DIR/hef_srtm.tif" &&
gdal_translate -q -srcwin 0 0 192 142 "$S" g0_0.tif &&
gdal_translate -q -srcwin 192 0 192 142 "$S" g192_0.tif &&
gdal_translate -q -srcwin 0 142 192 142 "$S" g0_142.tif &&
printf 'id,WKT\n1,"POLYGON((10.70 46.86,10.74 46.86,10.74 46.89,10.70 46.89,10.70 46.86))"\n' > box.csv &&
gdal_rasterize -q -burn -32768 box.csv g0_0.tif 2>/dev/null &&
gdalbuildvrt -q geo.vrt g0_0.tif g192_0.tif g0_142.tif && "$HC_INGEST" geo.vrt -o one.hcg > one.txt 2>&1]])
  hc_mpi_test(mpi.ingest_geographic_windows 0 [[rank 3/3: [0-9]+ windows? read, [0-9]+ px \([0-9.]+ % of the raster\)]]
    --setup "${GEO_MOSAIC}" --no-match [[error:|whole raster]]
    --check [[for n in 2 3
do cmp one.hcg g$n.hcg || exit 1
done
grep -E 'projected to UTM zone 32N .*map exact every [0-9]+ px' g3.txt
grep -E 'vs source +max [0-9.e+]+ m, RMS [0-9.e+]+ m against the [0-9]+ valid source pixels' g3.txt
grep -E 'lost +[0-9]+ valid source pixels' g3.txt
grep -E 'hold -32768, a classic nodata sentinel' one.txt
grep -E '^  |warning' one.txt | grep -vE '^ +(time|memory) ' > a.txt
grep -E '^  |warning' g3.txt | grep -vE '^ +(time|memory) ' > b.txt
diff a.txt b.txt
test "$(grep -cE 'rank [1-3]/3: [0-9]+ windows? read' g3.txt)" = 3]]
    -- ${HC_BASH} -c "${GEO_RUNS}")

  # Resampled on an affine map, window by window: a rotated geotransform (a VRT over the bundled LiDAR tile) and
  # --min-cell coarser than the pixels. The same bytes as one process.
  hc_mpi_test(mpi.ingest_rotated_and_min_cell_windows 0 [[rank 3/3: [0-9]+ windows? read]]
    --setup [[gdal_translate -q -of VRT "$HC_DATA_DIR/lidar1m_minnesota_utm15.tif" rot.vrt &&
sed -i 's|<GeoTransform>.*</GeoTransform>|<GeoTransform>429252.313370022, 0.9396926207859084, 0.3420201433256687, 5150885.424942633, 0.3420201433256687, -0.9396926207859084</GeoTransform>|' rot.vrt &&
"$HC_INGEST" --quiet rot.vrt -o rot1.hcg && "$HC_INGEST" --quiet "$HC_DATA_DIR/lidar1m_minnesota_utm15.tif" --min-cell 3 -o min1.hcg]]
    --match [[resampled north-up onto 1 m squares \(rotated geotransform]] --match [[resampled north-up onto 3 m squares \(--min-cell]]
    --no-match [[error:|whole raster]]
    --check [[cmp rot1.hcg rot3.hcg && cmp min1.hcg min3.hcg]]
    -- ${HC_BASH} -c [["$HC_MPIRUN" -np 3 "$HC_INGEST" rot.vrt -o rot3.hcg && "$HC_MPIRUN" -np 3 "$HC_INGEST" "$HC_DATA_DIR/lidar1m_minnesota_utm15.tif" --min-cell 3 -o min3.hcg]])

  # South-up rows and east-to-west columns (a geotransform with both signs turned): each rank mirrors its windows as
  # one process mirrors the whole raster. Same bytes.
  hc_mpi_test(mpi.ingest_windows_mirrored 0 [[rank 2/3: [0-9]+ windows? read]]
    --setup [[gdal_translate -q -a_ullr 603960 6741000 599000 6747000 "$HC_DATA_DIR/south_glacier_utm7.tif" flip.tif && "$HC_INGEST" --quiet flip.tif -o one.hcg]]
    --match [[south-up rows flipped north-up, east-to-west columns flipped]] --no-match [[error:|whole raster]]
    --check [[cmp one.hcg g.hcg]]
    -- ${HC_BASH} -c [["$HC_MPIRUN" -np 3 "$HC_INGEST" flip.tif -o g.hcg]])

  # A raster of nothing but nodata, read by windows: the error names the file, once, and no file is left.
  hc_mpi_test(mpi.ingest_windows_all_nodata nonzero [[hc-ingest: error: rank 1/3: allnd\.tif: the raster holds no valid pixel \(all nodata\)]]
    --setup [[gdal_create -q -of GTiff -outsize 100 100 -bands 1 -ot Float32 -burn 5 -a_nodata 5 -a_srs EPSG:32633 -a_ullr 500000 100 500100 0 allnd.tif]]
    --absent g.hcg --check [[test "$(grep -c 'error: ' "$OUTPUT")" = 1]]
    -- ${HC_MPIEXEC} -np 3 ${INGEST} --quiet allnd.tif -o g.hcg)

  # A tile of the mosaic that cannot be read (truncated): the rank whose windows hold it fails inside the read, every
  # rank stops there, rank 1 reports it once naming the mosaic, and no file is left.
  hc_mpi_test(mpi.ingest_mosaic_broken_tile nonzero [[hc-ingest: error: rank [1-3]/3: mosaic\.vrt: cannot read rows]]
    --setup "${MOSAIC_INPUT} && head -c 4000 t124_0.tif > cut.tif && mv cut.tif t124_0.tif"
    --absent g.hcg --check [[test "$(grep -c 'error: ' "$OUTPUT")" = 1]]
    -- ${HC_MPIEXEC} -np 3 ${INGEST} --quiet mosaic.vrt -o g.hcg)
  # The same through --t_srs: the block the warper asks for fails inside a rank's window; one error naming the mosaic,
  # no file left.
  hc_mpi_test(mpi.ingest_warped_broken_tile nonzero [[hc-ingest: error: rank [1-3]/3: mosaic\.vrt: projecting to EPSG:3338: .*cannot read rows]]
    --setup "${MOSAIC_INPUT} && head -c 4000 t124_0.tif > cut.tif && mv cut.tif t124_0.tif"
    --absent g.hcg --check [[test "$(grep -c 'error: ' "$OUTPUT")" = 1]]
    -- ${HC_MPIEXEC} -np 3 ${INGEST} --quiet mosaic.vrt --t_srs EPSG:3338 -o g.hcg)
endif()

# A rotated quadtree mesh (mesh.cmake's fixture, turned 30 degrees): rank 1 reads the mesh whole (one cell per face:
# nothing to share), the others say so; the influence cache and every step's pyramid are the same bytes from 3 ranks.
hc_mpi_test(mpi.mesh_rotated 0 [[rank 2/3: idle: model results are read by rank 1]]
  --setup "${TURNED} && $HC_INGEST --quiet t.nc -o one.hcg && $HC_INFLUENCE --quiet one.hcg > /dev/null"
  --no-match [[error:|warning]]
  --check [[cmp one.hcg m.hcg && for f in hci step0000.hcp step0001.hcp step0002.hcp
do cmp one.$f m.$f || exit 1
done
"$HC_INFO" m.hcg | grep -E '^  rotation +30\.0000000']]
  -- ${HC_BASH} -c [["$HC_MPIRUN" -np 3 "$HC_INGEST" --quiet t.nc -o m.hcg && "$HC_MPIRUN" -np 3 "$HC_INFLUENCE" --quiet m.hcg]])

# The ranks' agreement (core/ranks, support/on_ranks.h) with a failure on one rank only: inside ranks::together every rank
# stops at the same point and rank 1 reports the failing rank's error once; outside it (nobody waits for that rank) the
# failing rank reports and stops every rank. Without a failure the ranks reach the collective after it together.
add_executable(hc_ranks_check ranks_check.cpp)
target_link_libraries(hc_ranks_check PRIVATE hc_cli hc_ranks hc_ingest)
hc_target_defaults(hc_ranks_check)
set(RANKS_CHECK $<TARGET_FILE:hc_ranks_check>)
hc_mpi_test(mpi.ranks_agree 0 [[ranks_check: 3 ranks agreed]] --no-match [[error]] -- ${HC_MPIEXEC} -np 3 ${RANKS_CHECK} 0)
hc_mpi_test(mpi.ranks_fail_together nonzero [[^ranks_check: error: rank 2/3: failed inside together]]
  --no-match [[agreed]] --check [[test "$(grep -c 'error: ' "$OUTPUT")" = 1]]
  -- ${HC_MPIEXEC} -np 3 ${RANKS_CHECK} 2)
hc_mpi_test(mpi.ranks_fail_alone nonzero [[ranks_check: error: rank 3/3: failed alone, outside together]]
  --no-match [[agreed]] -- ${HC_MPIEXEC} -np 3 ${RANKS_CHECK} 3 outside)
# The builder under mpirun writes into a file only: a grid in memory is refused on every rank alike (no rank waits).
hc_mpi_test(mpi.build_in_memory_refused nonzero [[under mpirun the grid is built into a file]]
  --no-match [[built in memory]] -- ${HC_MPIEXEC} -np 2 ${RANKS_CHECK} in-memory)

# A failure under mpirun: every rank stops, rank 1 says it once, no rank waits forever, and no file is left.
hc_mpi_test(mpi.failure_reported_once nonzero [[hc-ingest: error: rank 1/3: nope\.tif: no such file \(terrain raster\)]]
  --absent g.hcg --no-match [[rank 2/3: nope]]
  --check [[test "$(grep -c 'error: ' "$OUTPUT")" = 1]]
  -- ${HC_MPIEXEC} -np 3 ${INGEST} nope.tif -o g.hcg)
# A grid file that is not one, read by every rank of hc-influence: the reader's own message, once.
hc_mpi_test(mpi.influence_bad_grid nonzero [[hc-influence: error: rank 1/3: g\.hcg: ]]
  --setup [[echo 'not a grid' > g.hcg]] --absent g.hci --absent g.hcp
  --check [[test "$(grep -c 'error: ' "$OUTPUT")" = 1]]
  -- ${HC_MPIEXEC} -np 3 ${INFLUENCE} g.hcg)
