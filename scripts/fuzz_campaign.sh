#!/usr/bin/env bash
# Runs every libFuzzer target of build/fuzz (preset `fuzz`) over its seed corpus, fuzz/corpus/NAME,
# and writes a markdown table of what each did (docs/faults.md#fuzzing):
#   scripts/fuzz_campaign.sh [EXECUTIONS]        the long campaign: EXECUTIONS runs per target (10^6)
#   scripts/fuzz_campaign.sh --seconds SECONDS   CI: SECONDS per target
# Options: --table FILE (default build/fuzz/campaign.md), --only NAME (one target).
# New inputs go to build/fuzz/corpus/NAME (the seeds in the repository are not changed); a crash,
# hang (-timeout=10 s per input), leak, memory blow-up (-rss_limit_mb=2048) or sanitizer report
# leaves its input in build/fuzz/artifacts/ and makes the script exit 1. -close_fd_mask=2: procam's
# own stderr is dropped, and libFuzzer and the sanitizers report on a copy of it, so that a report
# made while a reader silences stderr (SilencedStderr, around decoders) still reaches the log.
set -euo pipefail
cd "$(dirname "$0")/.."

budget="-runs=1000000"
budget_text="10^6 runs"
table=build/fuzz/campaign.md
only=""
while [ $# -gt 0 ]; do
  case "$1" in
    --seconds) budget="-max_total_time=$2"; budget_text="$2 s"; shift 2 ;;
    --table) table=$2; shift 2 ;;
    --only) only=$2; shift 2 ;;
    *) budget="-runs=$1"; budget_text="$1 runs"; shift ;;
  esac
done

# fuzz_one NAME: runs build/fuzz/fuzz/fuzz_NAME; prints the table's row; returns its exit status.
# Seeds: fuzz/corpus/NAME and the inputs of earlier findings, fuzz/regressions/NAME.
fuzz_one() {
  local name=$1 log=build/fuzz/logs/$1.log status=0 seeds=("fuzz/corpus/$1")
  [ -d "fuzz/regressions/$name" ] && seeds+=("fuzz/regressions/$name")
  mkdir -p "build/fuzz/corpus/$name" build/fuzz/artifacts build/fuzz/logs
  "build/fuzz/fuzz/fuzz_$name" "$budget" -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 -close_fd_mask=2 \
    -artifact_prefix="build/fuzz/artifacts/$name-" "build/fuzz/corpus/$name" "${seeds[@]}" \
    >"$log" 2>&1 || status=$?
  local runs cov ft corpus seconds verdict=ok
  runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  seconds=$(sed -n 's/.*Done [0-9]* runs in \([0-9]*\) second.*/\1/p' "$log" | tail -1)
  cov=$(grep -o 'cov: [0-9]*' "$log" | tail -1 | cut -d" " -f2 || true)
  ft=$(grep -o 'ft: [0-9]*' "$log" | tail -1 | cut -d" " -f2 || true)
  corpus=$(grep -o 'corp: [0-9]*' "$log" | tail -1 | cut -d" " -f2 || true)
  [ "$status" -eq 0 ] || verdict="**FAILED** (build/fuzz/logs/$name.log)"
  echo "| $name | ${runs:-?} | ${seconds:-?} | ${cov:-?} | ${ft:-?} | ${corpus:-?} | $verdict |"
  return "$status"
}

failed=0
{
  echo "Budget per target: $budget_text. libFuzzer's final stats (clang 14, ASan+UBSan); $(date -u +%F)."
  echo
  echo "| target | executions | seconds | cov (edges) | ft (features) | corpus | result |"
  echo "|---|---|---|---|---|---|---|"
} >"$table"
for binary in build/fuzz/fuzz/fuzz_*; do
  name=${binary##*/fuzz_}
  [ -z "$only" ] || [ "$only" = "$name" ] || continue
  fuzz_one "$name" | tee -a "$table" || failed=1
done
echo "procam: fuzz table in $table"
if [ "$failed" -ne 0 ]; then
  echo "procam: error: a fuzz target failed; its input is in build/fuzz/artifacts/" >&2
  exit 1
fi
