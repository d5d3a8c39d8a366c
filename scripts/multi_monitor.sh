#!/usr/bin/env bash
# Runs a command on a headless display server with several monitors, for trying procam's
# projector output without projectors (and for its tests):
#
#   scripts/multi_monitor.sh [--mode WxH] [--timeout SECONDS] [--user USER] N -- COMMAND [ARGS...]
#
# starts sway with its headless backend and N outputs HEADLESS-1..N, each at WxH (default
# 640x480), side by side from left to right (HEADLESS-k at x = (k-1)·W, y = 0), with Xwayland,
# so that X11 clients such as procam see N monitors XWAYLAND0..N-1 at the same places. COMMAND
# runs in the caller's environment with DISPLAY, WAYLAND_DISPLAY, SWAYSOCK, XDG_RUNTIME_DIR and
# HOME set; `grim -o HEADLESS-k FILE.png` inside it captures what output k shows, and swaymsg
# talks to sway. The script exits with COMMAND's exit status (124 when it ran past --timeout,
# default 60 s) and leaves no process behind.
#
# sway refuses to run as root: as root, sway and COMMAND run as USER (default nobody), who must
# be able to read and run what COMMAND names and to write where it writes.
set -euo pipefail

usage() {
  echo "usage: scripts/multi_monitor.sh [--mode WxH] [--timeout SECONDS] [--user USER] N -- COMMAND [ARGS...]" >&2
  exit 2
}
fail() {
  echo "multi_monitor: $*" >&2
  exit 1
}

mode=640x480
timeout_seconds=60
user=nobody
while [ $# -gt 0 ]; do
  case "$1" in
    --mode) mode=${2:-}; shift 2 || usage ;;
    --timeout) timeout_seconds=${2:-}; shift 2 || usage ;;
    --user) user=${2:-}; shift 2 || usage ;;
    --) shift; break ;;
    -*) usage ;;
    *) [ -n "${outputs:-}" ] && usage; outputs=$1; shift ;;
  esac
