#!/usr/bin/env bash
# The scan judged on rooms made at random (docs/scan.md#rooms-made-at-random): for each seed,
# `procam scene random --seed N` writes the room and `procam scene judge-scan` scans it without
# its model and measures it against the file. Prints one row per seed, then the median and the
# worst of each measure, then the seeds that missed an aim (rerun one alone with
# `scripts/scan_random.sh N N`).
#   scripts/scan_random.sh [FIRST_SEED [LAST_SEED]]     (default 1 20)
# dE00 is the photographed compensation's mean CIEDE2000 on the scan minus on the true model, seam
# the seam metric on the scan: both with COMPENSATE=1 only (about a minute more a room).
# Environment: PROCAM_BINARY (default build/release/apps/procam), OUT (default a temporary
# directory, removed at the end; given, the rooms and judgement JSONs are kept there).
set -euo pipefail
first=${1:-1}
last=${2:-20}
compensate=${COMPENSATE:-}
[ "$compensate" = 0 ] && compensate=
procam=${PROCAM_BINARY:-build/release/apps/procam}
if [ -n "${OUT:-}" ]; then
  out=$OUT
  mkdir -p "$out"
else
  out=$(mktemp -d)
  trap 'rm -rf "$out"' EXIT
fi
rows="$out/rows.txt"
: > "$rows"
printf '%-6s %-10s %-8s %-10s %-10s %-9s %-10s %-8s %-6s %-6s %s\n' seed calibrated found planar_mm curved_mm area_% \
  spurious_% dE00 seam time room
for seed in $(seq "$first" "$last"); do
  dir="$out/seed_$seed"
  rm -rf "$dir"
  room=$("$procam" scene random --seed "$seed" --out "$dir" | sed -n 's/^wrote \([^;]*\);.*/\1/p')
  description=$(grep -o '"made at random[^"]*' "$room" | sed 's/.*: random_[0-9]*: //')
  line=$("$procam" scene judge-scan "$room" ${compensate:+--compensate} --json "$dir/judgement.json" |
    tee "$dir/judgement.txt" | grep '^judged ')
  # judged NAME calibrated C found F expected E planar_rms_mm P curved_rms_mm R area_percent A
  # spurious_percent S delta_e2000_model M delta_e2000_scan N seam_scan Q seconds T
  read -r _ _ _ calibrated _ found _ expected _ planar _ curved _ area _ spurious _ model _ scan _ seam _ seconds \
    <<< "$line"
  difference=$(awk -v m="$model" -v s="$scan" 'BEGIN { if (m < 0) print "-"; else printf "%+.2f", s - m }')
  [ "$model" = "-1.00" ] && seam=-
  echo "$seed $calibrated $found $expected $planar $curved $area $spurious $difference $seam $seconds" >> "$rows"
  printf '%-6s %-10s %-8s %-10s %-10s %-9s %-10s %-8s %-6s %-6s %s\n' "$seed" "$calibrated" "$found/$expected" "$planar" \
    "$curved" "$area" "$spurious" "$difference" "$seam" "${seconds}s" "$description"
done
# Median and worst per measure; the seeds that missed an aim (5 mm planar, 1 cm curved, 1% area,
# 1% spurious, every seen-and-lit surface found).
awk '
  function median(values, n,   sorted, i, j) {
    for (i = 1; i <= n; ++i) {  # insertion sort (POSIX awk has no asort)
      for (j = i; j > 1 && sorted[j - 1] > values[i] + 0; --j) sorted[j] = sorted[j - 1]
      sorted[j] = values[i] + 0
    }
    return n % 2 ? sorted[(n + 1) / 2] : (sorted[n / 2] + sorted[n / 2 + 1]) / 2
  }
  function abs(x) { return x < 0 ? -x : x }
  {
    n++; seed[n] = $1; missed[n] = $3 < $4 || $2 == 0
    planar[n] = $5; curved[n] = $6; area[n] = abs($7); spurious[n] = $8; missing[n] = $4 - $3
    if ($5 > 5) why[n] = why[n] " planar " $5 " mm"
    if ($6 > 10) why[n] = why[n] " curved " $6 " mm"
    if (abs($7) > 1) why[n] = why[n] " area " $7 "%"
    if ($8 > 1) why[n] = why[n] " spurious " $8 "%"
    if ($9 != "-") { ncomp++; de[ncomp] = $9; se[ncomp] = $10
      if ($9 > 0.5) why[n] = why[n] " dE00 " $9; if ($10 >= 0.5) why[n] = why[n] " seam " $10 }
    if ($3 < $4) why[n] = why[n] " found " $3 " of " $4
    if ($2 == 0) why[n] = why[n] " not calibrated"
  }
  END {
    if (n == 0) exit 1
    for (i = 1; i <= n; ++i) {
      if (planar[i] > wp) wp = planar[i]; if (curved[i] > wc) wc = curved[i]
      if (area[i] > wa) wa = area[i]; if (spurious[i] > ws) ws = spurious[i]
      if (missing[i] > wm) wm = missing[i]
    }
    printf "\nover %d rooms      median   worst   aim\n", n
    printf "planar RMS, mm   %7.2f %7.2f   5\n", median(planar, n), wp
    printf "curved RMS, mm   %7.2f %7.2f   10 (0: no curved surface seen)\n", median(curved, n), wc
    printf "|area error|, %%  %7.2f %7.2f   1\n", median(area, n), wa
    printf "spurious, %%      %7.2f %7.2f   1\n", median(spurious, n), ws
    printf "surfaces missed  %7d %7d   0\n", median(missing, n), wm
    if (ncomp > 0) {
      wd = de[1]; wsm = se[1]
      for (i = 1; i <= ncomp; ++i) { if (de[i] > wd) wd = de[i]; if (se[i] > wsm) wsm = se[i] }
      printf "dE00 scan-model  %+7.2f %+7.2f   0.5 (%d rooms)\n", median(de, ncomp), wd, ncomp
      printf "seam on the scan %7.2f %7.2f   0.5\n", median(se, ncomp), wsm
    }
    failed = 0
    for (i = 1; i <= n; ++i) if (why[i] != "") { printf "seed %s missed:%s\n", seed[i], why[i]; failed++ }
    printf "%d of %d rooms met every aim\n", n - failed, n
  }' "$rows"
