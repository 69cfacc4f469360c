#!/usr/bin/env bash
# expect.sh: runs one command as a user would and checks what came of it (the CLI tests' driver).
#
#   expect.sh STATUS REGEX [options] -- COMMAND [ARG...]
#
#   STATUS   0, nonzero or a number. "nonzero" means a clean failure: exit 1..125. Death by a signal (a crash,
#            an abort, the OOM killer) or 126/127 (could not run) never counts as the expected failure.
#   REGEX    POSIX extended regex that the command's stdout + stderr (together, as one text) must match
#            somewhere; '.' also matches a line end, so 'cells.*deviation' may span lines.
#   options (each may be repeated; relative paths are relative to --dir):
#   --dir DIR          run in DIR, removed and made afresh first (each test has its own: ctest -j is safe)
#   --setup SCRIPT     bash run in DIR before the command, to make fixtures; it must succeed
#   --absent PATH      PATH must not exist afterwards (no partial output left behind)
#   --exists PATH      PATH must exist afterwards (and be a non-empty file, if a file)
#   --match REGEX      a further regex the output must match
#   --no-match REGEX   a regex the output must not match
#   --check SCRIPT     bash run in DIR afterwards; must succeed. It sees OUTPUT (a file holding the command's
#                      output) and STATUS (its exit status); what it prints is shown if it fails.
#   --allow-new-files  a failing command may leave new files in DIR (otherwise, when STATUS is not 0, any file
#                      that was not there after --setup counts as left behind)
#   --keep             keep DIR after a pass: other tests read its files (a FIXTURES_SETUP test)
#
# A passing test's DIR is removed (the suite's outputs would otherwise fill gigabytes a build: CI makes three
# builds on one disk), unless --keep or HC_CLI_KEEP=1 in the environment; a failing test's DIR always stays.
#
# Whatever the STATUS, a temporary file of an atomic write (NAME.tmp.XXXXXX) left in DIR fails the test.
# On failure, everything that was expected and everything that came out is printed, and the exit status is 1.
set -u

usage() { echo "usage: expect.sh STATUS REGEX [--dir D] [--setup S] [--absent P] [--exists P] [--match R] [--no-match R] [--check S] [--allow-new-files] [--keep] -- COMMAND [ARG...]" >&2; exit 2; }

[ $# -ge 3 ] || usage
want_status=$1
want_regex=$2
shift 2
case $want_status in
  nonzero | 0 | [1-9] | [1-9][0-9] | 1[0-9][0-9] | 2[0-4][0-9] | 25[0-5]) ;;
  *) echo "expect.sh: STATUS must be 0, nonzero or a number, not '$want_status'" >&2; exit 2 ;;
esac

dir=""
allow_new=0
keep=0
setups=() absents=() exists=() matches=("$want_regex") nomatches=() checks=()
while [ $# -gt 0 ]; do
  case $1 in
    --) shift; break ;;
    --dir) [ $# -ge 2 ] || usage; dir=$2; shift 2 ;;
    --setup) [ $# -ge 2 ] || usage; setups+=("$2"); shift 2 ;;
    --absent) [ $# -ge 2 ] || usage; absents+=("$2"); shift 2 ;;
    --exists) [ $# -ge 2 ] || usage; exists+=("$2"); shift 2 ;;
    --match) [ $# -ge 2 ] || usage; matches+=("$2"); shift 2 ;;
    --no-match) [ $# -ge 2 ] || usage; nomatches+=("$2"); shift 2 ;;
    --check) [ $# -ge 2 ] || usage; checks+=("$2"); shift 2 ;;
    --allow-new-files) allow_new=1; shift ;;
    --keep) keep=1; shift ;;
    *) echo "expect.sh: unknown option '$1' (the command goes after --)" >&2; usage ;;
  esac
