#!/usr/bin/env bash
# Checks procam's layering: no module includes a module above it.
#   scripts/check_layering.sh [ROOT]     (ROOT: the repository, default: this script's)
# The rules are the ```layers block of ROOT/docs/architecture.md, one line per module:
#   MODULE: MODULES IT MAY INCLUDE ...      ('*' = any module)
# Every #include "DIR/..." in MODULE/ (.h, .cc, .cu, .cuh) must name MODULE itself, a module
# listed for it, or procam/ (the generated config.h). Prints one line per violation
# (file:line: includes DIR/, which MODULE may not include) and exits 1 if there is any.
set -euo pipefail
root=${1:-"$(dirname "$0")/.."}
doc="$root/docs/architecture.md"
[ -f "$doc" ] || { echo "check_layering: $doc: file not found" >&2; exit 2; }

rules=$(awk '/^```layers$/ {inside = 1; next} /^```$/ {inside = 0} inside' "$doc")
[ -n "$rules" ] || { echo "check_layering: $doc: no \`\`\`layers block" >&2; exit 2; }

violations=0
while IFS= read -r rule; do
  [ -z "$rule" ] && continue
  module=${rule%%:*}
  allowed=" ${rule#*:} "
  [[ "$allowed" == *" * "* ]] && continue
  [ -d "$root/$module" ] || { echo "check_layering: $doc: module '$module' has no folder" >&2; exit 2; }
  while IFS=: read -r file line text; do
    target=$(sed -E 's/^[[:space:]]*#[[:space:]]*include[[:space:]]*"([A-Za-z0-9_]+)\/.*/\1/' <<<"$text")
    [ "$target" = "$module" ] || [ "$target" = "procam" ] && continue
    [[ "$allowed" == *" $target "* ]] && continue
    echo "${file#"$root"/}:$line: includes $target/, which $module may not include (docs/architecture.md)"
    violations=$((violations + 1))
  done < <(grep -rnE '^[[:space:]]*#[[:space:]]*include[[:space:]]*"[A-Za-z0-9_]+/' \
             --include='*.h' --include='*.cc' --include='*.cu' --include='*.cuh' "$root/$module" || true)
done <<<"$rules"

if [ "$violations" -gt 0 ]; then
  echo "check_layering: $violations include(s) against the layering" >&2
  exit 1
fi
echo "check_layering: every module includes only modules below it"
