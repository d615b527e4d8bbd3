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
.venv/bin/pip install -q --disable-pip-version-check -r requirements.txt
.venv/bin/pip install -q --disable-pip-version-check --no-deps -e .
