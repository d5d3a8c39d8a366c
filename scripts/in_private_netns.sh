#!/bin/sh
# Runs a command in a private network namespace whose only interface is loopback (127.0.0.1,
# up), so nothing the command binds or sends — GigE Vision control and stream packets, answers
# to discovery — reaches the host's network or another process's sockets.
#
#   scripts/in_private_netns.sh COMMAND [ARGUMENTS...]
#
# `unshare -rn` (util-linux) makes a new user and network namespace, mapping the caller to root
# inside (no privilege needed where unprivileged user namespaces are allowed, as on Debian 12);
# where user namespaces are refused, root with CAP_SYS_ADMIN still gets a network namespace
# (`unshare -n`). `ip` (iproute2) brings loopback up. Where neither works (a container whose
# seccomp profile forbids unshare) it says so in one line and exits 77, which CTest reports as
# a skipped test.
if unshare -rn true 2>/dev/null; then
  exec unshare -rn sh -c 'ip link set lo up && exec "$@"' in_private_netns "$@"
elif unshare -n true 2>/dev/null; then
  exec unshare -n sh -c 'ip link set lo up && exec "$@"' in_private_netns "$@"
fi
echo "in_private_netns: cannot create a network namespace (unshare -rn or -n); not running $1" >&2
exit 77
