"""Shared by the scripts: make the repo importable and report errors in one line."""

from __future__ import annotations

import signal
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
signal.signal(signal.SIGPIPE, signal.SIG_DFL)  # `score_bag.py ... | head` ends quietly


def fail(message: str, status: int = 2) -> None:
    print(f"error: {message}", file=sys.stderr)
    sys.exit(status)
