#!/usr/bin/env bash
# Creates .venv (CPython 3.11: the ROS 2 Jazzy wheels exist for it only), installs
# requirements.txt and the package into it and compiles the simulation kernels, saying
# so before each step. Safe to run again: an existing .venv is reused.
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
if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv with $python"
  "$python" -m venv .venv
fi
# (pip's notes about configured local index folders that do not exist are noise)
echo "setup: installing the pinned packages of requirements.txt into .venv (ROS 2 Jazzy" \
  "wheels, numpy, numba, Dask, ...)"
.venv/bin/python -m pip install --quiet --disable-pip-version-check -r requirements.txt \
  2> >(grep -v "^WARNING: Location .* is ignored" >&2)
# The package itself, editable: `import ato_nodes` works from any directory, the node
# entry points are on .venv/bin, and the checkout stays the code that runs.
echo "setup: installing ato_nodes from this checkout, editable"
.venv/bin/python -m pip install --quiet --disable-pip-version-check --no-deps -e . \
  2> >(grep -v "^WARNING: Location .* is ignored" >&2)
# The worked example of a plug-in (docs/plugins.md), editable: its kind `smc` is found by
# its entry point in every process of the venv (the nodes, tuning and study workers), and
# the tests drive it end to end.
echo "setup: installing the example plug-in examples/ato-smc (controller kind smc), editable"
.venv/bin/python -m pip install --quiet --disable-pip-version-check --no-deps \
  -e examples/ato-smc 2> >(grep -v "^WARNING: Location .* is ignored" >&2)
# Compiled now (one loop per controller kind), the in-process loop is loaded from its
# cache by every later run, tuning worker and test instead of being compiled by the
# first; each compilation says what it compiles, why and how long it took.
echo "setup: compiling the simulation kernels that are not cached yet"
.venv/bin/python -c "from ato_nodes.core.base import kernels; from ato_nodes.core.run import loop
with kernels.announced(): loop.warm()"
