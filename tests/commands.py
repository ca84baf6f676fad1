"""How the tests run the project's programs, as a user does: the package's commands
(ato_nodes/cli: run_stack, tune, analyze, replay_bag, score_bag) by their console entry
points (scripts/setup.sh installs them beside the interpreter), the checkout's other
tools by their script in scripts/."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
COMMANDS = {path.stem for path in (ROOT / "ato_nodes" / "cli").glob("*.py")} - {
    "__init__", "console"}


def invocation(name: str) -> list[str]:
    """The argv that runs `name`: a command ("run_stack") or a script ("repair_bag.py")."""
    stem = name.removesuffix(".py")
    if stem in COMMANDS:
        return [str(Path(sys.executable).with_name(stem))]
    return [sys.executable, str(ROOT / "scripts" / f"{stem}.py")]


def run_stack(scenario: str, bag: Path, overrides: list[str]) -> None:
    """Run `scenario` through the stack with `overrides` (NAME=VALUE), recorded to `bag`;
    the run must end well (its output in the failure's message)."""
    done = subprocess.run([*invocation("run_stack"), "--scenario", scenario, "--out", str(bag),
                           *(f"--set={item}" for item in overrides)],
                          capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert done.returncode == 0, done.stdout + done.stderr


def script(name: str, *args, timeout=300) -> subprocess.CompletedProcess:
    """`name` (a command or a script) run with `args` from the checkout, its output kept."""
    return subprocess.run([*invocation(name), *map(str, args)],
                          capture_output=True, text=True, timeout=timeout, cwd=ROOT)


def one_line_exit_2(result: subprocess.CompletedProcess, *words) -> str:
    """The refusal the project promises for bad input: exit 2, one line on stderr (no
    traceback) holding every one of `words`; that line."""
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2, result.stdout + result.stderr
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    for word in words:
        assert word in lines[0], lines[0]
    return lines[0]
