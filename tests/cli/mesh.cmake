# tests/cli/mesh.cmake: UGRID quadtree meshes (issue 14, docs/design.md section 6) end to end: a scenario written as a
# mesh by hc-export and read back by hc-ingest as the same grid, a rotated quadtree (made by rotate_grid, written as a
# turned mesh) kept with its rotation through info, probe and render; and the refusals, each leaving nothing behind.
#
# The fixture: the bundled DEM flooded at 1900, 2100 and 2300 m (steps.cmake's HEF_STEPS), written as a mesh.
set(HEF_MESH "${HEF_STEPS} && $HC_EXPORT f.hcg -o f.nc >/dev/null")

# Out and back: the same cells per level (a level without cells is not in a mesh), the same steps; the probe of the flooded valley gives each step's
# level on both grids (the node coordinates carry the origin to 1e-6 m: the values agree to 1e-6 m).
hc_cli_test(mesh.roundtrip 0 [[input +heightcast quadtree mesh \(UGRID-1.0\): [0-9]+ faces \(quadrilaterals\), [0-9]+ nodes, 3 steps.*nodes within [0-9.e-]+ m of the fitted lattice.*cells +[0-9]+ \(one per face\)]]
  --setup ${HEF_MESH} --exists m.hcg --no-match [[error|warning]]
  --check [["$HC_INFO" f.hcg --json | tr -d ' \n' | grep -oE '"cells":[0-9]+|"time_s":[0-9.]+|"wet_cells":[0-9]+' | grep -v '"cells":0$' > a.txt
            "$HC_INFO" m.hcg --json | tr -d ' \n' | grep -oE '"cells":[0-9]+|"time_s":[0-9.]+|"wet_cells":[0-9]+' | grep -v '"cells":0$' > b.txt
            cat b.txt && cmp a.txt b.txt]]
  --check [["$HC_INFO" m.hcg --json | tr -d ' \n' | grep -F '"source_kind":"UGRIDmesh"' && "$HC_INFO" m.hcg --json | grep -vq max_dev_m]]
  --check [["$HC_INFO" m.hcg | grep -E 'source +f\.nc \(heightcast quadtree mesh \(UGRID-1\.0\): [0-9]+ faces .*, WGS 84 / UTM zone 32N \(EPSG:32632\)\)' && ! "$HC_INFO" m.hcg | grep '^  deviation'
            "$HC_INFO" m.hcg | grep -E '^  lattice +every node within [0-9.e-]+ m of the lattice']]
  --check [["$HC_PROBE" f.hcg --xy 622800,5170600 --layer water_surface --all-steps > pa.csv
            "$HC_PROBE" m.hcg --xy 622800,5170600 --layer water_surface --all-steps > pb.csv
            paste -d, pa.csv pb.csv | awk -F, 'NR > 1 { e = $5 - $10
                                                     if (e < 0) e = -e
                                                     if (e > 1e-6 || $4 != $9) bad = 1
                                                     n++ }
                                               END { exit bad || n != 3 }']]
  -- ${INGEST} f.nc -o m.hcg)

# A rotated quadtree: the mesh's faces turned 30 degrees against UTM's axes. Ingested with its rotation (hc-info
# prints it, --json has rotation_deg), the probe at a world point equals the unrotated grid's at the point turned
# back, and the render shows terrain.
set(TURNED "${HEF_STEPS} && '${ROTATE_GRID}' f.hcg t.hcg 30 && $HC_EXPORT t.hcg -o t.nc >/dev/null")
hc_cli_test(mesh.rotated 0 [[turned 30 degrees against the CRS's axes]]
  --setup ${TURNED} --exists r.hcg --no-match [[error|warning]]
  --check [["$HC_INFO" r.hcg | grep -E '^  rotation +30\.0000000'
            "$HC_INFO" r.hcg --json | tr -d ' \n' | grep -E '"rotation_deg":30\.0000000']]
  --check [[o=$("$HC_INFO" f.hcg --json | tr -d ' \n' | grep -oE '"origin":.[-0-9.e]+,[-0-9.e]+' | sed 's/.*://' | tr -d '[]')
            ox=${o%,*}
            oy=${o#*,}
            awk -v ox="$ox" -v oy="$oy" 'BEGIN { c = cos(atan2(1, 1) / 1.5)
                                                 s = sin(atan2(1, 1) / 1.5)
                                                 x = 9000
                                                 y = 12000
                                                 printf "%.6f,%.6f\n", ox + x, oy + y
                                                 printf "%.6f,%.6f\n", ox + c * x - s * y, oy + s * x + c * y }' > pts.txt
            "$HC_PROBE" f.hcg --xy "$(sed -n 1p pts.txt)" | tail -n 1 | cut -d, -f3 > za.txt
            "$HC_PROBE" r.hcg --xy "$(sed -n 2p pts.txt)" | tail -n 1 | cut -d, -f3 > zb.txt
            paste za.txt zb.txt
            paste za.txt zb.txt | awk '{ e = $1 - $2
                                         if (e < 0) e = -e
                                         exit !(NF == 2 && $1 > 1000 && e < 1e-3) }']]
  --check "'$<TARGET_FILE:hc-render>' r.hcg -o r.png --step 2 --size 320x180 --texels 128 --backend cpu > /dev/null && '${PNG_CHECK}' r.png"
  -- ${INGEST} t.nc -o r.hcg)

# Refusals: a sampling option on a quadtree taken as cells, a step layer that is not there, and a mesh exported over its own grid.
hc_cli_test(mesh.raster_option_refused nonzero [[^hc-ingest: error: --tolerance / --min-cell / --max-cell: f\.nc's faces are taken as cells]]
  --setup ${HEF_MESH} --absent m.hcg
  -- ${INGEST} f.nc -o m.hcg --tolerance 1)
hc_cli_test(mesh.face_layer_missing nonzero [[^hc-ingest: error: f\.nc: no variable 'vel' \(--face-layers\)]]
  --setup ${HEF_MESH} --absent m.hcg
  -- ${INGEST} f.nc -o m.hcg --face-layers vel)
hc_cli_test(mesh.face_layers_need_a_mesh nonzero [[^hc-ingest: error: --terrain-var / --water-surface-var / --face-layers: .*hef_srtm\.tif is not model results read here]]
  --absent m.hcg
  -- ${INGEST} ${D}/hef_srtm.tif -o m.hcg --face-layers vel)
hc_cli_test(mesh.export_options_refused nonzero [[^hc-export: error: --resolution: a \.nc mesh holds the cells themselves]]
  --setup ${HEF_STEPS} --absent m.nc
  -- ${EXPORT} f.hcg -o m.nc --resolution 30)

# A further face variable (a depth-shaped speed sqrt(g d), made by add_step_layer and written into the mesh by
# hc-export) read with --face-layers: probed out of core over every step it is its wet cells' field (within 0.5 % of
# sqrt(g d) of the probed depth in the deep valley, where the smoothing of a square root is nearly the square root
# of the smoothing), undefined on dry land; hc-render --color-by draws it on the water with its legend.
set(SPEED_MESH "${HEF_STEPS} && '${ADD_STEP_LAYER}' f.hcg fs.hcg speed && $HC_EXPORT fs.hcg -o fs.nc >/dev/null")
hc_cli_test(mesh.face_layers 0 [[cells +[0-9]+ \(one per face\), 3 layers: elevation .m. water_depth .m. speed .m s-1.]]
  --setup ${SPEED_MESH} --exists s.hcg --no-match [[error|warning]]
  --check [["$HC_PROBE" s.hcg --xy 622800,5170600 --layer speed --all-steps 2>/dev/null > v.csv
            "$HC_PROBE" s.hcg --xy 622800,5170600 --layer water_depth --all-steps 2>/dev/null > d.csv
            paste -d, v.csv d.csv | awk -F, 'NR > 1 { want = sqrt(9.81 * $10)
                                                     e = ($5 - want) / want
                                                     if (e < 0) e = -e
                                                     print $3, $5, want
                                                     if (!(e < 0.005)) bad = 1
                                                     n++ }
                                               END { exit bad || n != 3 }']]
  --check [["$HC_PROBE" s.hcg --xy 633759,5184153 --layer speed --step 2 2>/dev/null | tail -n 1 | grep -x '633759,5184153,']]
  --check "'$<TARGET_FILE:hc-render>' s.hcg -o c.png --color-by speed --step 2 --size 320x180 --texels 128 --backend cpu > r.txt 2>&1 && '${PNG_CHECK}' c.png"
  -- ${INGEST} fs.nc -o s.hcg --face-layers speed)
# On the GL backend (llvmpipe here) too: the exact values at the hits come from the CPU, shade.comp colours them (the
# picture against the CPU's: render_gl_parity_test); the EXR carries the values, and the picture is not the plain one.
if(HC_WITH_GL)
  hc_cli_test(render.color_by_gl 0 [[backend +gl \(]]
    --setup ${SPEED_MESH} --setup [[$HC_INGEST --quiet fs.nc -o s.hcg --face-layers speed]]
    --exists c.png --exists c.exr --no-match [[error|CPU backend only]]
    --check "'${PNG_CHECK}' c.png"
    --check "'$<TARGET_FILE:hc-render>' s.hcg -o p.png --step 2 --size 320x180 --texels 128 --backend gl > p.txt 2>&1 && ! cmp -s c.png p.png"
    -- ${RENDER} s.hcg -o c.png --exr c.exr --color-by speed --step 2 --size 320x180 --texels 128 --backend gl)
endif()
hc_cli_test(render.color_by_unknown_layer nonzero [[^hc-render: error: no layer 'speed' in the grid \(it has: elevation, water_depth, water_surface\)]]
  --setup ${HEF_STEPS} --absent c.png --absent f.hci
  -- ${RENDER} f.hcg -o c.png --color-by speed --backend cpu)
hc_cli_test(render.color_by_elevation_refused nonzero [[^hc-render: error: --color-by elevation: use --color elevation or water_depth for those]]
  --absent c.png
  -- ${RENDER} f.hcg -o c.png --color-by elevation)
hc_cli_test(render.color_by_out_of_core_refused nonzero [[^hc-render: error: --color-by needs the grid in memory with its influence lists: leave out --out-of-core]]
  --absent c.png
  -- ${RENDER} f.hcg -o c.png --color-by speed --out-of-core)

# The viewer colours by the layer as hc-render does, on either backend, the legend in the layer's units.
if(HC_WITH_GL AND HC_XVFB_RUN)
  foreach(backend cpu gl)
    string(TOUPPER ${backend} shown)
    hc_cli_test(view.color_by_${backend} 0 "backend ${shown}"
      --setup ${SPEED_MESH} --setup [[$HC_INGEST --quiet fs.nc -o s.hcg --face-layers speed]] --exists shot.png --no-match [[error]]
      --check "'${PNG_CHECK}' shot.png"
      -- ${HC_XVFB_RUN} -a -s "-screen 0 1280x1024x24" $<TARGET_FILE:hc-view> s.hcg --color-by speed --step 2 --frames 2 --screenshot shot.png --size 480x300 --texels 128 --backend ${backend})
  endforeach()
endif()

# Model results that are no quadtree, end to end: the bundled DEM written by hc-bench-models as a finite-element
# model's map (nodes at the pixel centres, two triangles a square of them, bed and levels per node, in WGS 84 degrees
# as the DEM is), sampled by hc-ingest (projected to UTM, linear over the triangles); hc-info names the model.
hc_cli_test(mesh.sampled_triangles 0 [[input +D-Flow FM map \(UGRID-1\.0\): [0-9]+ faces \(triangles\), [0-9]+ nodes, 3 steps.*grid CRS +WGS 84 / UTM zone 32N.*method +sampled at the centres of]]
  --setup "'$<TARGET_FILE:hc-bench-models>' ${D}/hef_srtm.tif -o t.nc --faces triangles --steps 3 > /dev/null"
  --exists s.hcg --no-match [[error]]
  --check [["$HC_INFO" s.hcg | grep -E '^  model +D-Flow FM map \(UGRID-1\.0\): [0-9]+ faces \(triangles\)']]
  -- ${INGEST} t.nc -o s.hcg)

# A variable of model results named as a raster has no georeferencing of its own: refused, naming the file to give.
set(BENCH_MAP "'$<TARGET_FILE:hc-bench-models>' ${D}/hef_srtm.tif -o q.nc --steps 2 > /dev/null")
hc_cli_test(mesh.model_variable_as_terrain nonzero [[^hc-ingest: error: NETCDF:"q\.nc":zb: a variable of flood model results .*give the file itself \(hc-ingest q\.nc]]
  --setup ${BENCH_MAP} --absent x.hcg
  -- ${INGEST} [[NETCDF:"q.nc":zb]] -o x.hcg)
hc_cli_test(mesh.model_variable_as_water nonzero [[^hc-ingest: error: NETCDF:"q\.nc":zs: a variable of flood model results .*--water-mesh q\.nc]]
  --setup ${BENCH_MAP} --absent x.hcg
  -- ${INGEST} ${D}/hef_srtm.tif --water-surface [[NETCDF:"q.nc":zs]] -o x.hcg)
