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
process of the checkout loads it in a fraction of that. numba checks only the
compiled function's own file to decide whether its cache is stale, while the loop
inlines formulas from all over the core: `compiled` therefore keeps a digest of
every core source beside the cache and drops the cache when any of them changed.
`announced` tells the user when a compilation really happens.
"""

from __future__ import annotations

import functools
import hashlib
import io
import pickle
import sys
from contextlib import contextmanager
from pathlib import Path

try:
    import numba
    from numba import objmode  # noqa: F401 (exported: Python called from compiled code)
    from numba.extending import overload, register_jitable  # noqa: F401 (overload: exported)
except ImportError:  # optional: runs are then Python only
    numba = objmode = overload = None

AVAILABLE = numba is not None


def jitable(function=None, *, inline: bool = False):
    """`function` itself, callable from compiled code too when numba is installed; with
    inline, compiled code inlines it where it is called (worth it for a small function
    handed arrays many times a step: compiled code counts references to every array it
    hands to a function it calls, which can cost more than the function's arithmetic)."""
    if function is None:
        return functools.partial(jitable, inline=inline)
    if not AVAILABLE:
        return function
    if inline:
        typing = functools.wraps(function)(lambda *arguments: function)
        overload(function, inline="always", strict=False)(typing)
        return function
    return register_jitable(function)


def compiled(function):
    """`function` compiled by numba (machine code cached on disk beside the source, and
    recompiled when any core source changed; for the signatures of the core's own types
    only, CoreCache), or None without numba."""
    if not AVAILABLE:
        return None
    _drop_stale_cache(function)
    dispatcher = numba.njit(cache=True, nogil=True)(function)
    dispatcher._cache = CoreCache(function)
    return dispatcher


# The packages whose classes a signature cached on disk may hold: the core's (its sources
# are in sources_digest()) and those of numba and numpy (numba's index keys its version).
CACHED_PACKAGES = frozenset({"ato_nodes", "numba", "numpy", "builtins"})


class _Classes(pickle.Pickler):
    """Notes the module of every class a pickled object holds."""

    def __init__(self):
        super().__init__(io.BytesIO())
        self.modules: set[str] = set()

    def reducer_override(self, obj):
        if isinstance(obj, type):
            self.modules.add(obj.__module__)
        return NotImplemented


def cacheable(signature) -> bool:
    """Whether a compiled signature is made of the core's, numba's and numpy's types
    alone (not of a plug-in's: core/config/plugins.py)."""
    classes = _Classes()
    classes.dump(signature)
    return all(module.partition(".")[0] in CACHED_PACKAGES for module in classes.modules)


if AVAILABLE:
    from numba.core.caching import FunctionCache

    class CoreCache(FunctionCache):
        """numba's on-disk cache for the signatures cacheable() allows; a plug-in's kind
        is compiled in each process that runs it instead. Its classes in the index shared
        by every process of the checkout would stop each process without the plug-in
        from loading any entry (the index is unpickled whole), and a change of its
        sources would not drop the machine code compiled from the old ones."""

        def load_overload(self, sig, target_context):
            return super().load_overload(sig, target_context) if cacheable(sig) else None

        def save_overload(self, sig, data):
            if cacheable(sig):
                super().save_overload(sig, data)


CORE = Path(__file__).resolve().parents[1]  # ato_nodes/core


@functools.lru_cache(maxsize=1)
def sources_digest() -> str:
    """sha256 over every core source file, by path and content (once per process: every
    compiled function's cache check at import reads the same files)."""
    digest = hashlib.sha256()
    for path in sorted(CORE.rglob("*.py")):
        digest.update(str(path.relative_to(CORE)).encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()


def _drop_stale_cache(function) -> None:
    """Remove `function`'s numba cache files when the core's sources differ from those
    it was compiled from (a digest kept beside them); best effort: a cache folder that
    cannot be written is numba's to handle."""
    source = Path(function.__code__.co_filename)
    cache = source.parent / "__pycache__"
    stem = f"{source.stem}.{function.__qualname__}"
    stamp = cache / f"{stem}.sources"
    digest = sources_digest()
    try:
        if stamp.is_file() and stamp.read_text() == digest:
            return
        for stale in cache.glob(f"{stem}-*.nb[ic]"):
            stale.unlink(missing_ok=True)
        cache.mkdir(exist_ok=True)
        stamp.write_text(digest)
    except OSError:
        pass


@contextmanager
def announced(message: str):
    """While inside, the first compilation that numba really does (a function not in
    its cache yet, or cached for another source) prints `message` to stderr first."""
    if not AVAILABLE:
        yield
        return
    from numba.core import event
    from numba.core.dispatcher import ObjModeLiftedWith

    class Announcer(event.Listener):
        said = False

        def on_start(self, compilation):
            # a Python call inside compiled code (objmode) is lifted in every process,
            # cache or not: ~0.1 s, nothing to announce
            lifted = isinstance(compilation.data["dispatcher"], ObjModeLiftedWith)
            if not self.said and not lifted:
                print(message, file=sys.stderr, flush=True)
                self.said = True

        def on_end(self, compilation):
            pass

    with event.install_listener("numba:compile", Announcer()):
        yield
