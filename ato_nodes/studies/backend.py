"""Where a study's runs go, shared by the tuner and the study scripts: local worker
processes (or threads, for runs that are processes already) or the workers of a Dask
cluster (--cluster local:N or tcp://HOST:PORT); how a Ctrl-C or a lost scheduler ends
them (the runs under way cancelled, one line, what was recorded kept); and the
progress line on stderr.
"""

from __future__ import annotations

import contextlib
import ctypes
import itertools
import logging
import math
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Hashable, Iterable, Iterator
from concurrent.futures import (FIRST_COMPLETED, CancelledError, Executor, Future,
                                ProcessPoolExecutor, ThreadPoolExecutor, wait)
from typing import Any

from ato_nodes.core.base.errors import ScenarioError

INTERRUPT_POLL = 0.1  # s: how soon a Ctrl-C stops the runs under way
BAR_WIDTH = 30  # characters of the progress bar on a terminal
QUEUED_PER_SLOT = 4  # runs handed out ahead per worker (stream()): its next ones are queued
SLOTS_REFRESH = 2.0  # s between asking a cluster how many threads it has
PR_SET_PDEATHSIG = 1
LIBC = ctypes.CDLL(None, use_errno=True)  # loaded before any fork: prctl in the worker


class ClusterLost(RuntimeError):
    """The Dask scheduler stopped answering: the study cannot go on through no fault of
    its input; what it recorded stays for a resume."""


def check_cluster(spec: str) -> None:
    """A ScenarioError (one line) for a --cluster that is neither local:N nor
    tcp://HOST:PORT: checked before anything starts."""
    if spec.startswith("local:"):
        count = spec.partition(":")[2]
        if not count.isdigit() or int(count) < 1:
            raise ScenarioError(f"--cluster local:N needs a positive worker count, got {spec!r}")
    elif not spec.startswith("tcp://"):
        raise ScenarioError(f"--cluster expects local:N or tcp://HOST:PORT, got {spec!r}")


def open_cluster(spec: str):
    """(client, cluster or None) for --cluster: `local:N` starts a Dask LocalCluster of
    N single-threaded worker processes on this machine, `tcp://HOST:PORT` connects to
    a running scheduler (`dask scheduler`, `dask worker ...`)."""
    check_cluster(spec)
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise ScenarioError("--cluster needs Dask: pip install 'dask[distributed]'") from None
    if spec.startswith("local:"):
        # silence_logs: its workers' notes on tasks they lose and on the scheduler they
        # lose as it closes (Ctrl-C, a loaded machine) are no errors; a task's are raised
        # where its result is read
        cluster = LocalCluster(n_workers=int(spec.partition(":")[2]), threads_per_worker=1,
                               processes=True, dashboard_address=None,
                               silence_logs=logging.CRITICAL)
        client = Client(cluster)
        from ato_nodes.studies.dask_workers import StopsAreTheStudys
        client.register_plugin(StopsAreTheStudys())
        return _with_plugins(client, cluster)
    try:
        return _with_plugins(Client(spec, timeout=10), None)
    except OSError as exc:
        raise ScenarioError(f"--cluster {spec}: no scheduler answers ({exc})") from None


def _with_plugins(client, cluster):
    """(client, cluster) once every worker imports the study's plug-ins; else closed and
    ScenarioError (one line, dask_workers.check_plugins)."""
    from ato_nodes.studies.dask_workers import check_plugins
    try:
        check_plugins(client)
    except BaseException:
        client.close()
        if cluster is not None:
            cluster.close()
        raise
    return client, cluster


@contextlib.contextmanager
def dask_logs_silenced():
    """Dask's log lines in this process (a lost connection's tracebacks from its event
    loop, tasks it cancels) are not shown while they last."""
    loggers = [logging.getLogger(name) for name in list(logging.root.manager.loggerDict)
               if name.partition(".")[0] in ("distributed", "tornado")]
    disabled = [logger.disabled for logger in loggers]
    for logger in loggers:
        logger.disabled = True
    try:
        yield
    finally:
        for logger, before in zip(loggers, disabled, strict=True):
            logger.disabled = before


