#!/usr/bin/env bash
# Build ROS 2 interface packages with rosidl into the project's venv (the venv is the install
# prefix, so the messages import with no environment variables).
#
# The ROS wheels' cmake exports name the include dirs of the machine that built them
# (/opt/python/cp311-cp311/...); they are pointed at this venv's Python and numpy first.
# Usage: tools/build_interfaces.sh VENV PACKAGE_DIR...
set -euo pipefail
venv=$(cd "$1" && pwd); shift
python="$venv/bin/python"
py_include=$("$python" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
np_include=$("$python" -c 'import numpy; print(numpy.get_include())')

{ grep -rl --include='*.cmake' '/opt/python/cp311-cp311' "$venv/share" 2>/dev/null || true; } | while read -r file; do
  sed -i -e "s#/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include#$np_include#g" \
         -e "s#/opt/python/cp311-cp311/include/python3.11#$py_include#g" "$file"
done

export _ROS_WHEELS_BOOTSTRAP_COMPLETE=1 AMENT_PREFIX_PATH="$venv" PATH="$venv/bin:$PATH"
for pkg in "$@"; do
  name=$(basename "$pkg")
  build="$venv/build-interfaces/$name"
  mkdir -p "$build"
  echo "building $name into $venv"
  cmake -S "$pkg" -B "$build" -DCMAKE_BUILD_TYPE=Release -DBUILD_TESTING=OFF \
    -DCMAKE_PREFIX_PATH="$venv" -DCMAKE_INSTALL_PREFIX="$venv" \
    -DPython3_EXECUTABLE="$python" -DPYTHON_EXECUTABLE="$python" >"$build.log" 2>&1 \
    || { tail -30 "$build.log"; exit 1; }
  cmake --build "$build" -j2 >>"$build.log" 2>&1 || { tail -30 "$build.log"; exit 1; }
  cmake --install "$build" >>"$build.log" 2>&1 || { tail -30 "$build.log"; exit 1; }
done
