# tests/cli/hostile_files.cmake: crafted files with VALID checksums (issue 11), included at the end of
# tests/cli/CMakeLists.txt. hc_hostile_craft (hostile_craft.cpp, ../hostile_files.h) writes them through the
# real container writer, so only the readers' own count checks stand between them and the tools.
add_executable(hc_hostile_craft hostile_craft.cpp)
target_link_libraries(hc_hostile_craft PRIVATE hc_grid)
hc_target_defaults(hc_hostile_craft)
set(CRAFT $<TARGET_FILE:hc_hostile_craft>)
set(KOOTENAI_CACHE [[$HC_INGEST --quiet "$HC_DATA_DIR/kootenai_1m.asc" -o k.hcg >/dev/null 2>&1 && $HC_INFLUENCE --quiet k.hcg >/dev/null]])

# Issue 11: a .hcg declaring 2^62 cells (empty sections, valid CRCs) failed with "vector::_M_default_append"
# and no file name; now one line names the file, the offset of the count and the problem.
hc_cli_test(hostile.grid_2e62_cells nonzero
  [[^hc-info: error: huge\.hcg: at byte offset 24: header declares 4611686018427387904 cells of 12 bytes each, more than the [0-9]+-byte file holds
$]]
  FIXTURES_REQUIRED cli_hef_hcg
  --setup "${CRAFT} grid-cells '${HEF_HCG}' huge.hcg 4611686018427387904"
  --no-match [[_M_default_append|length_error]]
  -- ${INFO} huge.hcg)
# The same file through a tool that then needs a cache: refused before any cache is built or written.
hc_cli_test(hostile.grid_2e62_cells_probe nonzero [[^hc-probe: error: huge\.hcg: at byte offset 24: header declares 4611686018427387904 cells]]
  FIXTURES_REQUIRED cli_hef_hcg
  --setup "${CRAFT} grid-cells '${HEF_HCG}' huge.hcg 4611686018427387904"
  --absent huge.hci
  -- ${PROBE} huge.hcg --xy 0,0)

# Issue 11: a .hci declaring 2^62 entries (empty INDICES, valid CRCs) made hc-probe read past the end of the
# file. Now the cache is refused at the count's offset, rebuilt (tools rebuild a bad cache and say why), and
# the value equals the one from a cache built afresh.
hc_cli_test(hostile.cache_2e62_entries 0
  [[^hc-probe: k\.hci: at byte offset 32: header declares 4611686018427387904 entries, more than the [0-9]+-byte file holds .4 bytes of INDICES each.: rebuilt]]
  --setup "${KOOTENAI_CACHE} && $<TARGET_FILE:hc-probe> k.hcg --cache k.hci --xy 556460.5,5394950.5 > fresh.csv 2>/dev/null && ${CRAFT} cache-entries k.hci k.hci 4611686018427387904"
  --check [[grep -Eq '^556460\.5,5394950\.5,[0-9]' fresh.csv && grep -v '^hc-probe' "$OUTPUT" | cmp - fresh.csv]]
  -- ${PROBE} k.hcg --cache k.hci --xy 556460.5,5394950.5)
# Issue 11: OFFSETS ending at the entry count but overshooting it before (0, m + 100, ...) read 100 indices
# past the end of INDICES before the decrease was noticed.
hc_cli_test(hostile.cache_list_past_end 0 [[^hc-probe: k\.hci: at byte offset [0-9]+: OFFSETS exceed the entry count [0-9]+ at cell 0: rebuilt]]
  --setup "${KOOTENAI_CACHE} && ${CRAFT} cache-past-end k.hci k.hci 100"
  -- ${PROBE} k.hcg --cache k.hci --xy 0,0)

# Points CSV (parsed by hc::cli::parsePointsCsv, fuzzed by fuzz_points): a binary line of 5000 bytes is
# quoted by its first 80 only, in one line, and nothing is written.
hc_cli_test(hostile.points_binary_line nonzero [[^hc-probe: error: bad\.csv: line 2: expected two numbers x,y, got '.{80}\.\.\.'
$]]
  --setup [[printf 'x,y\n' > bad.csv && head -c 5000 /dev/zero | tr '\0' '\001' >> bad.csv]]
  --absent out.csv
  -- ${PROBE} nope.hcg --points bad.csv -o out.csv)
