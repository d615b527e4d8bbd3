#!/usr/bin/env bash
# Regenerate requirements.lock from requirements.in (and requirements-nodeps.in, installed
# without dependencies) in a throwaway venv and show what changed.
set -euo pipefail
cd "$(dirname "$0")/.."
python="${PYTHON:-python3}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
"$python" -m venv "$work/venv"
"$work/venv/bin/pip" install -q --disable-pip-version-check -r requirements.in
"$work/venv/bin/pip" install -q --disable-pip-version-check --no-deps -r requirements-nodeps.in
"$work/venv/bin/pip" check
{
  echo '# Every distribution scripts/setup.sh installs, at its exact version. Generated: do not'
  echo '# edit. Change requirements.in, then run scripts/lock.sh (a fresh venv, pip install -r'
  echo '# requirements.in, then scripts/freeze.py) and commit both files.'
  "$work/venv/bin/python" -c \
    'import platform; print("# Python", platform.python_version(), "on", platform.machine())'
  "$work/venv/bin/python" scripts/freeze.py
} >"$work/requirements.lock"
# Summary: + added, - removed, ~ changed (old -> new).
pins() { grep -v '^#' "$1" 2>/dev/null | sed 's/==/ /' | LC_ALL=C sort || true; }
LC_ALL=C join -a 1 -a 2 -e - -o 0,1.2,2.2 <(pins requirements.lock) \
  <(pins "$work/requirements.lock") | awk '
  $2 == "-" { print "  + " $1 " " $3; added++; next }
  $3 == "-" { print "  - " $1 " " $2; removed++; next }
  $2 != $3 { print "  ~ " $1 " " $2 " -> " $3; changed++ }
  END { printf "requirements.lock: %d added, %d removed, %d changed\n", added, removed, changed }'
cp "$work/requirements.lock" requirements.lock
echo "requirements.lock: $(grep -vc '^#' requirements.lock) pins"
