#!/usr/bin/env bash
# procam as an installed package: `cmake --install` into a temporary prefix, a program outside
# the tree (tests/package/consumer) configured with find_package(procam), built and run, the
# installed procam binary run; then `cpack -G DEB` and the .deb's contents and dependencies.
#   check_install.sh BUILD_DIR SOURCE_DIR
set -euo pipefail
build=$(cd "$1" && pwd)
source=$(cd "$2" && pwd)
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT

cmake --install "$build" --prefix "$scratch/prefix" >/dev/null
"$scratch/prefix/bin/procam" --version
for file in lib/cmake/procam/procamConfig.cmake include/procam/compensation/solver.h \
            include/procam/base/camera_model.h include/procam/procam/config.h; do
  [ -f "$scratch/prefix/$file" ] || { echo "FAIL: $file not installed"; exit 1; }
done

# The Python module, where this build made one: imported from the installed prefix alone.
python_module=no
if [ -f "$build/python/procam/__init__.py" ]; then
  python_module=yes
  PYTHONPATH="$scratch/prefix/lib/python3/dist-packages" /usr/bin/python3 -c \
    "import procam, sys; g = procam.geometry('synthetic:tiny_box', patches=64); assert g.fine.size > 0; \
assert procam.__file__.startswith(sys.argv[1]), procam.__file__" "$scratch/prefix"
fi

cmake -S "$source/tests/package/consumer" -B "$scratch/consumer" -G Ninja \
      -DCMAKE_PREFIX_PATH="$scratch/prefix" -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$scratch/consumer" >/dev/null
mkdir "$scratch/run"
"$scratch/consumer/consumer" "$scratch/run"

(cd "$scratch" && cpack -G DEB --config "$build/CPackConfig.cmake" >/dev/null)
deb=$(ls "$scratch"/procam_*.deb)
depends=$(dpkg-deb -f "$deb" Depends)
for package in libceres-dev libembree-dev libopencv-dev libmrcal-dev nlohmann-json3-dev; do
  grep -q "$package" <<<"$depends" || { echo "FAIL: $deb does not depend on $package ($depends)"; exit 1; }
done
contents=$(dpkg-deb -c "$deb")
for file in ./usr/bin/procam ./usr/lib/cmake/procam/procamConfig.cmake \
            ./usr/include/procam/geometry/scene.h; do
  grep -q " $file\$" <<<"$contents" || { echo "FAIL: $deb lacks $file"; exit 1; }
done
if [ "$python_module" = yes ]; then
  grep -q " ./usr/lib/python3/dist-packages/procam/__init__.py\$" <<<"$contents" ||
    { echo "FAIL: $deb lacks the Python module"; exit 1; }
  grep -q "python3-numpy" <<<"$depends" || { echo "FAIL: $deb does not depend on python3-numpy"; exit 1; }
fi
echo "$(basename "$deb"): depends on $depends"
