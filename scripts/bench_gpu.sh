#!/usr/bin/env bash
# GPU benchmark of the solver (issue 9), in one call on a machine with a CUDA device:
#   scripts/bench_gpu.sh TEST_BINARY OUTPUT.md [COMMIT]
# TEST_BINARY is compensation_solver_cuda_device_test (tests/compensation/solver_cuda_device_test.cc:
# it links only procam_compensation, so it runs where Embree/OpenCV are missing). It first runs
# the GPU-vs-CPU checks, then DISABLED_Timings, and writes a markdown table (device, date,
# commit, rows of CPU and GPU solves at about 3000 / 10000 / 30000 variables, the paper's
# figures beside them) to OUTPUT.md, for docs/gpu.md. Sizes: PROCAM_BENCH_GRIDS (plates of g×g
# patches each, n = 2g²), CPU rows up to PROCAM_BENCH_CPU_MAX_VARIABLES.
set -euo pipefail
binary=$1
output=$2
commit=${3:-$(git rev-parse --short HEAD 2>/dev/null || echo unknown)}
export PROCAM_BENCH_GRIDS=${PROCAM_BENCH_GRIDS:-22,40,70}
export PROCAM_BENCH_CPU_MAX_VARIABLES=${PROCAM_BENCH_CPU_MAX_VARIABLES:-10000}
device=$(nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader 2>/dev/null || echo "no nvidia-smi")
cpu=$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ //')
checks=$("$binary" --gtest_filter='SolveCudaAnalytic.MatchesTheCpuReference:-*DISABLED*' 2>&1) || { echo "$checks"; exit 1; }
echo "$checks"
timings=$("$binary" --gtest_also_run_disabled_tests --gtest_filter='*Timings' 2>&1)
echo "$timings"
{
  echo "Measured $(date -u +%Y-%m-%d) at commit $commit on $device (host CPU: $cpu, $(nproc) cores);"
  echo "\`scripts/bench_gpu.sh\`: analytic facing-plates rooms (tests/compensation/analytic_problem.h),"
  echo "bounds [0, 1], alpha 0.5, rho 0.9. Setup = CPU Cholesky of K, or K⁻¹ formed on the GPU; solve ="
  echo "everything after it (GPU rows: median of ${PROCAM_BENCH_REPEATS:-5}); objective evaluated in double."
  echo
  echo "$timings" | grep '^|'
  echo
  echo "GPU-vs-CPU checks of the same run:"
  echo
  echo '```'
  echo "$checks" | grep -E 'objective .* relative' || true
  echo '```'
} > "$output"
echo "wrote $output"
