"""Compiling the hot numerical functions with numba, when it is installed (optional).

`jitable` marks a plain function that compiled code may call: from Python it stays
the very same function (the nodes and simulate() call it as they always did); a
function compiled by `compiled` that calls it gets it compiled and inlined. So
there is one source of each formula, and the compiled run (core/run/fast_loop.py)
computes what the Python run does, operation for operation: numba keeps IEEE
semantics (no fast-math, no fused multiply-add) and calls the same libm for sin,
exp and pow, so the two agree bit for bit (tests/test_fast_loop.py checks it).
Without numba nothing is compiled and every run takes the Python path.

Compiling takes seconds (the loop of core/run/fast_loop.py: 3-5 s here); the machine
code is then cached beside the source (`__pycache__`, cache=True), and every later
process of the checkout loads it in a fraction of that. `announced` tells the
user when a compilation really happens.
"""

from __future__ import annotations

import sys
from contextlib import contextmanager

try:
    import numba
    from numba.extending import overload, register_jitable  # noqa: F401 (overload: exported)
except ImportError:  # optional: runs are then Python only
    numba = overload = None

AVAILABLE = numba is not None


def jitable(function):
    """`function` itself, callable from compiled code too when numba is installed."""
    return register_jitable(function) if AVAILABLE else function


def compiled(function):
    """`function` compiled by numba (machine code cached on disk beside the source),
    or None without numba."""
    return numba.njit(cache=True, nogil=True)(function) if AVAILABLE else None


@contextmanager
def announced(message: str):
    """While inside, the first compilation that numba really does (a function not in
    its cache yet, or cached for another source) prints `message` to stderr first."""
    if not AVAILABLE:
        yield
        return
    from numba.core import event

    class Announcer(event.Listener):
        said = False

        def on_start(self, compilation):
            if not self.said:
                print(message, file=sys.stderr, flush=True)
                self.said = True

        def on_end(self, compilation):
            pass

    with event.install_listener("numba:compile", Announcer()):
        yield
