#!/usr/bin/env bash
# Set up and run the whole test suite inside a private network namespace.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
# Two workers, one per core (nothing compiles in the tests: set-up built the engine). A file's
# tests stay on one worker (they share module fixtures and contexts).
exec scripts/isolated .venv/bin/python -m pytest tests -n 2 --dist loadfile "$@"
