#!/usr/bin/env bash
# Build interfaces/ (control_msgs' GripperCommand, tf2_msgs' TFMessage) with rosidl into .venv,
# unless they are importable already (a real Jazzy install has the upstream packages).
set -euo pipefail
cd "$(dirname "$0")/.."
venv="$PWD/.venv"
py="$venv/bin/python"
if [ "${1:-}" != --force ] && "$py" -c 'import control_msgs.action, tf2_msgs.msg' 2>/dev/null; then
  exit 0
fi
for tool in cmake g++; do
  command -v "$tool" >/dev/null || { apt-get update -qq && apt-get install -y -qq cmake g++; }
done
# The wheels' exported CMake files name the wheel builder's Python; point them at this one.
numpy_include="$("$py" -c 'import numpy; print(numpy.get_include())')"
python_include="$("$py" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')"
files="$(grep -rl /opt/python/cp311-cp311 "$venv"/share/*/cmake 2>/dev/null || true)"
if [ -n "$files" ]; then
  sed -i -e "s#/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include#$numpy_include#g" \
    -e "s#/opt/python/cp311-cp311/include/python3.11#$python_include#g" $files
fi
generator=()
command -v ninja >/dev/null && generator=(-G Ninja)
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
start=$SECONDS
# tf2_msgs and control_msgs depend only on packages the wheels installed, so the order is free.
for package in tf2_msgs control_msgs; do
  echo "build_interfaces: $package" >&2
  if ! { AMENT_PREFIX_PATH="$venv" cmake -S "interfaces/$package" -B "$work/$package" \
           "${generator[@]}" -DCMAKE_BUILD_TYPE=Release -DBUILD_TESTING=OFF \
           -DCMAKE_PREFIX_PATH="$venv" -DCMAKE_INSTALL_PREFIX="$venv" \
           -DPython3_EXECUTABLE="$py" &&
         cmake --build "$work/$package" -j "$(nproc)" &&
         cmake --install "$work/$package"; } >"$work/$package.log" 2>&1; then
    tail -n 30 "$work/$package.log" >&2
    echo "build_interfaces: building $package failed (log above)" >&2
    exit 1
  fi
done
"$py" -c 'import control_msgs.action, tf2_msgs.msg'
echo "build_interfaces: control_msgs and tf2_msgs built into .venv in $((SECONDS - start)) s" >&2