done
[ $# -ge 1 ] || usage

if [ -n "$dir" ]; then
  rm -rf -- "$dir" && mkdir -p -- "$dir" && cd -- "$dir" || { echo "expect.sh: cannot make a fresh $dir" >&2; exit 1; }
fi
# The driver's own files live in .expect/, which the listings below leave out.
mkdir -p .expect || exit 1
OUTPUT=$PWD/.expect/output
export OUTPUT

failures=()
fail() { failures+=("$1"); }

listing() { find . -mindepth 1 -path ./.expect -prune -o -print | LC_ALL=C sort; }
quoted_command() { local q="" a; for a in "$@"; do q+="$(printf '%q' "$a") "; done; printf '%s' "${q% }"; }

# Fixtures.
for s in ${setups[@]+"${setups[@]}"}; do
  if ! bash -euo pipefail -c "$s" >.expect/setup 2>&1; then
    echo "FAIL (setup): the fixture script failed, so the command was not run"
    echo "--- setup script:"; echo "$s"
    echo "--- its output:"; cat .expect/setup
    exit 1
  fi
done
listing >.expect/before

# The command.
"$@" </dev/null >"$OUTPUT" 2>&1
status=$?
export STATUS=$status
output=$(cat "$OUTPUT"; printf x)
output=${output%x}

# Exit status.
if [ $status -gt 128 ] && [ $status -lt 160 ]; then
  sig=$((status - 128))
  fail "exit status: expected $want_status, but the command was killed by signal $sig ($(kill -l $sig 2>/dev/null || echo '?')): a crash"
elif [ "$want_status" = nonzero ]; then
  if [ $status -eq 0 ]; then
    fail "exit status: expected a failure (nonzero), got 0"
  elif [ $status -ge 126 ]; then
    fail "exit status: expected a clean failure (1..125), got $status"
  fi
elif [ $status -ne "$want_status" ]; then
  fail "exit status: expected $want_status, got $status"
fi

# Output.
for re in "${matches[@]}"; do
  [[ $output =~ $re ]]
  case $? in
    0) ;;
    1) fail "output: expected a match for the regex  $re" ;;
    *) fail "output: the regex  $re  is not a valid extended regex (a mistake in the test)" ;;
  esac
done
for re in ${nomatches[@]+"${nomatches[@]}"}; do
  [[ $output =~ $re ]]
  case $? in
    0) fail "output: expected NO match for the regex  $re  (it matched '${BASH_REMATCH[0]}')" ;;
    1) ;;
    *) fail "output: the regex  $re  is not a valid extended regex (a mistake in the test)" ;;
  esac
done

# Files.
for p in ${absents[@]+"${absents[@]}"}; do
  if [ -e "$p" ] || [ -L "$p" ]; then fail "file: $p must not exist afterwards, but it does ($(ls -ld -- "$p"))"; fi
done
for p in ${exists[@]+"${exists[@]}"}; do
  if [ ! -e "$p" ]; then
    fail "file: $p must exist afterwards, but it does not"
  elif [ -f "$p" ] && [ ! -s "$p" ]; then
    fail "file: $p must exist afterwards, and it does, but it is empty"
  fi
done
listing >.expect/after
new_files=$(LC_ALL=C comm -13 .expect/before .expect/after)
temps=$(printf '%s\n' "$new_files" | grep -E '\.tmp\.[A-Za-z0-9]{6}$')
[ -n "$temps" ] && fail "file: temporary file(s) of an atomic write left behind: $(echo $temps)"
if [ "$want_status" != 0 ] && [ $allow_new -eq 0 ] && [ -n "$new_files" ]; then
  fail "file: the failing command left new file(s) behind: $(echo $new_files)"
fi

# Follow-up checks.
n=0
for s in ${checks[@]+"${checks[@]}"}; do
  n=$((n + 1))
  if ! bash -euo pipefail -c "$s" >.expect/check$n 2>&1 </dev/null; then
    fail "check: this script failed:
$s
--- its output:
$(cat .expect/check$n)"
  fi
done

if [ ${#failures[@]} -eq 0 ]; then
  echo "ok: $(quoted_command "$@")  (exit status $status)"
  if [ -n "$dir" ] && [ $keep -eq 0 ] && [ "${HC_CLI_KEEP:-0}" != 1 ]; then cd / && rm -rf -- "$dir"; fi
  exit 0
fi
echo "FAIL: $(quoted_command "$@")"
[ -n "$dir" ] && echo "  in: $dir"
for f in "${failures[@]}"; do echo "  - $f"; done
echo "--- expected: exit status $want_status; output matching:"
for re in "${matches[@]}"; do echo "      $re"; done
echo "--- exit status: $status"
lines=$(wc -l <"$OUTPUT")
echo "--- output (stdout + stderr, $lines lines):"
if [ "$lines" -le 200 ]; then cat "$OUTPUT"; else head -n 100 "$OUTPUT"; echo "[... $((lines - 200)) lines ...]"; tail -n 100 "$OUTPUT"; fi
echo "---"
exit 1
