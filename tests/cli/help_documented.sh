#!/usr/bin/env bash
# help_documented.sh TOOL_BINARY PAGE.md: fails unless the tool's page in docs/tools/ names every option its --help
# prints (as `--name`), so that a newcomer's page and the program cannot drift apart (issue 41).
set -euo pipefail
tool=$1
page=$2
[ -f "$page" ] || { echo "help_documented: $page is missing" >&2; exit 1; }
options=$("$tool" --help | grep -oE '^  --[a-z0-9_][a-z0-9_-]*' | sed 's/^ *//' | sort -u)
[ -n "$options" ] || { echo "help_documented: $tool --help lists no option" >&2; exit 1; }
missing=0
for o in $options; do
  grep -qF -- "\`$o" "$page" || { echo "help_documented: $page does not document $o" >&2; missing=1; }
done
[ $missing -eq 0 ] && echo "help_documented: $page names all $(echo "$options" | wc -l) options of $(basename "$tool")"
exit $missing
