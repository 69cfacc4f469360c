# tests/cli/render.cmake: hc-render end to end (included by CMakeLists.txt, whose helpers and variables it uses): the
# cache and pyramid it chooses, images, EXR layers and timings, flights, the GL backend on llvmpipe, and its refusals.
set(KOOTENAI [[$HC_INGEST --quiet "$HC_DATA_DIR/kootenai_1m.asc" -o k.hcg >/dev/null 2>&1]])
# The surface pyramid beside the grid (hc-influence writes it): used when valid for the grid, with copies named per
# cascade; a stale one is not used, saying why; a pyramid named with --pyramid must exist.
set(KOOTENAI_WITH_PYRAMID [[$HC_INGEST --quiet "$HC_DATA_DIR/kootenai_1m.asc" -o k.hcg >/dev/null 2>&1 && $HC_INFLUENCE --quiet k.hcg >/dev/null 2>&1]])
hc_cli_test(render.pyramid_copies 0 [[hc-render: using surface pyramid k\.hcp.*cascade 0 .*copied from pyramid level [0-9]+. within [0-9.e-]+ m .[0-9.e-]+ px.]]
  --setup ${KOOTENAI_WITH_PYRAMID} --exists k.png --check [[grep -q '"pyramid_texels": [1-9]' t.json]]
  -- ${RENDER} k.hcg -o k.png --timings t.json --size 64x48 --texels 16)
