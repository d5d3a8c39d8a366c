#!/usr/bin/env bash
# procam's one entry point for people and CI, on a fresh Debian 12 machine:
#   scripts/run.sh demo [procam demo options]   install what is missing, build (Release), run the demo
#   scripts/run.sh test                          install, build (Release), run the whole test suite
#   scripts/run.sh asan                          install, build with ASan+UBSan, run the tests (CI's set)
#   scripts/run.sh asan-all                      the same, every test
#   scripts/run.sh build                         install and build only
#   scripts/run.sh fuzz [SECONDS]                install, build the libFuzzer targets (clang 14), run
#                                                each over its corpus for SECONDS (20); fails on any crash
# Packages come from scripts/packages.txt; apt-get runs as root or through sudo.
set -euo pipefail
cd "$(dirname "$0")/.."

install_packages() {
  local wanted missing=()
  wanted=$(grep -v '^\s*#' scripts/packages.txt | grep -v '^\s*$')
  for package in $wanted; do
    dpkg-query -W -f='${Status}' "$package" 2>/dev/null | grep -q 'install ok installed' || missing+=("$package")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  echo "procam: installing ${missing[*]}"
  local sudo=""
  if [ "$(id -u)" -ne 0 ]; then
    command -v sudo >/dev/null || { echo "procam: need root or sudo to install: ${missing[*]}" >&2; exit 1; }
    sudo="sudo"
  fi
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
}

build() {
  local preset=$1
  # ccache keys on paths relative to the checkout, so fresh clones (CI) reuse earlier builds.
  export CCACHE_BASEDIR="$PWD" CCACHE_NOHASHDIR=1
  cmake --preset "$preset" >/dev/null
  cmake --build --preset "$preset"
}

command=${1:-}
[ $# -gt 0 ] && shift
case "$command" in
  demo)
    install_packages
    build release
    ./build/release/apps/procam demo "$@"
    ;;
  test)
    install_packages
    build release
    ctest --preset release --parallel 2 "$@"
    ;;
  asan|asan-all)
    install_packages
    build asan
    # `asan` (CI) leaves out, to keep CI short (all run by the test command, and every one under
    # the sanitizers by `asan-all`): apps/faults kills, fills and stalls whole commands,
    # apps/nodes starts, kills and restarts node processes against wall-clock deadlines (process
    # and timing behaviour, not memory); the end-to-end command tests (apps/cli,
    # apps/emulated_room, calibrate_all, the *_command tests, board_scene, capture/cli,
    # projection/multi_monitor, verification/verify, datasets_synthetic/scan_random) run whole
    # pipelines whose code runs under the sanitizers in the unit tests of each library; the
    # slowest numeric tests under ASan's -O1 (geometry/scene_from_points 443 s, calibration/
    # registration 401 s, self_calibration 215 s, board_projector 121 s, rig 109 s,
    # datasets_synthetic/evaluation 159 s, compensation/matrix_free 107 s: 60% of the sanitizer
    # run's time, measured 29 Nov 2026 on this 2-core machine) repeat solves on larger rooms;
    # package/install, layering/* and format/* check files, not code. apps/bad_input (every
    # command on malformed input) stays.
    if [ "$command" = asan ]; then
      ctest --preset asan --parallel 2 \
        -E '^(apps/(faults|nodes|cli|emulated_room)|calibration/(calibrate_all|projectors_command|photometric_command|board_command|board_scene|registration|self_calibration|board_projector|rig)|projection/(project_command|multi_monitor)|capture/cli|verification/verify|geometry/scene_from_points|compensation/matrix_free|datasets_synthetic/(scan_random|evaluation)|package/install|layering/.*|format/.*)$' \
        "$@"
    else
      ctest --preset asan --parallel 2 -E '^(package/install|layering/.*|format/.*)$' "$@"
    fi
    ;;
  build)
    install_packages
    build release
    ;;
  fuzz)
    install_packages
    build fuzz
    scripts/fuzz_campaign.sh --seconds "${1:-20}"
    ;;
  *)
    echo "usage: scripts/run.sh demo|test|asan|asan-all|build|fuzz [args]" >&2
    exit 2
    ;;
esac
