"""Shared by the benchmarks: scripts/_cli.py run as it is (the repository on sys.path,
Ctrl-C held while importing), and the helpers it gives the scripts."""

import runpy
import statistics
import time
from collections.abc import Callable
from pathlib import Path

_SHARED = runpy.run_path(str(Path(__file__).resolve().parents[1] / "scripts" / "_cli.py"))
argument_parser = _SHARED["argument_parser"]
fail = _SHARED["fail"]
interrupted_quietly = _SHARED["interrupted_quietly"]


def median_seconds(work: Callable[[int], object], repeats: int) -> float:
    """Median wall seconds of work(i) over i in range(repeats)."""
    times = []
    for repeat in range(repeats):
        started = time.perf_counter()
        work(repeat)
        times.append(time.perf_counter() - started)
    return statistics.median(times)
