#!/usr/bin/env bash
# Runs a command on an X server with several monitors that can be unplugged, for trying what
# procam does when a projector's cable comes out (and for its tests):
#
#   scripts/dummy_monitors.sh [--mode WxH] [--timeout SECONDS] N -- COMMAND [ARGS...]
#
# starts Xorg with the dummy video driver (no hardware) on a free display and N outputs
# DUMMY0..N-1, each at WxH (default 640x480), side by side from left to right (DUMMYk at
# x = k·W, y = 0). COMMAND runs in the caller's environment with DISPLAY set; inside it
#
#   xrandr --output DUMMYk --off
#
# takes output k's monitor away as an unplugged cable does: the X server drops it from its
# monitors and tells every client (a RandR screen change), which is how GLFW, and so procam, learn
# that a monitor is gone. The script exits with COMMAND's exit status (124 when it ran past
# --timeout, default 60 s) and leaves no process behind.
#
# Xorg takes a configuration file from an absolute path only when run as root, so this needs root
# (or sudo without a password). Unlike scripts/multi_monitor.sh (sway), nothing here can capture
# what an output shows.
set -euo pipefail

usage() {
  echo "usage: scripts/dummy_monitors.sh [--mode WxH] [--timeout SECONDS] N -- COMMAND [ARGS...]" >&2
  exit 2
}
fail() {
  echo "dummy_monitors: $*" >&2
  exit 1
}

mode=640x480
timeout_seconds=60
while [ $# -gt 0 ]; do
  case "$1" in
    --mode) mode=${2:-}; shift 2 || usage ;;
    --timeout) timeout_seconds=${2:-}; shift 2 || usage ;;
    --) shift; break ;;
    -*) usage ;;
    *) [ -n "${outputs:-}" ] && usage; outputs=$1; shift ;;
  esac
done
[ -n "${outputs:-}" ] && [ $# -gt 0 ] || usage
[[ "$outputs" =~ ^[1-9]$|^1[0-6]$ ]] || fail "N must be 1 to 16 (the dummy driver's outputs), not '$outputs'"
[[ "$mode" =~ ^([1-9][0-9]*)x([1-9][0-9]*)$ ]] || fail "--mode must be WxH, not '$mode'"
width=${BASH_REMATCH[1]}
height=${BASH_REMATCH[2]}
[[ "$timeout_seconds" =~ ^[0-9]+([.][0-9]+)?$ ]] || fail "--timeout must be seconds, not '$timeout_seconds'"
for program in Xorg xrandr cvt; do
  command -v $program >/dev/null ||
    fail "$program is not installed (apt-get install xserver-xorg-core xserver-xorg-video-dummy x11-xserver-utils)"
done
[ -e /usr/lib/xorg/modules/drivers/dummy_drv.so ] ||
  fail "the dummy video driver is not installed (apt-get install xserver-xorg-video-dummy)"
as_root=()
if [ "$(id -u)" -ne 0 ]; then
  sudo -n true 2>/dev/null || fail "Xorg with a configuration file needs root (or sudo without a password)"
  as_root=(sudo -n)
fi

# A free display number: no socket and no lock file.
display=""
for n in $(seq 120 199); do
  if [ ! -e "/tmp/.X11-unix/X$n" ] && [ ! -e "/tmp/.X$n-lock" ]; then display=$n; break; fi
done
[ -n "$display" ] || fail "no free X display between :120 and :199"

dir=$(mktemp -d /tmp/procam-dummy.XXXXXX)
xorg_pid=""
cleanup() {
  if [ -n "$xorg_pid" ]; then
    "${as_root[@]}" kill "$xorg_pid" 2>/dev/null || true
    for _ in $(seq 50); do kill -0 "$xorg_pid" 2>/dev/null || break; sleep 0.1; done
    "${as_root[@]}" kill -9 "$xorg_pid" 2>/dev/null || true
  fi
  rm -rf "$dir"
}
trap cleanup EXIT

# The dummy driver's frame buffer holds the N outputs side by side, and at least 1024x768 for the
# mode it starts its first output with (4 bytes a pixel, in KiB).
virtual_width=$(( outputs * width > 1024 ? outputs * width : 1024 ))
virtual_height=$(( height > 768 ? height : 768 ))
video_ram=$(( (virtual_width * virtual_height * 4) / 1024 + 4096 ))
cat > "$dir/xorg.conf" <<EOF
Section "Device"
  Identifier "dummy"
  Driver "dummy"
  VideoRam $video_ram
EndSection
Section "Monitor"
  Identifier "monitor"
  HorizSync 1.0-1000.0
  VertRefresh 1.0-200.0
EndSection
Section "Screen"
  Identifier "screen"
  Device "dummy"
  Monitor "monitor"
  DefaultDepth 24
  SubSection "Display"
    Depth 24
    Virtual $virtual_width $virtual_height
  EndSubSection
EndSection
EOF
mkdir "$dir/conf.d"
"${as_root[@]}" Xorg ":$display" -config "$dir/xorg.conf" -configdir "$dir/conf.d" -noreset \
  -nolisten tcp -logfile "$dir/xorg.log" >"$dir/xorg.out" 2>&1 &
xorg_pid=$!
export DISPLAY=":$display"
for _ in $(seq 100); do
  xrandr >/dev/null 2>&1 && break
  kill -0 "$xorg_pid" 2>/dev/null || fail "Xorg stopped: $(grep -E '^\[.*\(EE\)' "$dir/xorg.log" | tail -3 | tr '\n' ' ')"
  sleep 0.1
done
xrandr >/dev/null 2>&1 || fail "Xorg did not answer on :$display in 10 s"

# Every output at WxH (a CVT mode), side by side; the first is the one the driver starts with.
modeline=$(cvt "$width" "$height" 60 | sed -n 's/^Modeline "[^"]*" *//p')
[ -n "$modeline" ] || fail "cvt gave no mode for ${width}x${height}"
# shellcheck disable=SC2086  # the modeline's numbers and flags are separate arguments
xrandr --newmode "procam${width}x${height}" $modeline
for k in $(seq 0 $((outputs - 1))); do
  xrandr --addmode "DUMMY$k" "procam${width}x${height}"
  xrandr --output "DUMMY$k" --mode "procam${width}x${height}" --pos "$((k * width))x0"
done
monitors=$(xrandr --listmonitors | sed -n 's/^Monitors: //p')
[ "$monitors" = "$outputs" ] || fail "Xorg shows $monitors monitor(s), not $outputs"

status=0
timeout "$timeout_seconds" "$@" || status=$?
exit "$status"
