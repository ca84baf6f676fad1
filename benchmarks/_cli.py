"""Shared by the benchmarks: scripts/_cli.py run as it is (the repository on sys.path,
Ctrl-C held while importing), and the helpers it gives the scripts."""

import runpy
from pathlib import Path

_SHARED = runpy.run_path(str(Path(__file__).resolve().parents[1] / "scripts" / "_cli.py"))
argument_parser = _SHARED["argument_parser"]
fail = _SHARED["fail"]
interrupted_quietly = _SHARED["interrupted_quietly"]
