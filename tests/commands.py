"""How the tests run the project's programs, as a user does: the package's commands
(ato_nodes/cli: run_stack, tune, analyze, replay_bag, score_bag) by their console entry
points (scripts/setup.sh installs them beside the interpreter), the checkout's other
tools by their script in scripts/."""

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
