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
