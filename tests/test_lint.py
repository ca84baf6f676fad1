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


LONGEST_FUNCTION = 50  # lines from `def` to the function's last line


def test_no_function_is_longer_than_fifty_lines():
    """A function that does not fit on a screen does more than its name says."""
    import ast
    long = []
    for folder in ("ato_nodes", "scripts", "benchmarks", "launch"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    length = node.end_lineno - node.lineno + 1
                    if length > LONGEST_FUNCTION:
                        long.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name} "
                                    f"({length} lines)")
    assert not long, "; ".join(long)
