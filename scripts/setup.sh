#!/usr/bin/env bash
# Creates .venv (CPython 3.11: the ROS 2 Jazzy wheels exist for it only) and installs
# requirements.txt into it. Safe to run again: an existing .venv is reused.
set -euo pipefail
cd "$(dirname "$0")/.."
python=${PYTHON:-}
if [ -z "$python" ]; then
  for candidate in python3.11 python3; do
    if command -v "$candidate" >/dev/null &&
       "$candidate" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
      python=$candidate
      break
    fi
  done
fi
if [ -z "$python" ]; then
  echo "error: CPython 3.11 is needed (the ros-jazzy-* wheels are built for it); set PYTHON=" >&2
  exit 2
fi
[ -x .venv/bin/python ] || "$python" -m venv .venv
# (pip's notes about configured local index folders that do not exist are noise)
.venv/bin/python -m pip install --quiet --disable-pip-version-check -r requirements.txt \
  2> >(grep -v "^WARNING: Location .* is ignored" >&2)
# The package itself, editable: `import ato_nodes` works from any directory, the node
# entry points are on .venv/bin, and the checkout stays the code that runs.
.venv/bin/python -m pip install --quiet --disable-pip-version-check --no-deps -e . \
  2> >(grep -v "^WARNING: Location .* is ignored" >&2)
