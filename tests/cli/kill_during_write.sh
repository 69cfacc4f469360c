#!/usr/bin/env bash
# kill_during_write.sh CASE: issue 11, "kill -9 during every write (grid, cache, images) never leaves a partial
# file under the real name". One CASE per writer (see the case list below). It
#   1. runs the writer to completion in ref/: the reference outputs, and the run time T;
#   2. runs it again in kill/ NKILL times, SIGKILLed after delays spread over 0.05 T .. 1.25 T, and NTEMP times
#      as soon as one of its temporaries (OUTPUT.tmp.XXXXXX) appears, i.e. in the middle of a write; after each:
#      - the run ended by the kill (137) or had finished (0): nothing else (no error, no sanitizer abort);
#      - each output's real name is absent or a complete, valid file (check() below);
#      - every other new file is a temporary named OUTPUT.tmp.XXXXXX: never an output's name or extension,
#        so neither a later run nor a glob (*.png) takes it for output;
#   3. runs it once more to completion: every output valid, and no temporary left (a writer removes the
#      temporaries that killed runs left for its target: core/src/atomic_file.cpp).
# Timing decides only where the kills land, never the verdict: a kill before, during or after the write must
# pass the same checks, so a loaded machine cannot fail it. The summary counts where the kills landed (a
# temporary left = mid-write), so a run whose kills all missed the writes says so.
# Environment: HC_INGEST HC_INFO HC_INFLUENCE HC_PROBE HC_RENDER HC_EXPORT HC_FILE_CHECK HC_DATA_DIR HC_CLI_WORK.
set -uo pipefail
case_name=${1:?usage: kill_during_write.sh CASE}
NKILL=${HC_KILL_COUNT:-8}
NTEMP=${HC_KILL_ON_TEMP_COUNT:-2}
work=$HC_CLI_WORK/kill.$case_name
rm -rf "$work" && mkdir -p "$work/ref" "$work/kill" || exit 1
src=$HC_DATA_DIR/hef_srtm.tif
fail() { echo "kill_during_write $case_name: FAIL: $*" >&2; exit 1; }

# Inputs a case reads (made in ref/ before the reference run, copied into kill/): a grid and its cache.
make_grid() { "$HC_INGEST" "$src" -o "$1/g.hcg" --quiet >/dev/null && "$HC_INFLUENCE" "$1/g.hcg" --quiet >/dev/null; }
# hc-probe's points: every cell centre of the grid (hc-info's CSV starts x,y as --points wants).
make_points() { "$HC_INFO" "$1/g.hcg" --cells-csv "$1/pts.csv" >/dev/null; }

# The cases: inputs, command (run in its directory), outputs.
inputs=(g.hcg g.hci g.hcp)
case $case_name in
  ingest)     inputs=(); cmd=("$HC_INGEST" "$src" -o g.hcg --quiet); outputs=(g.hcg) ;;
  influence)  inputs=(g.hcg); cmd=("$HC_INFLUENCE" g.hcg -o g.hci --quiet); outputs=(g.hci g.hcp) ;;
  info_csv)   cmd=("$HC_INFO" g.hcg --cells-csv cells.csv); outputs=(cells.csv) ;;
  probe_csv)  inputs=(g.hcg g.hci g.hcp pts.csv); cmd=("$HC_PROBE" g.hcg --cache g.hci --points pts.csv -o p.csv); outputs=(p.csv) ;;
  render)     cmd=("$HC_RENDER" g.hcg --cache g.hci -o o.png --exr o.exr --timings t.json --size 480x270)
              outputs=(o.png o.exr t.json) ;;
  export_tif) cmd=("$HC_EXPORT" g.hcg --cache g.hci --resolution 30 --quiet -o e.tif); outputs=(e.tif) ;;
  export_exr) cmd=("$HC_EXPORT" g.hcg --cache g.hci --resolution 30 --quiet --layer elevation -o e.exr); outputs=(e.exr) ;;
  export_vdb) cmd=("$HC_EXPORT" g.hcg --cache g.hci --resolution 60 --quiet -o e.vdb); outputs=(e.vdb) ;;
  *) fail "unknown case" ;;
esac

# check FILE: is kill/FILE complete and valid? Outputs that are the same bytes on every run (checked in step 1)
# must equal the reference; the .hcg (a few bytes of its statistics differ between runs) is validated whole by
# hc-info --verify; the timings JSON must have the reference's keys and structure (its numbers are times); a VDB (a fresh
# UUID per file) must hold the reference's grids with the same active voxels.
check() {
  local f=$1
  case $f in
    *.hcg) "$HC_INFO" --verify "kill/$f" >/dev/null 2>&1 ;;
    *.json) cmp -s <(sed -E 's/-?[0-9][0-9.eE+-]*//g' "kill/$f") <(sed -E 's/-?[0-9][0-9.eE+-]*//g' "ref/$f") ;;
    *.vdb) local got want
           got=$("$HC_FILE_CHECK" "kill/$f" 2>&1) && want=$("$HC_FILE_CHECK" "ref/$f" 2>&1) && [ "$got" = "$want" ] ;;
    *) cmp -s "kill/$f" "ref/$f" ;;
  esac
}