done
[ -n "${outputs:-}" ] && [ $# -gt 0 ] || usage
[[ "$outputs" =~ ^[1-9][0-9]?$ ]] || fail "N must be 1 to 99, not '$outputs'"
[[ "$mode" =~ ^([1-9][0-9]*)x([1-9][0-9]*)$ ]] || fail "--mode must be WxH, not '$mode'"
width=${BASH_REMATCH[1]}
height=${BASH_REMATCH[2]}
[[ "$timeout_seconds" =~ ^[0-9]+([.][0-9]+)?$ ]] || fail "--timeout must be seconds, not '$timeout_seconds'"
command -v sway >/dev/null || fail "sway is not installed (apt-get install sway xwayland)"
command -v Xwayland >/dev/null || fail "Xwayland is not installed (apt-get install xwayland)"

# As root, everything below runs as `user` (sway refuses root); otherwise as the caller.
as_user=()
if [ "$(id -u)" -eq 0 ]; then
  id "$user" >/dev/null 2>&1 || fail "no user '$user' to run sway as (--user)"
  as_user=(setpriv "--reuid=$(id -u "$user")" "--regid=$(id -g "$user")" --clear-groups)
fi

# A private directory for the server's sockets, config and caches, owned by that user.
dir=$(mktemp -d /tmp/procam-monitors.XXXXXX)
sway_pid=""
cleanup() {
  [ -z "${command_pid:-}" ] || kill -KILL -- "-$command_pid" 2>/dev/null || true
  if [ -n "$sway_pid" ]; then
    # sway stops Xwayland and itself on SIGTERM (10–120 ms here): give it 1 s, then end sway,
    # Xwayland and whatever sway started together (they share sway's process group, setsid
    # below), and remove the X display's lock and socket left if it had to be killed.
    kill -TERM "$sway_pid" 2>/dev/null || true
    for _ in $(seq 10); do
      kill -0 "$sway_pid" 2>/dev/null || break
      sleep 0.1
    done
    kill -KILL -- "-$sway_pid" 2>/dev/null || true
    wait 2>/dev/null || true
    if [ -n "${display:-}" ]; then
      lock="/tmp/.X${display#:}-lock"
      owner=$( { tr -dc 0-9 <"$lock"; } 2>/dev/null || true)
      if [ -n "$owner" ] && ! kill -0 "$owner" 2>/dev/null; then
        rm -f "$lock" "/tmp/.X11-unix/X${display#:}"
      fi
    fi
  fi
  rm -rf "$dir"
}
trap cleanup EXIT
trap 'exit 130' INT TERM
mkdir -p "$dir/runtime" "$dir/home"
chmod 700 "$dir" "$dir/runtime"
[ ${#as_user[@]} -gt 0 ] && chown -R "$user:$(id -gn "$user")" "$dir"

{
  echo "# Written by scripts/multi_monitor.sh"
  echo "xwayland force"  # start Xwayland now (not on the first X11 client), so DISPLAY is up
  for k in $(seq "$outputs"); do
    # Black where nothing is shown, as an idle projector should be (sway's default is grey).
    echo "output HEADLESS-$k mode ${width}x${height} position $(((k - 1) * width)) 0 bg #000000 solid_color"
  done
  # Tell the script the sockets, once sway and Xwayland are up.
  echo "exec printf '%s %s\\n' \"\$WAYLAND_DISPLAY\" \"\$DISPLAY\" > $dir/sockets.tmp && mv $dir/sockets.tmp $dir/sockets"
} >"$dir/config"

# sway leads a session and process group of its own (setsid may fork first: the pid comes from
# the process that becomes sway), so that it, Xwayland and what sway starts end together.
setsid sh -c 'echo $$ >"$0/sway.pid" && exec "$@"' "$dir" \
  env -i PATH="$PATH" HOME="$dir/home" XDG_RUNTIME_DIR="$dir/runtime" \
  XDG_CACHE_HOME="$dir/home" WLR_BACKENDS=headless WLR_HEADLESS_OUTPUTS="$outputs" \
  WLR_RENDERER=pixman WLR_LIBINPUT_NO_DEVICES=1 \
  "${as_user[@]}" sway --config "$dir/config" >"$dir/sway.log" 2>&1 &
for _ in $(seq 50); do
  [ -s "$dir/sway.pid" ] && break
  sleep 0.02
done
sway_pid=$(cat "$dir/sway.pid" 2>/dev/null || true)
[ -n "$sway_pid" ] || fail "sway did not start"

# Wait (at most 10 s) for sway's exec and for Xwayland's socket.
for _ in $(seq 100); do
  if [ -s "$dir/sockets" ]; then
    read -r wayland_display display <"$dir/sockets"
    [ -S "/tmp/.X11-unix/X${display#:}" ] && break
  fi
  kill -0 "$sway_pid" 2>/dev/null || { tail -5 "$dir/sway.log" >&2; fail "sway exited at start"; }
  sleep 0.1
done
[ -n "${display:-}" ] && [ -S "/tmp/.X11-unix/X${display#:}" ] ||
  { tail -5 "$dir/sway.log" >&2; fail "sway or Xwayland did not come up within 10 s"; }

# sway's IPC socket, for swaymsg inside COMMAND.
swaysock=""
for socket in "$dir"/runtime/sway-ipc.*.sock; do [ -S "$socket" ] && swaysock=$socket; done

# timeout puts itself and COMMAND in a process group of their own: whatever COMMAND leaves
# running is ended with it.
env HOME="$dir/home" XDG_RUNTIME_DIR="$dir/runtime" XDG_CACHE_HOME="$dir/home" \
  WAYLAND_DISPLAY="$wayland_display" DISPLAY="$display" SWAYSOCK="$swaysock" \
  timeout --kill-after=5 "$timeout_seconds" "${as_user[@]}" "$@" &
command_pid=$!
status=0
wait "$command_pid" || status=$?
kill -KILL -- "-$command_pid" 2>/dev/null || true
exit "$status"
