#!/usr/bin/env bash
# The format check catches what it must: in a made-up repository, a line changed after the base
# and written against .clang-format fails, naming the file; the same change formatted passes, as
# do older unformatted lines; --fix formats only the changed lines; a tree without the base
# commit is skipped (77), never passed.
set -uo pipefail
script="$1/scripts/check_format.sh"
tree=$(mktemp -d)
trap 'rm -rf "$tree"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
cd "$tree"
git init -q . && git config user.email t@t && git config user.name t
cp "$1/.clang-format" .
mkdir scripts
printf 'int old(int a){return a;}\n' > a.cc
git add . && git commit -qm base
git rev-parse HEAD > scripts/format_base

output=$(bash "$script" "$tree" 2>&1) || fail "an untouched tree was rejected: $output"

printf 'int old(int a){return a;}\nint added(int b){return b;}\n' > a.cc
output=$(bash "$script" "$tree" 2>&1)
status=$?
[ "$status" -eq 1 ] || fail "an unformatted new line passed (exit $status): $output"
grep -q '^+int added(int b) { return b; }' <<<"$output" || fail "the fix is not shown: $output"
grep -q 'not as clang-format writes them' <<<"$output" || fail "no verdict line: $output"

bash "$script" "$tree" --fix >/dev/null 2>&1 || fail "--fix failed"
[ "$(cat a.cc)" = "$(printf 'int old(int a){return a;}\nint added(int b) { return b; }')" ] ||
  fail "--fix did not format only the changed line: $(cat a.cc)"
output=$(bash "$script" "$tree" 2>&1) || fail "the formatted change was rejected: $output"

echo 0000000000000000000000000000000000000000 > scripts/format_base
output=$(bash "$script" "$tree" 2>&1)
status=$?
[ "$status" -eq 77 ] || fail "a missing base gave exit $status: $output"
echo "check_format: catches an unformatted change, passes a formatted one and old lines, skips without history"