# HC_FILE_CHECK (hc_vdb_check) is empty in a build without OpenVDB, where export_vdb is not run.
for t in "$HC_INGEST" "$HC_INFO" "$HC_INFLUENCE" "$HC_PROBE" "$HC_RENDER" "$HC_EXPORT" ${HC_FILE_CHECK:+"$HC_FILE_CHECK"}; do
  [ -x "$t" ] || fail "$t is not an executable"
done
cd "$work" || exit 1
if [ ${#inputs[@]} -gt 0 ]; then
  make_grid ref || fail "could not make the input grid"
  [[ " ${inputs[*]} " == *" pts.csv "* ]] && { make_points ref || fail "could not make the points"; }
  for f in "${inputs[@]}"; do cp "ref/$f" kill/ || exit 1; done
fi

# 1. The reference run, timed (only to place the kills). Deterministic outputs are checked to be so.
t0=$EPOCHREALTIME
(cd ref && "${cmd[@]}" >/dev/null 2>&1) || fail "the reference run failed: ${cmd[*]}"
t1=$EPOCHREALTIME
run_us=$(( (${t1/./} - ${t0/./}) ))
for f in "${outputs[@]}"; do [ -s "ref/$f" ] || fail "the reference run did not write $f"; done
# A second full run: its outputs must pass check(), which also shows that the byte-compared ones are deterministic.
(cd kill && "${cmd[@]}" >/dev/null 2>&1) || fail "a second full run failed"
for f in "${outputs[@]}"; do check "$f" || fail "two full runs differ in $f (or it is invalid): check() cannot judge it"; done
echo "$case_name: full run $((run_us / 1000)) ms: ${cmd[*]##*/}"

# After a killed or finished run: outputs valid or absent, other new files only temporaries of the outputs.
mid=0 before=0 between=0 done_=0
verify() {
  local what=$1 f name left=0 ok
  for f in "${outputs[@]}"; do
    [ -e "kill/$f" ] && { check "$f" || fail "$what: kill/$f exists but is not a complete valid file"; }
  done
  while IFS= read -r name; do
    [ -n "$name" ] || continue
    ok=0
    for f in "${inputs[@]}" "${outputs[@]}"; do [ "$name" = "$f" ] && ok=1; done
    [ $ok = 1 ] && continue
    for f in "${outputs[@]}"; do [[ $name =~ ^${f//./\\.}\.tmp\.[A-Za-z0-9]{6}$ ]] && ok=1; done
    [ $ok = 1 ] || fail "$what: left kill/$name, which is neither an output nor one of its temporaries"
    left=1
  done < <(ls -A kill)
  return $left
}

# 2. The kills. Outputs of the previous run are removed first, so each kill shows what this run left.
kill_once() {
  local what=$1 delay_us=$2 on_temp=$3 pid rc f
  for f in "${outputs[@]}"; do rm -f "kill/$f"; done
  (cd kill && exec "${cmd[@]}" >/dev/null 2>&1) &
  pid=$!
  if [ "$on_temp" = 1 ]; then
    # Busy-poll (builtins only) until a temporary of an output appears, then kill at once.
    shopt -s nullglob
    while kill -0 "$pid" 2>/dev/null; do
      for f in "${outputs[@]}"; do
        t=(kill/"$f".tmp.??????)
        [ ${#t[@]} -gt 0 ] && break 2
      done
    done
    shopt -u nullglob
  else
    sleep "$(printf '%d.%06d' $((delay_us / 1000000)) $((delay_us % 1000000)))"
  fi
  kill -9 "$pid" 2>/dev/null
  { wait "$pid"; } 2>/dev/null  # no "Killed" line from bash
  rc=$?
  [ $rc = 137 ] || [ $rc = 0 ] || fail "$what: the run ended with status $rc, neither killed (137) nor done (0)"
  local present=0
  for f in "${outputs[@]}"; do [ -e "kill/$f" ] && present=$((present + 1)); done
  if ! verify "$what"; then mid=$((mid + 1))
  elif [ $present = ${#outputs[@]} ]; then done_=$((done_ + 1))
  elif [ $present = 0 ]; then before=$((before + 1))
  else between=$((between + 1)); fi
}
for ((i = 0; i < NKILL; i++)); do
  delay=$(( run_us * (5 + 120 * i / (NKILL > 1 ? NKILL - 1 : 1)) / 100 ))
  kill_once "kill $((i + 1)) after $((delay / 1000)) ms" "$delay" 0
done
for ((i = 0; i < NTEMP; i++)); do kill_once "kill on a temporary $((i + 1))" 0 1; done

# 3. A full run afterwards: valid outputs, and the killed runs' temporaries are gone.
for f in "${outputs[@]}"; do rm -f "kill/$f"; done
(cd kill && "${cmd[@]}" >/dev/null 2>&1) || fail "the full run after the kills failed"
verify "the full run after the kills" || fail "the full run after the kills left temporaries: $(ls -A kill | grep '\.tmp\.' | tr '\n' ' ')"
for f in "${outputs[@]}"; do check "$f" || fail "the full run after the kills wrote an invalid $f"; done
echo "$case_name: $((NKILL + NTEMP)) kills: $mid mid-write (a temporary left), $before before any output, $between between two outputs, $done_ after all outputs were in place; every output absent or valid, every leftover a temporary, removed by the next run"
# Passed: its grids and caches go (as expect.sh's do), unless HC_CLI_KEEP=1.
[ "${HC_CLI_KEEP:-0}" = 1 ] || { cd / && rm -rf -- "$work"; }
