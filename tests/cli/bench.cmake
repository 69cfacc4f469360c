# tests/cli/bench.cmake: the benchmark programs on tiny inputs (included by CMakeLists.txt, whose helpers it uses).
# The benchmark programs are measured by hand (docs/benchmarks.md), never timed here; these runs check that they work
# on tiny inputs and that --plot writes a complete SVG (opening tag, the data's names, closing tag) and --json.
set(BENCH $<TARGET_FILE:hc-bench>)
set(BENCH_INFLUENCE $<TARGET_FILE:hc-bench-influence>)
set(BENCH_PARALLEL $<TARGET_FILE:hc-bench-parallel>)
set(SVG_COMPLETE [[head -c 4 p.svg | grep -q '<svg' && tail -n 1 p.svg | grep -q '</svg>']])
hc_cli_test(bench.render_plot 0 [[Wachau.*approximation.*ray casting.*plot written to p\.svg]]
  --exists p.svg --exists j.json
  --check ${SVG_COMPLETE} --check [[grep -q '>Wachau<' p.svg && grep -q '"scenario": "Wachau"' j.json && test "$(grep -c '<rect' p.svg)" -ge 11]]
  -- ${BENCH} --scale 64 --scenarios Wachau --size 160x90 --repeat 1 --texels 64 --plot p.svg --json j.json)
hc_cli_test(bench.influence_plot 0 [[kootenai_1m\.asc.*plot written to p\.svg]]
  --exists p.svg
  --check ${SVG_COMPLETE} --check [[grep -q 'kootenai_1m: smooth surface, sigma 1<' p.svg && grep -q '<polyline' p.svg]]
  -- ${BENCH_INFLUENCE} --quick --points 1000 --repeat 1 --dems ${HC_DATA_DIR}/kootenai_1m.asc --plot p.svg)
hc_cli_test(bench.parallel_help 0 [[usage: hc-bench-parallel]] --match [[--threads LIST]] --match [[default 2,0]]
  -- ${BENCH_PARALLEL} --help)
hc_cli_test(bench.parallel_table 0 [[threads +back to back us.* +2 +[0-9]+\.[0-9]+ +[0-9]+\.[0-9]+ +[0-9]+\.[0-9]+]]
  -- ${BENCH_PARALLEL} --threads 2 --calls 10)
hc_cli_test(bench.parallel_bad_threads nonzero [[hc-bench-parallel: error: --threads: 'two' is not a thread count]]
  -- ${BENCH_PARALLEL} --threads two)
# The fly-through: the incremental frames keep most texels (a tiny frame, 64-texel cascades, 2 m a frame).
hc_cli_test(bench.fly_through 0 [[incremental cascades: the camera flies forward 2 m a frame for 4 frames]]
  --check [[grep -q '"fly_frames": 4' j.json && grep -Eq '"fly_texels_kept": (0\.[5-9]|1\.0)' j.json]]
  -- ${BENCH} --scale 64 --scenarios Wachau --size 160x90 --repeat 1 --texels 64 --fly-frames 4 --fly-step 2 --json j.json)
if(HC_WITH_GL)
  # On the GL backend out of core the renderer keeps the texels itself (the CPU fills the cascades).
  hc_cli_test(bench.fly_through_gl 0 [[incremental cascades: the camera flies forward 2 m a frame for 4 frames]]
    --check [[grep -q '"fly_frames": 4' j.json && grep -Eq '"fly_texels_kept": (0\.[5-9]|1\.0)' j.json]]
    -- ${BENCH} --backend gl --out-of-core --pyramid --scale 64 --scenarios Wachau --size 160x90 --repeat 1 --texels 64 --fly-frames 4 --fly-step 2 --json j.json)
