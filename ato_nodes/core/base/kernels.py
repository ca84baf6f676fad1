"""Compiling the hot numerical functions with numba, when it is installed (optional).

`jitable` marks a plain function that compiled code may call: from Python it stays
the very same function (the nodes and simulate() call it as they always did); a
function compiled by `compiled` that calls it gets it compiled and inlined. So
there is one source of each formula, and the compiled run (core/run/fast_loop.py)
computes what the Python run does, operation for operation: numba keeps IEEE
semantics (no fast-math, no fused multiply-add) and calls the same libm for sin,
exp and pow, so the two agree bit for bit (tests/test_fast_loop.py checks it).
Without numba nothing is compiled and every run takes the Python path.

Compiling takes seconds (one signature of the loop of core/run/fast_loop.py: 5-15 s
here); the machine code is then cached on disk (numba's cache: beside the source in
`__pycache__`, or under NUMBA_CACHE_DIR), and every later process loads it in a fraction
of that. numba itself checks only the compiled function's own file, while compiled code
inlines formulas from other modules: `compiled` therefore keys each signature's entry
of the cache by a digest of the sources that signature is built from (`Sources`): the
function's module and the modules it imports, transitively (read from their import
statements), and what the signature adds, e.g. the loop's controller kind's modules,
wherever they live. An edit recompiles the signatures built from the edited file only,
and an entry replaced by a newer one of its signature is dropped. `announced` says
what numba really compiles, why and how long it took.
"""

from __future__ import annotations

import ast
import functools
import hashlib
import importlib.util
import os
import sys
import sysconfig
import time
from collections.abc import Callable, Iterable
from contextlib import contextmanager
from pathlib import Path
from typing import NamedTuple

try:
    import numba
    from numba import objmode  # noqa: F401 (exported: Python called from compiled code)
    from numba.core import event
    from numba.core.caching import CompileResultCacheImpl, FunctionCache, IndexDataCacheFile
    from numba.extending import overload, register_jitable  # noqa: F401 (overload: exported)
except ImportError:  # optional: runs are then Python only
    numba = objmode = overload = None

AVAILABLE = numba is not None
COMPILING = "compiling "  # how each line `announced` writes begins


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


class Sources(NamedTuple):
    """What one signature of a compiled function is built from besides the function's
    own module and what it imports."""

    what: str                              # what is compiled, as `announced` names it
    modules: tuple[str, ...] = ()          # modules whose code it inlines (imports followed)
    apart: frozenset[str] = frozenset()    # modules not followed: they are other signatures'


def compiled(function, sources: Callable[[tuple], Sources] | None = None):
    """`function` compiled by numba, or None without numba. Each signature's machine code
    is cached on disk and compiled again when a source it is built from changed:
    `function`'s module and its imports, and what `sources(signature)` adds."""
    if not AVAILABLE:
        return None
    what = f"{function.__module__.rpartition('.')[2]}.{function.__qualname__}"
    dispatcher = numba.njit(nogil=True)(function)
    if not numba.config.DISABLE_JIT:
        # where numba's own cache=True puts its FunctionCache (Dispatcher.enable_caching)
        dispatcher._cache = SourcesCache(function, sources or (lambda signature: Sources(what)))
    return dispatcher


def sources_digest(modules: Iterable[str], apart: frozenset[str] = frozenset()) -> str:
    """sha256 over the source of each of `modules` and of the modules they import,
    transitively, by name and content. Not followed: `apart`, and the modules of other
    packages installed as libraries (the standard library, site-packages: they change
    with a version, not in place); the packages of `modules` are followed wherever they
    are installed."""
    digest = hashlib.sha256()
    for name, source in sorted(_closure(modules, apart).items()):
        digest.update(name.encode() + b"\0" + source + b"\0")
    return digest.hexdigest()


def _closure(modules: Iterable[str], apart: frozenset[str]) -> dict[str, bytes]:
    """{name: source} of `modules` and the loaded modules they import, transitively."""
    sources: dict[str, bytes] = {}
    pending = list(modules)
    packages = {name.partition(".")[0] for name in pending}
    while pending:
        name = pending.pop()
        path = getattr(sys.modules.get(name), "__file__", None)
        if (name in sources or name in apart or path is None or not path.endswith(".py")
                or name.partition(".")[0] not in packages and _library(path)):
            continue
        sources[name], imported = _read(path, sys.modules[name].__package__ or "")
        pending.extend(imported)
    return sources


_LIBRARIES = tuple(os.path.join(sysconfig.get_path(key), "")
                   for key in ("stdlib", "platstdlib"))


def _library(path: str) -> bool:
    """Whether a module's file is an installed library's (not edited in place)."""
    return path.startswith(_LIBRARIES) or bool({"site-packages", "dist-packages"}
                                                & set(Path(path).parts))


def _read(path: str, package: str) -> tuple[bytes, frozenset[str]]:
    """A module's source and the names it imports (a `from` import's names included:
    any of them may be a module); read again when the file changed."""
    try:
        status = os.stat(path)
    except OSError:  # gone since it was imported: nothing to build from
        return b"", frozenset()
    return _parsed(path, status.st_mtime_ns, status.st_size, package)


