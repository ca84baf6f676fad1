"""A Dask scheduler and two workers started as separate processes, as the README and
docs/reference.md start them, for the tests of tune.py and the studies on a cluster."""

import contextlib
import json
import subprocess
import sys
import time
from pathlib import Path

BIN = Path(sys.executable).parent


@contextlib.contextmanager
def scheduler_and_workers(directory: Path):
    """A scheduler (on loopback) and two workers as separate processes, as
    docs/reference.md starts them: (address, scheduler, workers); every one still
    running at the end is killed."""
    address_file = directory / "scheduler.json"
    processes = [subprocess.Popen([str(BIN / "dask"), "scheduler", "--scheduler-file",
                                   str(address_file), "--no-dashboard", "--port", "0",
                                   "--host", "127.0.0.1"],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        deadline = time.monotonic() + 60
        while not address_file.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        address = json.loads(address_file.read_text())["address"]
        processes += [subprocess.Popen([str(BIN / "dask"), "worker", address, "--nthreads", "1",
                                        "--no-nanny", "--no-dashboard"], cwd=directory,
                                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                      for _ in range(2)]
        yield address, processes[0], processes[1:]
    finally:
        for process in processes:
            if process.poll() is None:
                process.kill()
                process.wait()
