#!/usr/bin/env bash
# Set up and run the simulated gripper session: model node, simulated regulator, MCAP and chart.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
exec scripts/isolated .venv/bin/gripper_demo --output-dir "${1:-out/demo}"
