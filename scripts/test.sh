#!/usr/bin/env bash
# Set up and run the whole test suite inside a private network namespace.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
exec scripts/isolated .venv/bin/python -m pytest tests "$@"
