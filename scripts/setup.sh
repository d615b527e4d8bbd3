#!/usr/bin/env bash
# Create .venv with ROS 2 Jazzy (PyPI wheels) and every dependency, and install fpc_gripper into it.
set -euo pipefail
cd "$(dirname "$0")/.."
if ! command -v ip >/dev/null || ! command -v unshare >/dev/null; then
  apt-get update -qq && apt-get install -y -qq iproute2 util-linux
fi
if [ ! -x .venv/bin/python ]; then
  python3 -m venv .venv
fi
# The lock holds one Python's wheels (its header says which); another Python needs its own lock.
locked="$(sed -n 's/^# Python \([0-9]*\.[0-9]*\).*/\1/p' requirements.lock)"
python="$(.venv/bin/python -c 'import sys; print("%d.%d" % sys.version_info[:2])')"
if [ "$locked" != "$python" ]; then
  echo "setup.sh: requirements.lock is for Python $locked, .venv has $python:" \
    'run scripts/lock.sh with this Python (or remove .venv)' >&2
  exit 1
fi
pip=(.venv/bin/pip --disable-pip-version-check)
# Exactly requirements.lock: whatever .venv holds beyond it goes, the pins are installed as
# they are (--no-deps: nothing unpinned can come in), and pip check proves they are complete.
names() { sed -e '/^#/d' -e 's/==.*//' | LC_ALL=C sort; }
extra="$(LC_ALL=C comm -23 <(.venv/bin/python scripts/freeze.py | names) \
  <(names <requirements.lock))"
if [ -n "$extra" ]; then
  echo "setup.sh: removing from .venv what requirements.lock does not pin:" $extra
  "${pip[@]}" uninstall -q -y $extra
fi
# The compiled engine (about 1.5 min on 2 cores, once; nothing compiles at run time after) needs
# only numpy, scipy and numba: install those, start it from the source tree, and install the
# rest and build the interfaces beside it. In its own process group, so that a failed or
# interrupted set-up stops its workers too.
"${pip[@]}" install -q --no-deps $(grep -iE '^(numpy|scipy|numba|llvmlite)==' requirements.lock)
setsid .venv/bin/python -m fpc_gripper.model.build --if-stale &
engine=$!
trap 'kill -TERM -- -"$engine" 2>/dev/null || true' EXIT
"${pip[@]}" install -q --no-deps -r requirements.lock
"${pip[@]}" install -q --no-deps --use-pep517 --no-build-isolation -e .
# control_msgs (GripperCommand) and tf2_msgs (TFMessage), which PyPI lacks: about 20 s, once.
scripts/build_interfaces.sh
if ! wait "$engine"; then
  echo 'setup.sh: the engine build failed (its log above)' >&2
  exit 1
fi
trap - EXIT
if ! check="$("${pip[@]}" check)"; then
  echo "$check" >&2
  exit 1
fi
