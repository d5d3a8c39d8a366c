#!/bin/bash
# Benchmark: calibrating a projector from board poses on the 1280x800 board rig
# (DefaultBoardRig of datasets_synthetic/board_structured_light.h: a 1280x800 camera, a 1024x768
# projector 0.2 m to its right), the poses given by a scene file's "chessboard" key, captured by
# `procam capture` through the synthetic camera, then `procam calibrate board` timed from start to
# the files written. Prints the wall time of each step.
#
#   scripts/bench_board.sh PROCAM WORK_DIR [POSES]      (POSES: 3..7, default 5)
set -euo pipefail
procam=$(realpath "$1")
work=$2
poses=${3:-5}
mkdir -p "$work"
cd "$work"
rm -rf pose_* rig
python3 - "$poses" <<'EOF'
import json, math, sys
poses = int(sys.argv[1])
def rx(a):
    c, s = math.cos(a), math.sin(a)
    return [[1, 0, 0], [0, c, -s], [0, s, c]]
def ry(a):
    c, s = math.cos(a), math.sin(a)
    return [[c, 0, s], [0, 1, 0], [-s, 0, c]]
def mul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]
def apply(m, v):
    return [sum(m[i][k] * v[k] for k in range(3)) for i in range(3)]
def transpose(m):
    return [[m[j][i] for j in range(3)] for i in range(3)]
def rodrigues(r):
    angle = math.acos(max(-1.0, min(1.0, (r[0][0] + r[1][1] + r[2][2] - 1) / 2)))
    if angle < 1e-12:
        return [0.0, 0.0, 0.0]
    axis = [r[2][1] - r[1][2], r[0][2] - r[2][0], r[1][0] - r[0][1]]
    return [angle * a / (2 * math.sin(angle)) for a in axis]
deg = math.pi / 180
# DefaultBoardRig: the projector's centre (0.2, 0.03, -0.02) m in the camera frame, turned
# Ry(-8 deg) Rx(-12 deg).
cam_from_projector = mul(ry(-8 * deg), rx(-12 * deg))
centre = [0.2, 0.03, -0.02]
projector_from_camera = transpose(cam_from_projector)
t = [-x for x in apply(projector_from_camera, centre)]
def model(intrinsics, size, rt):
    return ("{'lensmodel': 'LENSMODEL_OPENCV4', 'intrinsics': [%s], 'extrinsics': [%s], "
            "'imagersize': [%d, %d]}\n" % (", ".join(repr(x) for x in intrinsics),
                                           ", ".join(repr(x) for x in rt), size[0], size[1]))
open("camera.cameramodel", "w").write(model(
    [1600.0, 1598.0, 641.3, 398.2, -0.08, 0.03, 0.0006, -0.0004], (1280, 800), [0.0] * 6))
open("projector.cameramodel", "w").write(model(
    [1500.0, 1503.0, 509.6, 700.4, 0.02, -0.01, 0.0, 0.0], (1024, 768),
    rodrigues(projector_from_camera) + t))
# BoardRigPoses' placements, centred where the projector's axis meets the plane 1 m ahead.
axis = apply(cam_from_projector, [(511.5 - 509.6) / 1500.0, (383.5 - 700.4) / 1503.0, 1.0])
along = (1.0 - centre[2]) / axis[2]
middle = [centre[i] + along * axis[i] for i in range(3)]
# The third placement (0.12, -0.06, 0.05, 35, -35, -10) is left out: OpenCV does not find the
# board in that white photo, and its failed search alone takes about 40 s at 1280x800.
placements = [(0.00, 0.00, 0.00, 30, 0, 0), (-0.12, -0.06, -0.03, -30, 40, 5),
              (-0.12, 0.06, 0.10, -40, -25, 15),
              (0.12, 0.06, -0.03, 40, 30, -20), (0.00, 0.00, 0.15, 0, -45, 90),
              (0.00, 0.00, -0.10, 45, 10, 30), (0.00, 0.00, 0.05, -25, -40, -30)]
scene = {
    "name": "board_bench", "patches": 20,
    "surfaces": [{"name": "wall", "quad": [[-3, 2, 3], [3, 2, 3], [3, -2, 3], [-3, -2, 3]],
                  "reflectance": 0.5, "desired": [0.5, 0.5, 0.5]}],
    "projectors": [{"name": "front", "model": "projector.cameramodel", "max": 1.0, "gamma": 2.2}],
    "cameras": [{"name": "camera", "model": "camera.cameramodel", "format": "Mono16",
                 "exposure_us": 1000, "reference_exposure_us": 1000, "fps": 500,
                 "ambient": 0.02, "camera_blur": 0.8, "noise": 262.14}],
    "chessboard": {"corners": [11, 8], "square_m": 0.025,
                   "poses": [{"rotation_deg": list(p[3:]),
                              "translation_m": [middle[i] + p[i] for i in range(3)]}
                             for p in placements[:poses]]}}
json.dump(scene, open("board.json", "w"), indent=1)
EOF
sessions=""
start=$(date +%s.%N)
for ((k = 0; k < poses; ++k)); do
  "$procam" capture --camera "synthetic:board.json?board_pose=$k&patches=20&seed=$((20 + k))" \
    --projector 0 --sequence structured_light --pattern-gamma 2.2 --frames 1 --settle-ms 1 \
    --out "pose_$k" > "capture_$k.log"
  sessions="$sessions pose_$k"
done
echo "capture: $poses poses, $(echo "$(date +%s.%N) - $start" | bc) s wall"
start=$(date +%s.%N)
# shellcheck disable=SC2086
/usr/bin/time -f "calibrate board: %e s wall, %U s user, %S s system, %M KiB" \
  "$procam" calibrate board $sessions --corners 11x8 --square 0.025 --name front --out rig \
  2>&1 | while IFS= read -r line; do
    printf '%6.2f s  %s\n' "$(echo "$(date +%s.%N) - $start" | bc)" "$line"
  done > calibrate.log
echo "procam calibrate board, $poses poses (1280x800 camera, 1024x768 projector): $(echo "$(date +%s.%N) - $start" | bc) s wall"
cut -c1-160 calibrate.log
