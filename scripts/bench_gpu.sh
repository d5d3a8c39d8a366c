#!/usr/bin/env bash
# GPU benchmark and checks of the solver, in one call on a machine with a CUDA device:
#   scripts/bench_gpu.sh BINARY_DIR OUTPUT.md [COMMIT]
# BINARY_DIR holds compensation_solver_cuda_device_test and compensation_compressed_cuda_device_test
# (tests/compensation/*_device_test.cc: built from the solver's sources with only the CUDA
# libraries and libgomp, so they run where Embree/OpenCV are missing; put libgomp.so.1 beside
# them). It runs every GPU-vs-CPU check of both, then their DISABLED_Timings, and writes the
# device, date, commit and the markdown tables to OUTPUT.md (for docs/gpu.md; the product timings
# of the dense K⁻¹ with them):
#   dense analytic plates: PROCAM_BENCH_GRIDS (g×g patches per plate, n = 2g²; default 22,70:
#     2904 and 29 400 variables), CPU rows up to PROCAM_BENCH_CPU_MAX_VARIABLES (10 000);
#   compressed plates: PROCAM_BENCH_COMPRESSED_GRIDS (default 40,120,224: 9600, 86 400 and
#     301 056 variables), CPU rows up to 30 000 variables.
# Real rooms: problem directories under BINARY_DIR/problems (written here by `procam compensate
# ROOM --export --out BINARY_DIR/problems/NAME`: F from Embree, projector bounds; and by
# `PROCAM_EXPORT_TEST_PROBLEMS=BINARY_DIR/problems compensation_solver_cuda_test
# --gtest_filter='*Exports*'`: that test's rooms) are solved on the GPU against the CPU as well
# (SolveCudaExported), one table row per room, method and solver.
set -euo pipefail
dir=$1
output=$2
commit=${3:-$(git rev-parse --short HEAD 2>/dev/null || echo unknown)}
export LD_LIBRARY_PATH="$dir${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
if [[ -d "$dir/problems" ]]; then export PROCAM_DEVICE_PROBLEMS="$dir/problems"; fi
export PROCAM_BENCH_GRIDS=${PROCAM_BENCH_GRIDS:-22,70}
export PROCAM_BENCH_REPEATS=${PROCAM_BENCH_REPEATS:-3}
export PROCAM_BENCH_COMPRESSED_GRIDS=${PROCAM_BENCH_COMPRESSED_GRIDS:-40,120,224}
dense="$dir/compensation_solver_cuda_device_test"
compressed="$dir/compensation_compressed_cuda_device_test"
device=$(nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader 2>/dev/null || echo "no nvidia-smi")
cpu=$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ //')

checks=$("$dense" 2>&1) || { echo "$checks"; exit 1; }
echo "$checks"
# The fused loop's fallback where its grid does not fit (SolverOptions::device_fused_blocks past
# what the device holds) ran among the checks.
echo "$checks" | grep -q '^\[       OK \] SolveCudaAnalytic.FusedLoopFallsBackWhereItsGridDoesNotFit' ||
  { echo "the fallback test did not run"; exit 1; }
compressed_checks=$("$compressed" 2>&1) || { echo "$compressed_checks"; exit 1; }
echo "$compressed_checks"
timings=$(PROCAM_BENCH_CPU_MAX_VARIABLES=${PROCAM_BENCH_CPU_MAX_VARIABLES:-10000} \
  "$dense" --gtest_also_run_disabled_tests --gtest_filter='*.DISABLED_Timings' 2>&1)
echo "$timings"
products=$("$dense" --gtest_also_run_disabled_tests --gtest_filter='*.DISABLED_ProductTimings' 2>&1)
echo "$products"
compressed_timings=$(PROCAM_BENCH_CPU_MAX_VARIABLES=30000 \
  "$compressed" --gtest_also_run_disabled_tests --gtest_filter='*Timings' 2>&1)
echo "$compressed_timings"
{
  echo "Measured $(date -u +%Y-%m-%d) at commit $commit on $device (host CPU: $cpu, $(nproc) cores),"
  echo "\`scripts/bench_gpu.sh\`: analytic facing plates (bounds [0, 1], alpha 0.5, rho 0.9); GPU rows"
  echo "median of $PROCAM_BENCH_REPEATS. Dense F (\`solver_cuda_device_test\`):"
  echo
  echo "$timings" | grep '^|'
  echo
  echo "Products with the dense K⁻¹, three columns, µs (median of 200; \`DISABLED_ProductTimings\`):"
  echo
  echo "$products" | grep '^|'
  echo
  echo "Compressed F (\`compressed_cuda_device_test\`):"
  echo
  echo "$compressed_timings" | grep '^|'
  echo
  echo "GPU-vs-CPU checks of the same run: $(echo "$checks" | grep -c '^\[       OK') + $(echo "$compressed_checks" | grep -c '^\[       OK') tests passed."
  echo
  echo "Real rooms exported here (\`procam compensate ROOM --export\`: F from Embree, projector bounds;"
  echo "test_*: solver_cuda_test's rooms; GPU rows median of 3):"
  echo
  echo "$checks" | grep '^|' || echo "(none: no BINARY_DIR/problems)"
} > "$output"
echo "wrote $output"
