#!/usr/bin/env bash
# The house rules a machine can check (CONTRIBUTING.md), run first by CI in seconds:
#  1. doors: no target includes another folder's src/ or compiles its sources (no quoted include through src/ or up
#     out of its own folder, no CMake include directory in another folder's src/, no source file of another folder);
#  2. rooms: no C++ source file over 1000 lines (the aim is ~600; a file past it is split along its seams);
#  3. format: every C++ file is as clang-format-14 writes it (.clang-format; bash scripts/format.sh fixes it);
#  4. commits: every subject since the commit-msg hook came (scripts/hooks/commit-msg) is at most 72 characters.
set -euo pipefail
cd "$(dirname "$0")/.."
status=0
fail() { echo "check_tree: $*" >&2; status=1; }
sources=$(git ls-files '*.cpp' '*.h' '*.comp' '*.glsl' | grep -v '^fuzz/corpus/')

# 1. Doors. A quoted include resolves against the including file's folder or its target's own include paths.
while IFS= read -r file; do
  top=${file%%/*}
  while IFS= read -r inc; do
    case "$inc" in
      *src/*) fail "$file includes \"$inc\": another folder's src/ (use its public header in include/heightcast/)";;
      ../*) resolved=$(realpath -m --relative-to=. "$(dirname "$file")/$inc")
            [ "${resolved%%/*}" = "$top" ] || fail "$file includes \"$inc\", outside its folder $top/";;
    esac
  done < <(sed -n 's/^[[:space:]]*#[[:space:]]*include[[:space:]]*"\([^"]*\)".*/\1/p' "$file")
done <<< "$sources"
while IFS= read -r cm; do
  grep -nE '(PROJECT_SOURCE_DIR|CMAKE_SOURCE_DIR)\}/([A-Za-z_/]*/src\b|[^ )]*\.(cpp|cc|c)\b)|\.\./([A-Za-z_]+/)*src\b' "$cm" | grep -v '^[0-9]*:[[:space:]]*#' |
    while IFS= read -r line; do echo "check_tree: $cm:$line: reaches into another folder's src/" >&2; echo x; done |
    grep -q x && status=1
done < <(git ls-files '*CMakeLists.txt' 'cmake/*.cmake')

# 2. Rooms.
while IFS= read -r file; do
  n=$(wc -l < "$file")
  [ "$n" -le 1000 ] || fail "$file has $n lines (at most 1000; split it along its seams)"
done <<< "$sources"

# 3. Format (C++ only; the GLSL keeps its own layout).
fmt=$(command -v clang-format-14 || command -v clang-format || true)
if [ -z "$fmt" ]; then
  fail "clang-format-14 is not installed (bash scripts/deps.sh clang)"
else
  unformatted=$(git ls-files '*.cpp' '*.h' | grep -v '^fuzz/corpus/' |
                while IFS= read -r f; do "$fmt" --dry-run -Werror "$f" >/dev/null 2>&1 || echo "$f"; done)
  [ -z "$unformatted" ] || fail "not formatted (bash scripts/format.sh): $(echo $unformatted)"
fi

# 4. Commit subjects since the hook's own commit (a shallow clone without it skips the check, saying so).
base=$(git log --format=%H --diff-filter=A -- scripts/hooks/commit-msg | tail -n 1)
if [ -n "$base" ] && git cat-file -e "$base^{commit}" 2>/dev/null; then
  while IFS= read -r s; do
    [ ${#s} -le 72 ] || fail "commit subject of ${#s} characters (at most 72): $s"
  done < <(git log --format=%s "$base~1..HEAD" 2>/dev/null || git log --format=%s "$base..HEAD")
else
  echo "check_tree: commit subjects not checked (no history of scripts/hooks/commit-msg in this clone)"
fi
[ $status -eq 0 ] && echo "check_tree: doors, rooms, format and commit subjects as CONTRIBUTING.md says"
exit $status