class Backend:
    """The runs of one study, as a context manager: `workers` local processes (threads
    with `threads`: runs that are processes already), or with `cluster` the workers
    of a Dask cluster; the same function gives the same result on each.

    While it lasts, Ctrl-C and SIGTERM are noted and acted on within INTERRUPT_POLL by
    finished() (a KeyboardInterrupt raised at whatever line runs can land in a
    library's finaliser and be swallowed). Leaving it by an exception stops at once:
    `cancel` is set (stack runs end), the runs under way are cancelled, a cluster is
    closed; a scheduler that stopped answering leaves it as ClusterLost."""

    def __init__(self, workers: int = 1, cluster: str = "", threads: bool = False,
                 cancel: threading.Event | None = None):
        self.workers, self.cluster, self.threads = workers, cluster, threads
        self.cancel = cancel if cancel is not None else threading.Event()
        self.interrupted = False
        self.client = self.local_cluster = None
        self.pool: Executor | None = None
        self.slots_asked = (-math.inf, 1)  # (when, the cluster's threads then)
        self.stack = contextlib.ExitStack()

    def __enter__(self) -> Backend:
        if threading.current_thread() is threading.main_thread():
            for number in (signal.SIGINT, signal.SIGTERM):  # either one stops it
                previous = signal.signal(number, self._on_interrupt)
                self.stack.callback(signal.signal, number, previous)
        try:
            if self.cluster:
                self.client, self.local_cluster = open_cluster(self.cluster)
                self.stack.enter_context(dask_logs_silenced())  # one line says what went wrong
                self.pool = self.client.get_executor(pure=False)
            else:
                self.pool = (ThreadPoolExecutor(self.workers) if self.threads else
                             ProcessPoolExecutor(self.workers, initializer=die_with_parent,
                                                 initargs=(os.getpid(),)))
        except BaseException:
            self.stack.close()
            raise
        return self

    def __exit__(self, kind, error, traceback) -> None:
        with self.stack:
            if error is None:
                self.pool.shutdown(wait=True)
                self._close_cluster()
                return
            lost = self._lost_by(error)
            self._stop()
            if lost:
                raise ClusterLost(f"the Dask scheduler {self.cluster} stopped answering") \
                    from None

    def _lost_by(self, error: BaseException) -> bool:
        """The error says the cluster's scheduler went away: a call to it failed, or a
        task was cancelled or a connection closed as its client stopped running."""
        if self.client is None or not isinstance(error, (CancelledError, OSError)):
            return False
        from distributed.comm import CommClosedError
        return isinstance(error, CommClosedError) or self.client.status != "running"

    def slots(self) -> int:
        """How many runs go at once: the workers, or the cluster's threads now (asked
        of its scheduler at most every SLOTS_REFRESH: workers may come and go)."""
        if self.client is None:
            return self.workers
        if time.monotonic() - self.slots_asked[0] > SLOTS_REFRESH:
            self.slots_asked = (time.monotonic(),
                                max(1, sum(self.client.nthreads().values())))
        return self.slots_asked[1]

    def submit(self, function: Callable, *args: Any) -> Future:
        return self.pool.submit(function, *args)

    def finished(self, waiting: set[Future]) -> set[Future]:
        """Those of `waiting` that have finished, waiting at most INTERRUPT_POLL for
        the first; a Ctrl-C noted meanwhile raises KeyboardInterrupt here."""
        done, _ = wait(waiting, timeout=INTERRUPT_POLL, return_when=FIRST_COMPLETED)
        if self.interrupted:
            raise KeyboardInterrupt
        return done

    def stream(self, function: Callable, tasks: Iterable[tuple[Hashable, tuple]]
               ) -> Iterator[tuple[Hashable, Any]]:
        """(key, function(*args)) for each (key, args) of `tasks` as it finishes (those
        finished together in the tasks' order); only QUEUED_PER_SLOT runs per slot are
        handed out ahead, so `tasks` may be a generator of any length (the memory of
        this process does not grow with it). A run's exception is raised here."""
        tasks = iter(tasks)
        pending: dict[Future, Hashable] = {}
        while True:
            room = QUEUED_PER_SLOT * self.slots() - len(pending)
            for key, args in itertools.islice(tasks, max(room, 0)):
                pending[self.submit(function, *args)] = key
            if not pending:
                return
            done = self.finished(set(pending))
            for future in [future for future in pending if future in done]:
                yield pending.pop(future), future.result()

    def _on_interrupt(self, signum, frame) -> None:
        self.interrupted = True

    def _close_cluster(self) -> None:
        if self.client is not None:
            self.client.close()
        if self.local_cluster is not None:
            self.local_cluster.close()

    def _stop(self) -> None:
        """Stop at once: stack runs told to end, the runs under way cancelled (not
        recorded: a resume runs them again), a cluster closed."""
        self.cancel.set()
        if self.client is None:
            self.pool.shutdown(wait=True, cancel_futures=True)
            return
        if self.client.status == "running":
            self.pool.shutdown(wait=False)  # a ClientExecutor cancels its tasks
        self._close_cluster()


def die_with_parent(parent: int) -> None:
    """A pool worker's start: it is killed when the process that started it dies, even
    by SIGKILL (an orphaned worker, forked, would keep that process's task queue and
    its output directory's lock open forever, and a resume would be refused)."""
    LIBC.prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    if os.getppid() != parent:  # it died before the line above
        os._exit(1)


def show_progress(done: int, total: int, line: str, note: str = "") -> None:
    """A progress line on stderr: on a terminal a bar redrawn in place, with `note`
    (what went wrong) printed above it and kept; else the line (and note) as it is."""
    if sys.stderr.isatty():
        filled = round(BAR_WIDTH * done / max(total, 1))
        if note:
            print(f"\r\033[K{note}", file=sys.stderr)
        print(f"\r\033[K[{'#' * filled}{'.' * (BAR_WIDTH - filled)}] {line}",
              end="" if done < total else "\n", file=sys.stderr, flush=True)
    else:
        print(line + (f" ({note})" if note else ""), file=sys.stderr, flush=True)


class Progress:
    """A study's runs done and its ETA (from this process's pace), on stderr: on a
    terminal after each run; else once per tenth of the study (a log stays short)."""

    STEPS = 10  # lines of a study's progress off a terminal

    def __init__(self, total: int, done: int, what: str):
        self.total, self.done, self.what = total, done, what
        self.fresh = 0  # runs done by this process (the pace)
        self.started = time.monotonic()

    def advance(self) -> None:
        self.done += 1
        self.fresh += 1
        step = self.total / self.STEPS
        if not sys.stderr.isatty() and int(self.done / step) == int((self.done - 1) / step):
            return
        eta = (time.monotonic() - self.started) / self.fresh * (self.total - self.done)
        show_progress(self.done, self.total, f"{self.what} {self.done:5d}/{self.total}  "
                      f"ETA {eta:6.0f} s")

    def end(self) -> None:
        """A study stopped before its end leaves the terminal's bar line: what it says
        next starts on a line of its own."""
        if sys.stderr.isatty() and self.fresh and self.done < self.total:
            print(file=sys.stderr, flush=True)