endif()
# Lists that would not fit what a scenario may hold (here 1 MB): the scenario runs out of core from a streamed grid
# file with its surface pyramid, and still renders (frames, hits, the pyramid's texels).
hc_cli_test(bench.out_of_core_when_lists_do_not_fit 0 [[Wachau +out of core: lists and frame .* would not fit 0\.0 GB available]]
  --match [[copied from pyramid level]] --match [[surface pyramid built in]]
  --check [[grep -q '"out_of_core": true' j.json && grep -q '"pyramid_ms"' j.json && grep -Eq '"hits": [1-9]' j.json]]
  -- ${BENCH} --scale 64 --scenarios Wachau --size 160x90 --repeat 1 --texels 64 --memory-gb 0.001 --json j.json)
# The speed/accuracy trade (issue 43): every setting's measured error lies under its frame's bound (a check that fails
# when a bound is too small), the JSON has a point per setting and the SVG the default's ring.
hc_cli_test(bench.trade 0 [[Wachau +CPU +10 m .*every measured error at or below its frame's bound: met.*trade plot written to p\.svg]]
  --exists p.svg --exists j.json
  --check ${SVG_COMPLETE} --check [[grep -q '"setting": "10 cm"' j.json && test "$(grep -c '"backend": "cpu"' j.json)" -eq 12 && grep -q '>default<' p.svg]]
  -- ${BENCH} --trade --scale 64 --scenarios Wachau --size 160x90 --repeat 1 --texels 64 --trade-samples 500 --json j.json --plot p.svg)
# A real grid with its pyramid beside it, alone, on both backends where GL is built.
if(HC_WITH_GL)
  set(TRADE_BACKENDS cpu,gl)
else()
  set(TRADE_BACKENDS cpu)
endif()
hc_cli_test(bench.trade_real_grid 0 [[k +CPU +1 m .*every measured error at or below its frame's bound: met]]
  --setup [[$HC_INGEST --quiet "$HC_DATA_DIR/kootenai_1m.asc" -o k.hcg >/dev/null 2>&1 && $HC_INFLUENCE --quiet --no-lists k.hcg >/dev/null]]
  -- ${BENCH} --trade --trade-grid k.hcg --scenarios none --backend ${TRADE_BACKENDS} --size 160x90 --repeat 1 --texels 64 --trade-samples 500)
hc_cli_test(bench.trade_no_pyramid nonzero [[hc-bench: error: k\.hcg: .*k\.hcg: no surface pyramid beside it .k\.hcp.. --trade-grid needs one: hc-influence k\.hcg]]
  --setup [[$HC_INGEST --quiet "$HC_DATA_DIR/kootenai_1m.asc" -o k.hcg >/dev/null 2>&1]]
  -- ${BENCH} --trade --trade-grid k.hcg --scenarios none --size 160x90)
hc_cli_test(bench.trade_with_budget nonzero [[hc-bench: error: --trade sweeps the error budgets itself: drop --max-error and --max-error-px]]
  -- ${BENCH} --trade --max-error 1)
hc_cli_test(bench.trade_grid_without_trade nonzero [[hc-bench: error: --trade-grid and --trade-samples go with --trade]]
  -- ${BENCH} --trade-grid k.hcg)
# A killed run's temporary grid (named with its process id) is removed by the next run; a live process's is kept.
hc_cli_test(bench.removes_stale_grids 0 [[removed \./t/hc_bench_Wachau_999999999\.hcg \(0\.0 GB\), left by hc-bench process 999999999, which is gone]]
  --setup [[mkdir t && echo stale > t/hc_bench_Wachau_999999999.hcg && echo live > t/hc_bench_Wachau_1.hcg]]
  --absent t/hc_bench_Wachau_999999999.hcg --exists t/hc_bench_Wachau_1.hcg
  -- env TMPDIR=./t ${BENCH} --scale 64 --scenarios Wachau --size 160x90 --repeat 1 --texels 64)
hc_cli_test(bench.memory_negative nonzero [[hc-bench: error: --memory-gb -1: must be a number of GB, >= 0]]
  -- ${BENCH} --memory-gb -1)
hc_cli_test(bench.plot_directory_missing nonzero [[^hc-bench: error: nodir/p\.svg: directory nodir does not exist]]
  --absent nodir
  -- ${BENCH} --scale 64 --scenarios Wachau --plot nodir/p.svg)
