# tests/cli/view.cmake: hc-view end to end under Xvfb and offscreen (included by CMakeLists.txt, whose helpers and
# variables it uses): scripted flights on both backends, out of core, the error budget and its keys, bookmarks, and
# its refusals. hc-view needs a window or a headless context, and OpenGL: built, and tested, with HC_WITH_GL only.
if(HC_WITH_GL)
  # The window runs under Xvfb (a virtual X server: no screen needed); png_check (png_check.cpp) asserts that
  # the screenshot shows terrain, not a blank window.
  set(VIEW $<TARGET_FILE:hc-view>)

  hc_cli_test(view.help 0 [[usage: hc-view]] --match [[--backend gl\|cpu\|auto]] --match [[default auto]] --match [[default 1280x720]]
    --match [[--frames N]] --match [[yaw 0 looks north]] --match [[press H in the window]] --match [[--max-error-px P]]
    --no-match [[error:]] -- ${VIEW} --help)
  # Without a display: a window is refused (no --frames), scripted frames render offscreen in a headless context.
  hc_cli_test(view.no_display nonzero [[^hc-view: error: no display: DISPLAY is not set]]
    --match [[--frames N renders scripted frames offscreen]] --setup ${KOOTENAI} --absent k.hci
    -- env -u DISPLAY -u WAYLAND_DISPLAY ${VIEW} k.hcg)
  hc_cli_test(view.offscreen_needs_frames nonzero [[^hc-view: error: --offscreen needs --frames N]]
    -- ${VIEW} k.hcg --offscreen)
  # The GL backend offscreen on llvmpipe (EGL's surfaceless platform): its frames drawn into the framebuffer object.
  hc_cli_test(view.offscreen_gl 0 [[hc-view: note: no display \(DISPLAY is not set\): the 4 frames render offscreen]]
    --match [[hc-view: backend GL \(]] --match [[hc-view: k\.hcg -> shot\.png \(4 frames\)]]
    --match [[frames: 4 in [0-9.]+ s]] --no-match [[error|warning]]
    --setup ${KOOTENAI} --exists shot.png --check "'${PNG_CHECK}' shot.png"
    -- env -u DISPLAY -u WAYLAND_DISPLAY ${VIEW} k.hcg --backend gl --frames 4 --screenshot shot.png --size 320x240 --texels 256)
  hc_cli_test(view.unknown_option nonzero [[^hc-view: error: unknown option --frobnicate \(see --help\)]]
    -- ${VIEW} k.hcg --frobnicate)
  hc_cli_test(view.bad_camera_text nonzero [[^hc-view: error: --camera 1,2,3: expected 6 or 7 comma-separated numbers]]
    -- ${VIEW} k.hcg --camera 1,2,3)
  hc_cli_test(view.bad_backend nonzero [[^hc-view: error: --backend vulkan: use cpu, gl or auto]]
    -- ${VIEW} k.hcg --backend vulkan)
  hc_cli_test(view.missing_bookmark nonzero [[^hc-view: error: k\.bookmarks\.json: no bookmark 5]]
    --setup "${KOOTENAI} && printf '{\"format\": \"heightcast-bookmarks\", \"version\": 1, \"bookmarks\": \\x5b\\x5d}' > k.bookmarks.json"
    --absent k.hci
    -- ${VIEW} k.hcg --bookmark 5)
  hc_cli_test(view.screenshot_without_frames nonzero [[^hc-view: error: --screenshot needs --frames N]]
    -- ${VIEW} k.hcg --screenshot shot.png)

  if(HC_XVFB_RUN)
    # The bundled DEM flooded at 2000 m: terrain and water. 30 frames of the scripted motion, the last at full size;
    # 256 texels per cascade keep the GL backend on llvmpipe (no GPU: seconds per 1024-texel frame) within the timeout.
    set(HEF_FLOODED [[$HC_INGEST --quiet "$HC_DATA_DIR/hef_srtm.tif" -o hef.hcg --tolerance 1 --max-cell 512 --water-level 2000 >/dev/null 2>&1]])
    foreach(backend cpu gl auto)
      # auto takes GL on a GPU only (on llvmpipe, as in CI, the CPU backend draws the window).
      set(extra "")
      if(backend STREQUAL "auto")
        set(extra --no-match [[hc-view: backend GL \((llvmpipe|softpipe)]])
      endif()
      # The last frame's stage times, each above zero (on llvmpipe in a window, timer queries once gave 0 ms for
      # the approximation and shading), and the frame rate over the 30 frames.
      hc_cli_test(view.screenshot_${backend} 0 [[hc-view: hef\.hcg -> shot\.png \(30 frames\)]] ${extra}
        --match [[frames: 30 in [0-9.]+ s, [0-9.]+ a second. a frame median [0-9.]+ ms, 99th percentile [0-9.]+ ms]]
        --match [=[approximation +[0-9]*[1-9][0-9]*\.[0-9]+|approximation +0\.[0-9]*[1-9]]=]
        --match [=[shading +[0-9]*[1-9][0-9]*\.[0-9]+|shading +0\.[0-9]*[1-9]]=]
        --setup ${HEF_FLOODED} --exists shot.png --no-match [[error|warning]] --match [[hc-view: backend (CPU|GL) \(]]
        --check "'${PNG_CHECK}' shot.png"
        -- ${HC_XVFB_RUN} -a -s "-screen 0 1280x1024x24" ${VIEW} hef.hcg --backend ${backend} --frames 30 --screenshot shot.png --size 640x400 --texels 256)
    endforeach()
    # Offscreen (no DISPLAY) the CPU backend's frames are the window's to the byte: the screenshots are the same under
    # the HUD (rows 0-119 hold its text, whose timings differ from run to run).
    hc_cli_test(view.offscreen_same_as_window 0 [[hc-view: note: no display \(DISPLAY is not set\): the 6 frames render offscreen]]
      --match [[hc-view: backend CPU \(]] --no-match [[error|warning]]
      --setup ${HEF_FLOODED} --exists off.png --check "'${PNG_CHECK}' off.png"
      --check "'${HC_XVFB_RUN}' -a -s '-screen 0 1280x1024x24' '${VIEW}' hef.hcg --backend cpu --frames 6 --screenshot win.png --size 640x400 --texels 256 > /dev/null 2>&1 && '${PNG_CHECK}' --same-below 120 off.png win.png"
      -- env -u DISPLAY -u WAYLAND_DISPLAY ${VIEW} hef.hcg --backend cpu --frames 6 --screenshot off.png --size 640x400 --texels 256)
    # Out of core (no lists: the frames read the cells they need; the ground under the camera from the cells around it):
    # the scripted flight draws, and no cache is written.
    hc_cli_test(view.out_of_core 0 [[hc-view: hef\.hcg -> shot\.png \(30 frames\)]]
      --match [[hc-view: --out-of-core: the grid is read a region at a time]] --match [[hc-view: backend CPU \(]]
      --setup ${HEF_FLOODED} --exists shot.png --absent hef.hci --no-match [[error|warning]]
      --check "'${PNG_CHECK}' shot.png"
      -- ${HC_XVFB_RUN} -a -s "-screen 0 1280x1024x24" ${VIEW} hef.hcg --out-of-core --backend cpu --frames 30 --screenshot shot.png --size 640x400 --texels 256)
    # The GL backend out of core: new texels evaluated on the CPU, the cascades kept and cast on the GPU (llvmpipe here),
    # cell outlines from the cells around the hits, read on the CPU.
    hc_cli_test(view.out_of_core_gl 0 [[hc-view: hef\.hcg -> shot\.png \(30 frames\)]]
      --match [[hc-view: backend GL \(]]
      --setup ${HEF_FLOODED} --exists shot.png --absent hef.hci --no-match [[error|warning|cell outlines need]]
      --check "'${PNG_CHECK}' shot.png"
      -- ${HC_XVFB_RUN} -a -s "-screen 0 1280x1024x24" ${VIEW} hef.hcg --out-of-core --backend gl --cells --frames 30 --screenshot shot.png --size 640x400 --texels 256)
    # The error budget reaches the viewer on both backends: with --max-error 10 the frame's bound is under 10 m (35.3 m
    # without it at these texels), and the summary names the budget.
    foreach(backend cpu gl)
      hc_cli_test(view.error_budget_${backend} 0 [[accuracy: within [0-9]\.[0-9]+ m of the exact surface, [0-9.]+ px at the worst texel \(budget 10 m\)]]
        --setup ${HEF_FLOODED} --setup [[$HC_INFLUENCE hef.hcg --quiet >/dev/null]] --exists shot.png --no-match [[error]]
        -- ${HC_XVFB_RUN} -a -s "-screen 0 1280x1024x24" ${VIEW} hef.hcg --backend ${backend} --frames 3 --screenshot shot.png --size 480x300 --texels 512 --max-error 10)
    endforeach()
    # The keys that steer the budget, pressed by --keys one a frame: N sets 1 px, B halves it (0.25 px after NBB), M
    # drops it (no budget after NBM); the summary is the last frame's, so it shows the keys reached the renderer.
    hc_cli_test(view.error_budget_keys 0 [[accuracy: within [0-9.]+ m of the exact surface, [0-9.]+ px at the worst texel \(budget 0\.25 px\)]]
      --setup ${HEF_FLOODED} --setup [[$HC_INFLUENCE hef.hcg --quiet >/dev/null]] --no-match [[error]]
      --check "'${HC_XVFB_RUN}' -a -s '-screen 0 1280x1024x24' '${VIEW}' hef.hcg --backend cpu --frames 4 --size 480x300 --keys NBM > m.txt 2>&1 && grep -q 'accuracy: within' m.txt && ! grep -q '(budget' m.txt"
      -- ${HC_XVFB_RUN} -a -s "-screen 0 1280x1024x24" ${VIEW} hef.hcg --backend cpu --frames 4 --size 480x300 --keys NBB)
    hc_cli_test(view.keys_refused nonzero [[^hc-view: error: --keys: '\+' is not a letter, a digit or a space]]
      --setup ${KOOTENAI}
      -- ${VIEW} k.hcg --frames 3 --keys N+)
    # A display that cannot be opened: one line naming DISPLAY.
    hc_cli_test(view.display_unreachable nonzero [[^hc-view: error: cannot open the display \(DISPLAY=:9876\)]]
      --setup ${KOOTENAI} --absent k.hci
      -- env DISPLAY=:9876 ${VIEW} k.hcg --frames 3)
    # A broken bookmarks file: a warning naming it, the viewer still runs, the file is left as it was.
    hc_cli_test(view.broken_bookmarks 0 [[hc-view: warning: k\.bookmarks\.json: at byte [0-9]+: .*bookmarks start empty]]
      --setup "${KOOTENAI} && printf '{\"format\": \"heightcast-bookmarks\", \"version\": 1, \"bookmarks\": \\x5b{\"slot\": 1,' > k.bookmarks.json && cp k.bookmarks.json orig.json"
      --exists shot.png --check "'${PNG_CHECK}' shot.png" --check [[cmp k.bookmarks.json orig.json]]
      -- ${HC_XVFB_RUN} -a -s "-screen 0 1280x1024x24" ${VIEW} k.hcg --backend cpu --frames 3 --screenshot shot.png --size 320x240)
    # A valid bookmarks file with a bad value: the warning says which bookmark and field.
    hc_cli_test(view.invalid_bookmark 0 [[hc-view: warning: k\.bookmarks\.json: bookmark 1: fov is outside \(0, 179\] degrees]]
      --setup "${KOOTENAI} && printf '{\"format\": \"heightcast-bookmarks\", \"version\": 1, \"bookmarks\": [{\"slot\": 1, \"x\": 0, \"y\": 0, \"z\": 600, \"yaw\": 0, \"pitch\": -30, \"fov\": 0}]}' > k.bookmarks.json"
      --exists shot.png
      -- ${HC_XVFB_RUN} -a -s "-screen 0 1280x1024x24" ${VIEW} k.hcg --backend cpu --frames 2 --screenshot shot.png --size 320x240)
    # --bookmark N starts at a saved view: the scripted run ends exactly there (it prints its last camera).
    hc_cli_test(view.start_at_bookmark 0 [[camera +630\.500, 5170\.250, 560\.000  yaw 30\.00  pitch -20\.00  fov 55\.0  320x240]]
      --setup "${KOOTENAI} && printf '{\"format\": \"heightcast-bookmarks\", \"version\": 1, \"bookmarks\": \\x5b{\"slot\": 4, \"x\": 630.5, \"y\": 5170.25, \"z\": 560, \"yaw\": 30, \"pitch\": -20, \"fov\": 55}\\x5d}' > k.bookmarks.json"
      --exists shot.png --no-match [[warning]]
      -- ${HC_XVFB_RUN} -a -s "-screen 0 1280x1024x24" ${VIEW} k.hcg --backend cpu --bookmark 4 --frames 2 --screenshot shot.png --size 320x240)
    # No OpenGL 4.3 (Mesa capped at 3.3): --backend auto falls back to a 3.3 context and the CPU backend, saying
    # why; --backend gl fails before loading anything.
    hc_cli_test(view.fallback_gl33 0 [[hc-view: note: the GL backend is not available \(no OpenGL 4\.3 core context.*: rendering on the CPU]]
      --match [[hc-view: backend CPU \(]] --setup ${KOOTENAI} --exists shot.png --check "'${PNG_CHECK}' shot.png"
      -- env MESA_GL_VERSION_OVERRIDE=3.3 ${HC_XVFB_RUN} -a -s "-screen 0 1280x1024x24" ${VIEW} k.hcg --frames 3 --screenshot shot.png --size 320x240)
    hc_cli_test(view.gl_without_gl43 nonzero [[^hc-view: error: --backend gl: no OpenGL 4\.3 core context]]
      --setup ${KOOTENAI} --absent k.hci --absent shot.png
      -- env MESA_GL_VERSION_OVERRIDE=3.3 ${HC_XVFB_RUN} -a -s "-screen 0 1280x1024x24" ${VIEW} k.hcg --backend gl --frames 3 --screenshot shot.png)
    # xvfb-run -a picks a free display number, but two starting at once can pick the same one: one at a time.
    set_tests_properties(cli.view.screenshot_cpu cli.view.screenshot_auto cli.view.out_of_core cli.view.broken_bookmarks cli.view.invalid_bookmark
                         cli.view.fallback_gl33 cli.view.gl_without_gl43 cli.view.start_at_bookmark cli.view.offscreen_same_as_window PROPERTIES RESOURCE_LOCK xvfb)
  else()
    message(WARNING "tests/cli: xvfb-run not found (Debian: xvfb xauth): the hc-view window tests are left out")
  endif()
endif()
