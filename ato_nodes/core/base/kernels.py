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
    recompiled when any core source changed; a plug-in's signatures in files of their own,
    CoreCache), or None without numba."""
    if not AVAILABLE:
        return None
    _drop_stale_cache(function)
    dispatcher = numba.njit(cache=True, nogil=True)(function)
    dispatcher._cache = CoreCache(function)
    return dispatcher


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


# The packages whose classes a signature may hold and still be cached in the function's
# own index: the core's (its sources are in sources_digest()), numba's and numpy's (numba's
# index keys its version). A signature that holds another package's (a plug-in's kind,
# core/config/plugins.py) is cached in an index of its own beside it (CoreCache).
CORE_PACKAGES = frozenset({"ato_nodes", "numba", "numpy", "builtins"})


class _Classes(pickle.Pickler):
    """Notes the module of every class a pickled object holds."""

    def __init__(self):
        super().__init__(io.BytesIO())
        self.modules: set[str] = set()

    def reducer_override(self, obj):
        if isinstance(obj, type):
            self.modules.add(obj.__module__)
        return NotImplemented


def foreign_packages(signature) -> tuple[str, ...]:
    """The packages besides CORE_PACKAGES whose classes a compiled signature holds."""
    classes = _Classes()
    classes.dump(signature)
    return tuple(sorted({module.partition(".")[0] for module in classes.modules}
                        - CORE_PACKAGES))


def packages_digest(packages: tuple[str, ...]) -> str | None:
    """sha256 over the sources of `packages` (each package's folder, or its one module),
    None if one has no source file to read."""
    digest = hashlib.sha256()
    for name in packages:
        source = getattr(sys.modules.get(name), "__file__", None)
        if source is None:
            return None
        source = Path(source)
        files = sorted(source.parent.rglob("*.py")) if source.name == "__init__.py" \
            else [source]
        for path in files:
            digest.update(f"{name}/{path.relative_to(source.parent)}".encode() + b"\0"
                          + path.read_bytes())
    return digest.hexdigest()


if AVAILABLE:
    from numba.core.caching import FunctionCache, IndexDataCacheFile

    class CoreCache(FunctionCache):
        """numba's on-disk cache of a compiled function, with the signatures that hold
        another package's classes (a plug-in's settings and state) in an index of their
        own per set of packages, stamped with those packages' sources. In the function's
        own index, shared by every process of the checkout, such a signature would stop
        each process without the plug-in from loading any entry (numba unpickles the
        index whole), and a change of the plug-in's sources would not drop the machine
        code compiled from the old ones. Both kinds of files are dropped with the core's
        (_drop_stale_cache)."""

        def __init__(self, py_func):
            super().__init__(py_func)
            self._beside: dict[tuple[str, ...], IndexDataCacheFile | None] = {}

        def _file_for(self, sig) -> IndexDataCacheFile | None:
            packages = foreign_packages(sig)
            if not packages:
                return self._cache_file
            if packages not in self._beside:
                stamp = packages_digest(packages)
                self._beside[packages] = None if stamp is None else IndexDataCacheFile(
                    self._cache_path, f"{self._impl.filename_base}-{'-'.join(packages)}", stamp)
            return self._beside[packages]

        def _load_overload(self, sig, target_context):
            cache_file = self._file_for(sig)
            if not self._enabled or cache_file is None:
                return None
            data = cache_file.load(self._index_key(sig, target_context.codegen()))
            return None if data is None else self._impl.rebuild(target_context, data)

        def _save_overload(self, sig, data):
            cache_file = self._file_for(sig)
            if not self._enabled or cache_file is None or not self._impl.check_cachable(data):
                return
            self._impl.locator.ensure_cache_path()
            cache_file.save(self._index_key(sig, data.codegen), self._impl.reduce(data))


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
