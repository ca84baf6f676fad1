"""Waiting on a command by the progress lines it prints on stderr (no fixed sleep)."""

import selectors
import subprocess
import time
from typing import Callable


def read_progress_until(process: subprocess.Popen, done: Callable[[], bool],
                        seconds: float = 300) -> list[str]:
    """Read `process`'s stderr line by line until done() holds (within `seconds`); it
    must still be running then. The lines read."""
    deadline = time.monotonic() + seconds
    lines = []
    with selectors.DefaultSelector() as selector:
        selector.register(process.stderr, selectors.EVENT_READ)
        while not done():
            assert time.monotonic() < deadline and process.poll() is None, \
                ["the command ended (or took too long) before it could be stopped", *lines]
            if selector.select(timeout=deadline - time.monotonic()):
                lines.append(process.stderr.readline())
    return lines