# The error budget (issue 43): the frame's bound in the summary and the JSON, never null with a pyramid, and the error
# measured at the hits against the exact surface beside it, its largest below the bound (+ 5 mm: float32 positions).
hc_cli_test(render.error_budget_verified 0 [[accuracy: within [0-9.e-]+ m of the exact surface, [0-9.e-]+ px at the worst texel .budget 0.5 m.]]
  --match [[verified +500 hits against the exact surface: largest [0-9.e-]+ m .* bound [0-9.e-]+ m]]
  --setup ${KOOTENAI_WITH_PYRAMID} --exists k.png
  --check [[python3 -c "import json
t = json.load(open('t.json'))
v = t['verified']
assert t['error_bound_m'] is not None and t['max_error_m'] == 0.5 and v['hits'] == 500, t
assert v['max_m'] <= t['error_bound_m'] + 0.005, t"]]
  -- ${RENDER} k.hcg -o k.png --timings t.json --size 160x90 --texels 64 --backend cpu --max-error 0.5 --verify-error 500)
# A budget without the pyramid steers the texel sizes from a prediction: said; the frame's bound from its texels.
hc_cli_test(render.max_error_without_pyramid 0 [[note: without the surface pyramid .hc-influence writes it. --max-error and --max-error-px choose texel sizes from a prediction, a coarse probe of each cascade's ground. the accuracy line gives the bound the texels carry.*accuracy: within [0-9.e+-]+ m of the exact surface, [0-9.e+-]+ px at the worst texel, from the texels and the relief under them .no surface pyramid: hc-influence writes one.]]
  --setup ${KOOTENAI_GRID} --exists k.png --exists t.json
  --check [[python3 -c "import json
t = json.load(open('t.json'))
v = t['verified']
assert t['error_bound_m'] is not None and t['error_bound_from'] == 'texels' and v['hits'] == 500, t
assert all(c['texel_estimate_m'] is not None for c in t['cascades']), t
assert v['max_m'] <= t['error_bound_m'] + 0.005, t"]]
  -- ${RENDER} k.hcg -o k.png --size 64x48 --backend cpu --max-error 0.5 --timings t.json --verify-error 500)
# With water the frame bounds its shoreline, and --verify-error also says how many hits lie on the other side of the
# exact shoreline and how far it lies from them (JSON too; measured up to 9 % long, verify_error.cpp).
hc_cli_test(render.verify_shoreline 0 [[shoreline    [0-9]+ of them drawn dry where the ray came down through the exact water, [0-9]+ drawn on water where the exact surface is dry]]
  --setup [[$HC_INGEST --quiet "$HC_DATA_DIR/hef_srtm.tif" -o f.hcg --water-level 2600 >/dev/null 2>&1 && $HC_INFLUENCE --quiet f.hcg >/dev/null]]
  --exists f.png --exists t.json --match [[accuracy: within .* m of the exact surface.*. the shoreline within [0-9.]+ m]]
  --check [[python3 -c "import json
t = json.load(open('t.json'))
v = t['verified']
assert v['drawn_dry_over_water'] + v['drawn_wet_over_dry'] < v['hits'] / 20, v
assert t['shore_bound_m'] > 0 and v['shore_distance_m'] <= t['shore_bound_m'] * 1.0906, t"]]
  -- ${RENDER} f.hcg -o f.png --size 160x90 --backend cpu --verify-error 2000 --timings t.json)
hc_cli_test(render.max_error_negative nonzero [[^hc-render: error: --max-error must be a finite number >= 0 .metres.]] --absent k.png
  --setup ${KOOTENAI_WITH_PYRAMID} -- ${RENDER} k.hcg -o k.png --size 64x48 --max-error -1)
# A cache and a pyramid beside the grid (hc-influence's defaults on a small grid): the default reads the grid out of
# core with the pyramid, not the grid and cache whole, and says so; the image is the same bytes as with --cache.
hc_cli_test(render.pyramid_beside_cache_out_of_core 0 [[hc-render: the surface pyramid serves the texels: the grid is read a region at a time .out of core.]]
  --setup "${KOOTENAI} && $HC_INFLUENCE --quiet k.hcg >/dev/null" --exists k.png --exists k.hci --no-match [[error]]
  --check "'${RENDER}' k.hcg -o c.png --size 160x90 --texels 64 --backend cpu --cache k.hci > c.txt 2>&1 && ! grep -q 'region at a time' c.txt && cmp k.png c.png"
  -- ${RENDER} k.hcg -o k.png --size 160x90 --texels 64 --backend cpu)
hc_cli_test(render.stale_pyramid_not_used 0 [[hc-render: k\.hcp: stale or foreign surface pyramid.*: not used, every texel summed from the kernels]]
  --setup [[$HC_INGEST --quiet "$HC_DATA_DIR/kootenai_1m.asc" -o k.hcg >/dev/null 2>&1 && $HC_INFLUENCE --quiet k.hcg >/dev/null 2>&1 && $HC_INGEST --quiet "$HC_DATA_DIR/kootenai_1m.asc" -o k.hcg --tolerance 0.5 >/dev/null 2>&1]]
  --exists k.png -- ${RENDER} k.hcg -o k.png --size 64x48 --texels 16)
hc_cli_test(render.named_pyramid_missing nonzero [[^hc-render: error: nope\.hcp: no such file]] --absent k.png
  --setup ${KOOTENAI_WITH_PYRAMID} -- ${RENDER} k.hcg -o k.png --size 64x48 --pyramid nope.hcp)
hc_cli_test(render.help 0 [[usage: hc-render]] --match [[--camera X,Y,Z,YAW,PITCH,FOV.,ROLL.]] --match [[--near M]] --match [[--far M]] --match [[default 1024]] --match [[yaw 0 looks north]]
  -- ${RENDER} --help)
hc_cli_test(render.overview 0 [[k\.hcg -> k\.png \+ k\.exr.*approximation.*cascade 0.*ray casting +[0-9.]+ +[0-9]+ rays, [1-9][0-9]* hits.*total]]
  --setup ${KOOTENAI} --exists k.png --exists k.exr --exists t.json
  --check [[head -c 8 k.png | od -An -c | grep -q 'P   N   G' && grep -q '"raycast_ms"' t.json && grep -q '"gaussians"' t.json]]
  --match [[hc-render: no influence cache at k\.hci: the grid is read a region at a time .out of core]] --absent k.hci
  --check [[grep -q '"cells_read": [1-9]' t.json]]
  -- ${RENDER} k.hcg -o k.png --exr k.exr --timings t.json --size 160x90 --texels 128)
# Clipping planes and roll: what was asked is what the camera line reports (render_cameras_test checks the pixels).
hc_cli_test(render.near_far 0 [[camera +[0-9.]+, [0-9.]+, [0-9.]+ +yaw 20\.00 +pitch -35\.00 +fov 45\.0 +160x90 +near 50 m +far 400 m]]
  --setup ${KOOTENAI} --exists k.png
  -- ${RENDER} k.hcg -o k.png --size 160x90 --texels 128 --near 50 --far 400)
hc_cli_test(render.camera_with_roll 0 [[camera +556448\.084, 5394904\.023, 575\.255 +yaw 20\.00 +pitch -35\.00 +fov 45\.0 +160x90 +roll 30\.00]]
  --setup ${KOOTENAI} --exists k.png
  -- ${RENDER} k.hcg -o k.png --size 160x90 --texels 128 --camera 556448.084,5394904.023,575.255,20,-35,45,30)
hc_cli_test(render.bad_near nonzero [[^hc-render: error: --near -1: must be a distance >= 0 m]] --absent k.png
  -- ${RENDER} k.hcg -o k.png --near -1)
hc_cli_test(render.far_not_beyond_near nonzero [[^hc-render: error: --far 5 m is not beyond --near 10 m]] --absent k.png
  -- ${RENDER} k.hcg -o k.png --near 10 --far 5)
hc_cli_test(render.look_at_with_cells 0 [[-> k\.png]]
  --setup ${KOOTENAI} --exists k.png
  -- ${RENDER} k.hcg -o k.png --size 64x48 --texels 64 --cells --look-at 10,-20,560,25,18,540)
hc_cli_test(render.bad_fov nonzero [[^hc-render: error: camera field of view 0 degrees is outside]] --absent k.png
  --setup ${KOOTENAI}
  -- ${RENDER} k.hcg -o k.png --camera 0,0,600,0,-30,0)
hc_cli_test(render.bad_camera_text nonzero [[^hc-render: error: --camera 1,2,3: expected 6 or 7 comma-separated numbers]] --absent k.png
  -- ${RENDER} k.hcg -o k.png --camera 1,2,3)
hc_cli_test(render.bad_size nonzero [[^hc-render: error: --size 0x10]] --absent k.png
  -- ${RENDER} k.hcg -o k.png --size 0x10)
hc_cli_test(render.bad_cascades nonzero [[^hc-render: error: --cascades 7 is outside 1\.\.4]] --absent k.png
  -- ${RENDER} k.hcg -o k.png --cascades 7)
hc_cli_test(render.same_eye_and_target nonzero [[^hc-render: error: --look-at: the eye and the target are the same point]] --absent k.png
  --setup ${KOOTENAI}
  -- ${RENDER} k.hcg -o k.png --look-at 1,2,3,1,2,3)
hc_cli_test(render.missing_grid nonzero [[^hc-render: error: nope\.hcg: no such file]] --absent k.png
  -- ${RENDER} nope.hcg -o k.png)
# A flight (--fly): one image a frame, each later frame keeping the texels it still sees from the last; the kept
# texels are the bits a fresh evaluation gives, so the images are the same bytes as a flight evaluated afresh.
set(KOOTENAI_PYRAMID "${KOOTENAI} && $HC_INFLUENCE --quiet --no-lists k.hcg >/dev/null")
hc_cli_test(render.fly 0 [[a flight of 3 frames, 5 m a frame -> f_0000\.png.*frames 1\.\.2 +render median [0-9.]+ ms]]
  --setup "${KOOTENAI_PYRAMID}" --exists f_0000.png --exists f_0002.png --absent f.png --absent f_0003.png --no-match [[error]]
  --check [[awk '$1 == 1 && NF >= 10 { found = 1 + ($5 > 50) } END { exit found != 2 }' "$OUTPUT"]]
  --check "'${RENDER}' k.hcg -o g.png --fly 3 --fly-step 5 --size 160x90 --texels 64 --backend cpu --fly-fresh > fresh.txt 2>&1 && awk '\$1 ~ /^[0-9]+\$/ && NF >= 10 && \$5 != 0 { exit 1 }' fresh.txt && cmp f_0001.png g_0001.png && cmp f_0002.png g_0002.png && ! cmp -s f_0000.png f_0002.png"
  -- ${RENDER} k.hcg -o f.png --fly 3 --fly-step 5 --size 160x90 --texels 64 --backend cpu)
hc_cli_test(render.fly_one_frame nonzero [[^hc-render: error: --fly 1: a flight has 2 to 100000 frames]] --absent f_0000.png
  -- ${RENDER} k.hcg -o f.png --fly 1)
hc_cli_test(render.fly_fresh_alone nonzero [[^hc-render: error: --fly-fresh needs --fly N]] -- ${RENDER} k.hcg -o f.png --fly-fresh)
hc_cli_test(render.fly_last_image_alone nonzero [[^hc-render: error: --fly-last-image needs --fly N]] --absent f.png
  -- ${RENDER} k.hcg -o f.png --fly-last-image)
hc_cli_test(render.fly_last_image_video nonzero [[^hc-render: error: --video needs every frame's image: leave out --fly-last-image]]
  -- ${RENDER} k.hcg -o f.png --fly 3 --fly-last-image --video f.mp4)
hc_cli_test(render.fly_and_steps nonzero [[^hc-render: error: .*--steps.*--fly|--fly.*--steps]] -- ${RENDER} k.hcg -o f.png --fly 3 --steps 0:1)
# Flying west into the rising slope (537.8 m at the start, 539.6 m 10 m on): refused before any image is written.
hc_cli_test(render.fly_under_terrain nonzero [[hc-render: error: --fly frame [0-9]+: the camera at .* below the terrain surface]]
  --setup "${KOOTENAI_PYRAMID}" --absent f_0000.png
  -- ${RENDER} k.hcg -o f.png --camera 556460,5394950,538.5,270,-10,45 --fly 3 --fly-step 5 --size 160x90 --backend cpu)
if(HC_WITH_GL)
  # The GL compute backend, headless (EGL; Mesa llvmpipe where there is no GPU): a PNG and EXR layers, and the
  # device named. A GL that is not 4.3 (Mesa capped at 3.3) fails --backend gl and makes --backend auto fall back.
  # Without a cache beside the grid it reads the grid out of core (the cascades filled on the CPU), writing none.
  hc_cli_test(render.gl_backend 0 [[k\.hcg -> k\.png \+ k\.exr.*backend +gl \(.*OpenGL [4-9]\.[0-9].*approximation.*cascade 0.*ray casting +[0-9.]+ +[0-9]+ rays, [1-9][0-9]* hits]]
    --match [[no influence cache at k\.hci: the grid is read a region at a time]] --absent k.hci
    --setup ${KOOTENAI} --exists k.png --exists k.exr --no-match [[error|not available]]
    --check [[head -c 8 k.png | od -An -c | grep -q 'P   N   G' && test "$(head -c 4 k.exr | od -An -tx1 | tr -d ' ')" = 762f3101 && grep -aq water_depth k.exr && grep -aq 'N\.Z' k.exr]]
    -- ${RENDER} k.hcg -o k.png --exr k.exr --size 160x90 --texels 128 --backend gl)
  # With the cache hc-influence wrote, named: the grid, its cells and lists on the GPU, the kernels summed there.
  hc_cli_test(render.gl_in_memory 0 [[backend +gl \(.*cascade 0 .*[1-9][0-9]* Gaussians.*ray casting +[0-9.]+ +[0-9]+ rays, [1-9][0-9]* hits]]
    --setup "${KOOTENAI} && $HC_INFLUENCE --quiet k.hcg >/dev/null" --exists k.png --no-match [[error|not available|region at a time]]
    -- ${RENDER} k.hcg -o k.png --size 160x90 --texels 128 --backend gl --cache k.hci)
  # Out of core with the pyramid alone (--no-lists, as for 100 M cells): texels copied from it on the CPU, cast on the GPU.
  hc_cli_test(render.gl_out_of_core_pyramid 0 [[backend +gl \(.*copied from pyramid level [0-9]+.*ray casting +[0-9.]+ +[0-9]+ rays, [1-9][0-9]* hits]]
    --setup "${KOOTENAI} && $HC_INFLUENCE --quiet --no-lists k.hcg >/dev/null" --exists k.png --absent k.hci --no-match [[error|not available]]
    -- ${RENDER} k.hcg -o k.png --size 160x90 --texels 32 --backend gl)
  # A flight on the GL backend out of core: the CPU keeps the texels it still sees, the GPU casts every frame.
  hc_cli_test(render.gl_fly 0 [[backend +gl \(.*frame .*upload ms +GPU ms +readback ms.*frames 1\.\.2 +render median]]
    --setup "${KOOTENAI_PYRAMID}" --exists f_0000.png --exists f_0002.png --no-match [[error]]
    --check [[awk '$1 == 1 && NF >= 13 { found = 1 + ($5 > 50) } END { exit found != 2 }' "$OUTPUT"]]
    -- ${RENDER} k.hcg -o f.png --fly 3 --fly-step 5 --size 160x90 --texels 64 --backend gl)
  # --fly-last-image: the frames before the last stay on the GPU, unread; the last is the same image as that frame of
  # a flight that reads every frame back (the texels kept on the GPU do not depend on the read-back).
  hc_cli_test(render.gl_fly_last_image 0 [[frames 1\.\.2 +render median [0-9.]+ ms.*with the image \(the last frame's alone\)]]
    --setup "${KOOTENAI_PYRAMID}" --exists f_0002.png --absent f_0000.png --absent f_0001.png --absent f.png --no-match [[error]]
    --check "'${RENDER}' k.hcg -o g.png --fly 3 --fly-step 5 --size 160x90 --texels 64 --backend gl > all.txt 2>&1 && cmp f_0002.png g_0002.png"
    -- ${RENDER} k.hcg -o f.png --fly 3 --fly-step 5 --size 160x90 --texels 64 --backend gl --fly-last-image)
  # Cell outlines out of core on GL: the cell around each hit read from the file on the CPU, shade.comp darkens the
  # edges (the picture against the CPU's: render_gl_parity_test).
  hc_cli_test(render.gl_out_of_core_cells 0 [[backend +gl \(]]
    --setup ${KOOTENAI} --exists k.png --absent k.hci --no-match [[error|CPU backend only]]
    --check "'${RENDER}' k.hcg -o p.png --size 160x90 --texels 128 --backend gl > p.txt 2>&1 && ! cmp -s k.png p.png"
    -- ${RENDER} k.hcg -o k.png --size 160x90 --texels 128 --backend gl --cells)
  hc_cli_test(render.gl_without_gl43 nonzero [[^hc-render: error: --backend gl: no headless OpenGL 4\.3 context]] --absent k.png
    --setup ${KOOTENAI}
    -- env MESA_GL_VERSION_OVERRIDE=3.3 ${RENDER} k.hcg -o k.png --size 160x90 --texels 128 --backend gl)
  hc_cli_test(render.auto_falls_back_to_cpu 0 [[note: the GL backend is not available .*rendering on the CPU.*backend +cpu \(CPU, ]]
    --setup ${KOOTENAI} --exists k.png
    -- env MESA_GL_VERSION_OVERRIDE=3.3 ${RENDER} k.hcg -o k.png --size 160x90 --texels 128)
else()
  # A build without the GL backend (-DHC_WITH_GL=OFF): --backend gl says so and writes nothing; auto renders on the CPU.
  hc_cli_test(render.gl_built_out nonzero [[^hc-render: error: --backend gl: this heightcast was built without the OpenGL backend \(-DHC_WITH_GL=OFF]]
    --setup ${KOOTENAI} --absent k.png
    -- ${RENDER} k.hcg -o k.png --size 160x90 --texels 128 --backend gl)
  hc_cli_test(render.auto_without_gl_backend 0 [[note: the GL backend is not available \(this heightcast was built without.*backend +cpu \(CPU, ]]
    --setup ${KOOTENAI} --exists k.png
    -- ${RENDER} k.hcg -o k.png --size 160x90 --texels 128)
endif()
# auto takes GL on a GPU only: where the only OpenGL is software (llvmpipe, as in CI) it renders on the CPU and
# says why; on a machine with a GPU it takes GL.
hc_cli_test(render.auto_skips_software_gl 0 [[backend +(cpu \(CPU|gl \()]]
  --setup ${KOOTENAI} --exists k.png --no-match [[backend +gl \((llvmpipe|softpipe)]]
  --check [[! grep -q 'backend *cpu' "$OUTPUT" || grep -q 'software rendering .*rendering on the CPU, which is faster\|GL backend is not available' "$OUTPUT"]]
  -- ${RENDER} k.hcg -o k.png --size 160x90 --texels 128)
hc_cli_test(render.bad_backend nonzero [[^hc-render: error: --backend vulkan: use cpu, gl or auto]] --absent k.png
  -- ${RENDER} k.hcg -o k.png --backend vulkan)
