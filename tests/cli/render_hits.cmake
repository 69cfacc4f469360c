# tests/cli/render_hits.cmake: hc-render and the hits that are not on the surface (issue 11), on the bundled
# Kootenai LiDAR (1 m cells; its west edge at x = 556440, surface 538-542 m around y = 5394950).
set(KOOTENAI_HCI [[$HC_INGEST --quiet "$HC_DATA_DIR/kootenai_1m.asc" -o k.hcg >/dev/null 2>&1 && $HC_INFLUENCE k.hcg >/dev/null 2>&1]])

# A camera 38 m below the surface (538.14 m at 556465, 5394950) would see nothing: refused with a message saying
# how far below and what to do, before any evaluation, and nothing written (before: exit 0, an all-sky PNG and
# the whole approximation done for it).
hc_cli_test(render.camera_below_terrain nonzero
  [[hc-render: error: the camera at 556465\.000, 5394950\.000, 500\.000 is 38\.14 m below the terrain surface \(538\.14 m there\): every ray would start inside the terrain and see nothing.*--near M]]
  --setup ${KOOTENAI_HCI} --absent k.png --no-match [[approximation]]
  -- ${RENDER} k.hcg -o k.png --size 160x90 --texels 128 --camera 556465,5394950,500,20,-10,45)
# With --near the rays start that far out, so the same camera is not refused.
hc_cli_test(render.camera_below_terrain_with_near 0 [[near 40 m.*ray casting +[0-9.]+ +14400 rays]]
  --setup ${KOOTENAI_HCI} --exists k.png
  -- ${RENDER} k.hcg -o k.png --size 160x90 --texels 128 --camera 556465,5394950,500,20,-10,45 --near 40)
# A camera 25 m west of the domain, below the edge's surface, looking east: the domain's edge is a wall (before:
# sky in the lower half); the summary counts the wall hits, and the EXR carries the wall channel.
hc_cli_test(render.domain_edge_wall 0 [[walls +[1-9][0-9]* of [1-9][0-9]* hits on the walls at hole and domain edges \(EXR channel wall\)]]
  --setup ${KOOTENAI_HCI} --exists k.png --exists k.exr
  --check [[grep -a -q 'water_depth' k.exr && grep -a -q 'wall' k.exr]]
  -- ${RENDER} k.hcg -o k.png --exr k.exr --size 160x90 --texels 128 --camera 556415,5394950,535,90,0,50)

# Texels finer than the stored pyramid levels (1 m texels over the 2-8 m cells; 32 texels a side put the cascades on levels 0-1): interpolated by default,
# counted in the stage table and the timings JSON; --pyramid-interpolate 0 sums them; out of range is refused.
hc_cli_test(render.pyramid_interpolated 0 [[interpolated from up to [1-3] levels? above]]
  --setup ${KOOTENAI_HCI} --exists k.png --exists t.json
  --check "grep -q '\"pyramid_interpolated\": [1-9]' t.json && '${RENDER}' k.hcg -o z.png --size 160x90 --texels 32 --backend cpu --pyramid-interpolate 0 --camera 556420,5394910,575,45,-30,60 --timings z.json >/dev/null && ! grep -q '\"pyramid_interpolated\": [1-9]' z.json"
  -- ${RENDER} k.hcg -o k.png --size 160x90 --texels 32 --backend cpu --camera 556420,5394910,575,45,-30,60 --timings t.json)
hc_cli_test(render.pyramid_interpolate_out_of_range nonzero [[^hc-render: error: --pyramid-interpolate 9 is outside 0\.\.8]]
  --setup ${KOOTENAI_HCI} --absent k.png
  -- ${RENDER} k.hcg -o k.png --pyramid-interpolate 9)
hc_cli_test(render.beam_tile_out_of_range nonzero [[^hc-render: error: --beam-tile 65 is outside 0\.\.64]]
  --setup ${KOOTENAI_HCI} --absent k.png
  -- ${RENDER} k.hcg -o k.png --beam-tile 65)
