"""The repository passes `ruff check` with ruff.toml's rules (pyflakes, bugbear,
pycodestyle at 100 columns, complexity at most 15): a lint finding fails the suite,
as ament's flake8 test does for ROS packages."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_ruff_finds_nothing():
    result = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache",
                             "--output-format", "concise", "."],
                            cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr
