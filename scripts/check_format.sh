#!/usr/bin/env bash
# Checks that every line of C++ changed since the format base is written as clang-format writes
# it (.clang-format: Google style, 100 columns). Older lines are left as they are: a file is
# formatted a change at a time, never in one commit that would bury its history.
#   scripts/check_format.sh [ROOT] [--fix]
# The base is the commit in ROOT/scripts/format_base. Prints clang-format's diff of the lines
# that differ and exits 1 if any does; --fix rewrites them in place instead. Exits 77 (skipped)
# when ROOT is not a git checkout holding the base commit (a source archive, a shallow clone).
set -euo pipefail
root=${1:-"$(dirname "$0")/.."}
fix=${2:-}
cd "$root"
base_file=scripts/format_base
[ -f "$base_file" ] || { echo "check_format: $root/$base_file: file not found" >&2; exit 2; }
base=$(tr -d '[:space:]' < "$base_file")
git_clang_format=$(command -v git-clang-format-14 || command -v git-clang-format || true)
[ -n "$git_clang_format" ] || { echo "check_format: git-clang-format not found (Debian: clang-format-14)" >&2; exit 2; }
if ! git rev-parse --git-dir >/dev/null 2>&1 || ! git cat-file -e "$base^{commit}" 2>/dev/null; then
  echo "check_format: skipped: $root has no git history holding the format base $base"
  exit 77
fi
binary=$(command -v clang-format-14 || command -v clang-format)
extensions=h,cc,cu,cuh
if [ "$fix" = "--fix" ]; then
  "$git_clang_format" --binary "$binary" --extensions "$extensions" --force "$base"
  exit 0
fi
diff=$("$git_clang_format" --binary "$binary" --extensions "$extensions" --diff "$base" 2>&1)
if grep -q '^diff ' <<<"$diff"; then
  printf '%s\n' "$diff"
  files=$(grep -c '^diff ' <<<"$diff")
  echo "check_format: lines changed since $base in $files file(s) are not as clang-format writes them (fix: scripts/check_format.sh . --fix)" >&2
  exit 1
fi
echo "check_format: every line changed since ${base:0:12} is clang-formatted"
