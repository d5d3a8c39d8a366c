#!/usr/bin/env bash
# docs/options.md holds the option tables exactly as `procam options --markdown` writes them from
# the declarations (between its "generated" markers), so the docs cannot drift from the code.
#   options_doc_test.sh PROCAM_BINARY SOURCE_DIR
set -uo pipefail
procam=$1
doc="$2/docs/options.md"
begin='<!-- begin: procam options --markdown -->'
end='<!-- end: procam options --markdown -->'
[ -f "$doc" ] || { echo "FAIL: $doc: file not found"; exit 1; }
expected=$("$procam" options --markdown) || { echo "FAIL: procam options --markdown failed"; exit 1; }
[ -n "$expected" ] || { echo "FAIL: procam options --markdown wrote nothing"; exit 1; }
documented=$(awk -v b="$begin" -v e="$end" '$0 == e {inside = 0} inside {print} $0 == b {inside = 1}' "$doc")
if [ "$documented" != "$expected" ]; then
  diff <(printf '%s\n' "$documented") <(printf '%s\n' "$expected")
  echo "FAIL: $doc differs from the declarations (rewrite the block between its markers with: procam options --markdown)"
  exit 1
fi
echo "options_doc: docs/options.md matches the declared option tables"
