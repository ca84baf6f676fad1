#!/usr/bin/env python3
"""Benchmark the compile cache of the loop (core/base/kernels.py): what a first process
pays, what an edit of one controller kind's module costs, what a later process pays.

    python benchmarks/benchmark_compile.py [--module control/pid.py]

In a copy of the package in a temporary folder, with its own NUMBA_CACHE_DIR (the
checkout and its cache are not touched), three processes one after the other each run
loop.warm() on seed000: a two-step run with every controller kind that has compiled
steps (each a signature of the loop; and one with the kinds without, if one is
registered), and the LSSVM's solves. Each line gives the seconds warm() took in that
process and what it compiled:
1. cold: an empty cache, every signature compiled;
2. after a comment is appended to one module of ato_nodes/core (--module, default the
   PID's): only the signatures built from it are compiled;
3. a second process: everything loaded from the cache.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import _cli

ROOT = Path(__file__).resolve().parents[1]
COMPILING = "compiling "  # kernels.COMPILING: how each announced compilation begins

# One process of the benchmark: warm() in the copy, its seconds on stdout.
WARM = """
import sys, time
import ato_nodes
from ato_nodes.core.base import kernels
from ato_nodes.core.config.scenario import load_scenario
from ato_nodes.core.run import loop
if not ato_nodes.__file__.startswith(sys.argv[1]):
    sys.exit(f"error: imported {ato_nodes.__file__}, not the copy")
values = load_scenario("seed000")
started = time.perf_counter()
with kernels.announced():
    loop.warm(values)
print(time.perf_counter() - started)
"""


def warm(copy: Path) -> tuple[float, list[str]]:
    """A new process's warm() in `copy`: its seconds and what it compiled (the lines
    `announced` wrote)."""
    done = subprocess.run([sys.executable, "-c", WARM, str(copy)], capture_output=True,
                          text=True, cwd=copy, env={**os.environ, "PYTHONPATH": str(copy),
                                                    "NUMBA_CACHE_DIR": str(copy / "cache")})
    if done.returncode != 0:
        _cli.fail(f"the benchmark's process failed: {done.stderr.strip()}", 1)
    compiled = [line.removeprefix(COMPILING) for line in done.stderr.splitlines()
                if line.startswith(COMPILING)]
    return float(done.stdout), compiled


def report(what: str, seconds: float, compiled: list[str]) -> None:
    print(f"{what:44s} {seconds:7.1f} s, {len(compiled)} compiled")
    for line in compiled:
        print(f"    {line}")


def main() -> None:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("--module", default="control/pid.py",
                        help="the module of ato_nodes/core edited before the second process "
                             "(default control/pid.py)")
    args = parser.parse_args()
    core = ROOT / "ato_nodes" / "core"
    module = (core / args.module).resolve()
    if not (module.is_file() and module.suffix == ".py" and module.is_relative_to(core)):
        _cli.fail(f"--module: no module ato_nodes/core/{args.module}")
    with tempfile.TemporaryDirectory() as scratch:
        copy = Path(scratch)
        shutil.copytree(ROOT / "ato_nodes", copy / "ato_nodes",
                        ignore=shutil.ignore_patterns("__pycache__"))
        (copy / "msg_config").symlink_to(ROOT / "msg_config")  # the shipped scenarios
        report("cold (an empty cache)", *warm(copy))
        with (copy / module.relative_to(ROOT)).open("a") as edited:
            edited.write("# an edit\n")
        report(f"after an edit of core/{args.module}", *warm(copy))
        report("a second process (the cache)", *warm(copy))
    print("(one measurement each, on this machine as loaded at the time)")


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
