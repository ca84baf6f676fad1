"""The last word on a process whose middleware teardown stalls.

A call stalled inside the middleware (a node destroyed, a context shut down) holds the
interpreter lock, so no Python thread can end the process. faulthandler's watchdog runs
without the lock but can only exit with status 1. Once a process has done its work (its
bag closed, its status known), a stall after it should not turn a good run into a failed
one: `exit_after` has every thread's stack written on stderr (faulthandler) and then the
process ended with the status it had earned, by a POSIX timer whose expiry calls libc's
_exit on a thread of its own (SIGEV_THREAD), which needs no interpreter.
"""

from __future__ import annotations

import ctypes
import faulthandler
import sys

CLOCK_MONOTONIC = 1
SIGEV_THREAD = 2
EXIT_DELAY = 0.5  # s after the stacks are written: faulthandler's dump takes milliseconds
# s a process's teardown (its last records flushed, a bag closed, the middleware shut
# down) may take before it gives up on it: every Python thread's stack on stderr, then exit
# status 1 while it still holds its work (faulthandler's watchdog runs without the
# interpreter lock, which a call stalled in the middleware holds), its own status once
# that is released (exit_after), rather than a process never exiting
TEARDOWN_LIMIT = 10.0


class _ThreadNotify(ctypes.Structure):
    _fields_ = [("function", ctypes.c_void_p), ("attributes", ctypes.c_void_p)]


class _SigeventTail(ctypes.Union):
    _fields_ = [("padding", ctypes.c_int * 12), ("thread", _ThreadNotify)]


class _Sigevent(ctypes.Structure):
    """glibc's struct sigevent: the value handed to the function (a union sigval, passed
    in the first argument register, so _exit reads it as its int), then how to notify."""
    _fields_ = [("value", ctypes.c_ssize_t), ("signal", ctypes.c_int),
                ("notify", ctypes.c_int), ("tail", _SigeventTail)]


class _Timespec(ctypes.Structure):
    _fields_ = [("seconds", ctypes.c_long), ("nanoseconds", ctypes.c_long)]


class _Itimerspec(ctypes.Structure):
    _fields_ = [("interval", _Timespec), ("first", _Timespec)]


_libc = ctypes.CDLL(None, use_errno=True)
_armed: list = []  # the one exit timer of the process, with its status


def exit_after(seconds: float, status: int) -> None:
    """In `seconds`, every thread's stack on stderr; EXIT_DELAY later the process ends
    with `status` unless it has exited by then. Replaces an earlier faulthandler watchdog
    (an exit with status 1) and any earlier exit_after."""
    sys.stdout.flush()
    sys.stderr.flush()
    faulthandler.dump_traceback_later(seconds, exit=False)
    if _armed and _armed[0][0] != status:
        _libc.timer_delete(_armed.pop()[1])
    if not _armed:
        _armed.append((status, _new_exit_timer(status)))
    _arm(_armed[0][1], seconds + EXIT_DELAY)


def _new_exit_timer(status: int) -> ctypes.c_void_p:
    event = _Sigevent(value=status, notify=SIGEV_THREAD)
    event.tail.thread.function = ctypes.cast(_libc._exit, ctypes.c_void_p).value
    timer = ctypes.c_void_p()
    if _libc.timer_create(CLOCK_MONOTONIC, ctypes.byref(event), ctypes.byref(timer)) != 0:
        raise OSError(ctypes.get_errno(), "timer_create")
    return timer


def _arm(timer: ctypes.c_void_p, seconds: float) -> None:
    whole = int(seconds)
    due = _Itimerspec(first=_Timespec(whole, int((seconds - whole) * 1e9)))
    if _libc.timer_settime(timer, 0, ctypes.byref(due), None) != 0:
        raise OSError(ctypes.get_errno(), "timer_settime")