@functools.lru_cache(maxsize=None)
def _parsed(path: str, mtime: int, size: int, package: str) -> tuple[bytes, frozenset[str]]:
    source = Path(path).read_bytes()
    try:
        nodes = list(ast.walk(ast.parse(source, path)))
    except SyntaxError:  # edited since it was imported: its text is what counts
        nodes = []
    names = set()
    for node in nodes:
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = "." * node.level + (node.module or "")
            try:
                base = importlib.util.resolve_name(base, package) if node.level else base
            except ValueError:  # relative beyond its package: it could not be imported
                continue
            names.add(base)
            names.update(f"{base}.{alias.name}" for alias in node.names)
    return source, frozenset(names)


if AVAILABLE:
    class SignatureIndex(IndexDataCacheFile):
        """numba's index of a function's cache entries, keyed by SourcesCache: the stamp
        numba gives it (its check of the function's own file) is fixed, since each key's
        digest covers that file; saving an entry replaces the one of the same signature
        built from other sources (each signature keeps one entry and one data file)."""

        def __init__(self, cache_path: str, filename_base: str):
            super().__init__(cache_path, filename_base, source_stamp="keyed by sources")

        def save(self, key, data):
            overloads = self._load_index()
            stale = [old for old in overloads if old[:2] == key[:2] and old != key]
            if stale:
                names = [overloads.pop(old) for old in stale]
                overloads[key] = names[0]  # its data file is overwritten next
                self._save_index(overloads)
                for name in names[1:]:
                    Path(self._data_path(name)).unlink(missing_ok=True)
            super().save(key, data)

        def holds(self, signature: str) -> bool:
            """Whether an entry of `signature` is kept (built from other sources)."""
            return any(key[0] == signature for key in self._load_index())

    class SourcesCacheImpl(CompileResultCacheImpl):
        def get_filename_base(self, fullname: str, abiflags: str) -> str:
            """numba's name of the index and data files but for the function's first line
            (an edit above it would leave them behind: the key tells code apart)."""
            version = f"{sys.version_info[0]}{sys.version_info[1]}"
            return f"{fullname.replace('<', '').replace('>', '')}.py{version}{abiflags}"

    class SourcesCache(FunctionCache):
        """numba's cache of a compiled function, each signature's entry keyed also by the
        digest of the sources it is built from (`Sources`); the key names the types by
        text, so that no module is imported to read the index (a plug-in's kind, gone
        since, would make it unreadable)."""

        _impl_class = SourcesCacheImpl

        def __init__(self, function, sources: Callable[[tuple], Sources]):
            self.sources, self.missed = sources, {}  # missed: signature -> why compiled
            super().__init__(function)
            self._cache_file = SignatureIndex(self._cache_path, self._impl.filename_base)

        def _index_key(self, sig, codegen):
            _, machine, code = super()._index_key(sig, codegen)
            sources = self.sources(tuple(sig))
            roots = (self._py_func.__module__, *sources.modules)
            return signature_text(sig), machine, code, sources_digest(roots, sources.apart)

        def load_overload(self, sig, target_context):
            result = super().load_overload(sig, target_context)
            if result is None:
                held = self._cache_file.holds(signature_text(sig))
                self.missed[signature_text(sig)] = ("its sources changed" if held
                                                    else "not in the cache")
            return result

        def described(self, signature: tuple) -> str:
            """What compiling `signature` compiles and why, as `announced` says it."""
            why = self.missed.get(signature_text(signature), "not cached")
            return f"{self.sources(signature).what} ({why})"

    def signature_text(signature) -> str:
        """A signature's argument types as text, each class in them by module and name
        (numba's names of types name a NamedTuple by its class's bare name)."""
        return _named(tuple(signature))

    def _named(part) -> str:
        if isinstance(part, type):
            return f"{part.__module__}.{part.__qualname__}"
        if isinstance(part, tuple):
            return f"({', '.join(map(_named, part))})"
        if isinstance(part, numba.types.Type):
            return f"{type(part).__name__}{_named(part.key)}"
        return repr(part)

    class Announcer(event.Listener):
        """Says on stderr what each compilation of a `compiled` function compiles and why,
        then how long it took (what it compiles along is part of it: said once)."""

        def __init__(self):
            self.open: list[float | None] = []  # per compilation under way: its start, if said

        def on_start(self, compilation):
            cache = getattr(compilation.data["dispatcher"], "_cache", None)
            if isinstance(cache, SourcesCache) and all(said is None for said in self.open):
                print(f"{COMPILING}{cache.described(tuple(compilation.data['args']))} ...",
                      end="", file=sys.stderr, flush=True)
                self.open.append(time.perf_counter())
            else:
                self.open.append(None)

        def on_end(self, compilation):
            started = self.open.pop()
            if started is not None:
                print(f" {time.perf_counter() - started:.1f} s", file=sys.stderr, flush=True)


@contextmanager
def announced():
    """While inside, each compilation numba really does of a `compiled` function (its
    signature not in the cache, or cached from other sources) says on stderr what it
    compiles, why and how long it took: 'compiling the loop for controller pid (its
    sources changed) ... 6.1 s'. Loading from the cache says nothing."""
    if not AVAILABLE:
        yield
        return
    with event.install_listener("numba:compile", Announcer()):
        yield
