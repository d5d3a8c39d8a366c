#!/usr/bin/env bash
# The layering check catches what it must: a tree whose rules forbid an include it holds fails,
# naming the file, the line and the module; the same tree without it passes; a missing rules
# block is an error of its own.
set -uo pipefail
script="$1/scripts/check_layering.sh"
tree=$(mktemp -d)
trap 'rm -rf "$tree"' EXIT
mkdir -p "$tree/docs" "$tree/base" "$tree/geometry" "$tree/apps"
cat > "$tree/docs/architecture.md" <<'DOC'
# Architecture
```layers
base:
geometry: base
apps: *
```
DOC
printf '#include "base/io.h"\n#include "geometry/scene.h"\n' > "$tree/geometry/scene.cc"
printf '#include "geometry/scene.h"\n#include "base/io.h"\n' > "$tree/apps/procam.cc"
printf '#pragma once\n#include <vector>\n' > "$tree/base/io.h"
fail() { echo "FAIL: $*"; exit 1; }

output=$(bash "$script" "$tree" 2>&1) || fail "a clean tree was rejected: $output"

printf '#pragma once\n\n#include "geometry/scene.h"\n' > "$tree/base/io.h"
output=$(bash "$script" "$tree" 2>&1)
status=$?
[ "$status" -eq 1 ] || fail "an upward include passed (exit $status): $output"
grep -q '^base/io.h:3: includes geometry/, which base may not include' <<<"$output" ||
  fail "the violation is not named: $output"

sed -i '/```layers/,/```$/d' "$tree/docs/architecture.md"
output=$(bash "$script" "$tree" 2>&1)
status=$?
[ "$status" -eq 2 ] || fail "no rules block gave exit $status: $output"
echo "check_layering: catches an upward include, passes a clean tree, needs its rules"
