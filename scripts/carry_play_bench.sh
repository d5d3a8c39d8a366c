#!/usr/bin/env bash
# Packs tools/procam-play-bench with the shared libraries it needs that a bare GPU machine lacks
# (everything ldd lists but the C/C++ runtime and the CUDA libraries, plus the GL vendor-neutral
# dispatch libraries libepoxy opens at run time), for `procam bench play --render gpu` measured on
# a machine without procam's Debian packages:
#   scripts/carry_play_bench.sh BUILD_DIR OUT.tar.xz
# On the GPU machine: tar xf OUT.tar.xz; LD_LIBRARY_PATH=playcarry/lib playcarry/procam-play-bench ...
set -euo pipefail
build=$1
out=$2
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
mkdir -p "$work/playcarry/lib"
cp "$build/tools/procam-play-bench" "$work/playcarry/"
skip='^(linux-vdso|ld-linux|libc\.|libm\.|libdl\.|libpthread\.|librt\.|libstdc\+\+|libgcc_s|libcudart|libcublas|libcusolver|libcusparse|libnvJitLink)'
ldd "$build/tools/procam-play-bench" | awk '$3 ~ /^\// {print $1, $3}' | while read -r name path; do
  [[ "$name" =~ $skip ]] || cp -L "$path" "$work/playcarry/lib/$name"
done
for name in libEGL.so.1 libOpenGL.so.0 libGLX.so.0 libGLdispatch.so.0; do
  path=$(ldconfig -p | awk -v n="$name" '$1 == n {print $NF; exit}')
  [ -n "$path" ] && cp -L "$path" "$work/playcarry/lib/$name"
done
tar -C "$work" -cJf "$out" playcarry
echo "$out: $(du -h "$out" | cut -f1), $(ls "$work/playcarry/lib" | wc -l) libraries"
