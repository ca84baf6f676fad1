#!/usr/bin/env python3
"""Run the README's commands as written and report each: pass, or fail with one line why.

    python scripts/check_readme.py [--quick] [--only TEXT] [--list] [--readme FILE]

A runnable block is a fenced block whose info string says so, after the language (GitHub
shows neither): ```sh runnable for one that takes seconds, ```sh runnable slow for one that
takes minutes (a full run, a tuning, the test suite). Each line of it is a command (a
trailing backslash continues it); a command passes when it exits 0.

The blocks run in README order in one fresh copy of the checkout (the files git tracks
or would track, nothing under bags/), so a block may use what an earlier one wrote. The
copy shares the checkout's .venv unless a command it runs is scripts/setup.sh: that
installs the package editable, into the copy's own .venv, which it then builds.
"""

from __future__ import annotations

import re
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import _cli

ROOT = Path(__file__).resolve().parents[1]
FENCE = re.compile(r"```(?P<info>.*)")
RUNNABLE = re.compile(r"\S+ runnable(?P<slow> slow)?")  # the info string of a runnable block
TIMEOUT = {False: 300.0, True: 3600.0}  # wall seconds a quick / slow command may take
SETUP = "scripts/setup.sh"


@dataclass(frozen=True)
class Command:
    block: int  # the line of its block's fence in the README, 1-based
    line: int  # the line it starts on
    text: str
    slow: bool


def runnable_commands(readme: Path) -> list[Command]:
    """Every command of every runnable block, in order; a block never closed, or one that
    says runnable in another way, or holds no command, fails (one line, exit 2)."""
    lines = readme.read_text().splitlines()
    commands, fence = [], None  # fence: (its line number, runnable, slow) while in a block
    start = None  # the line a command continued over several lines starts on
    for number, line in enumerate(lines, 1):
        opened = FENCE.fullmatch(line.strip())
        if fence is None:
            if opened:
                info = opened["info"].strip()
                runnable = RUNNABLE.fullmatch(info)
                if "runnable" in info and not runnable:
                    fail_at(readme, number, f"say ```LANGUAGE runnable [slow], not ```{info}")
                fence = (number, bool(runnable), bool(runnable and runnable["slow"]), len(commands))
            continue
        fenced_at, runnable, slow, found = fence
        if opened and not opened["info"].strip():
            if runnable and len(commands) == found:
                fail_at(readme, fenced_at, "the runnable block holds no command")
            fence = None
        elif runnable:
            start = start or number
            if not line.endswith("\\"):  # bash joins the continued lines itself
                if "\n".join(lines[start - 1:number]).strip():
                    commands.append(Command(fenced_at, start, "\n".join(lines[start - 1:number]),
                                            slow))
                start = None
    if fence is not None:
        fail_at(readme, fence[0], "the block is never closed")
    return commands


def fail_at(readme: Path, line: int, problem: str) -> None:
    _cli.fail(f"{readme}:{line}: {problem}")


def shown(command: Command) -> str:
    return " ".join(command.text.replace("\\\n", " ").split())


def fresh_copy(destination: Path, own_venv: bool) -> None:
    listed = subprocess.run(["git", "ls-files", "-z", "--cached", "--others",
                             "--exclude-standard"], cwd=ROOT, capture_output=True,
                            check=True).stdout.decode().split("\0")
    for name in listed:
        source = ROOT / name
        if name and source.is_file() and not name.startswith("bags/"):
            (destination / name).parent.mkdir(parents=True, exist_ok=True)
            (destination / name).write_bytes(source.read_bytes())
            (destination / name).chmod(source.stat().st_mode)
    (destination / "bags").mkdir(exist_ok=True)
    if not own_venv:
        (destination / ".venv").symlink_to(ROOT / ".venv")


def reason(result: subprocess.CompletedProcess) -> str:
    said = [line for line in (result.stderr + result.stdout).splitlines() if line.strip()]
    return f"exit {result.returncode}: {said[-1].strip() if said else 'no output'}"


def run(command: Command, where: Path) -> tuple[bool, str]:
    try:
        result = subprocess.run(["bash", "-c", command.text], cwd=where, capture_output=True,
                                text=True, timeout=TIMEOUT[command.slow],
                                stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        return False, f"still running after {TIMEOUT[command.slow]:g} s"
    return result.returncode == 0, "" if result.returncode == 0 else reason(result)


def main() -> None:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("--readme", type=Path, default=ROOT / "README.md")
    parser.add_argument("--quick", action="store_true", help="skip the slow blocks")
    parser.add_argument("--only", metavar="TEXT",
                        help="only the blocks with a command containing TEXT (and every quick "
                        "block before them, whose output they may need)")
    parser.add_argument("--list", action="store_true", help="list the commands, run nothing")
    args = parser.parse_args()
    if not args.readme.is_file():
        _cli.fail(f"{args.readme} is not a file")
    commands = runnable_commands(args.readme)
    if args.quick:
        commands = [command for command in commands if not command.slow]
    if args.only is not None:
        chosen = {command.block for command in commands if args.only in shown(command)}
        if not chosen:
            _cli.fail(f"no runnable command contains {args.only!r}")
        commands = [command for command in commands if command.block in chosen
                    or (not command.slow and command.block < max(chosen))]
    if args.list:
        for command in commands:
            print(f"{args.readme.name}:{command.line} block {command.block}"
                  f"{' slow' if command.slow else ''}: {shown(command)}")
        return
    failed = 0
    started = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="check-readme-") as copy:
        fresh_copy(Path(copy), own_venv=any(SETUP in command.text for command in commands))
        for command in commands:
            began = time.monotonic()
            ok, why = run(command, Path(copy))
            failed += not ok
            print(f"{'pass' if ok else 'FAIL'} {time.monotonic() - began:7.1f} s  "
                  f"{args.readme.name}:{command.line}  {shown(command)}"
                  + (f"\n     {why}" if why else ""), flush=True)
    print(f"{len(commands) - failed} of {len(commands)} commands pass "
          f"({time.monotonic() - started:.0f} s)")
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
