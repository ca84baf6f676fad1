"""ato-check-node: a node of the user's alone against the contract, one verdict per rule;
each rule found broken in a node made to break it, and kept by a node that keeps them."""

import subprocess
import sys
from pathlib import Path

import pytest

from ato_nodes.cli.check_node import RULES
from commands import invocation, one_line_exit_2

pytestmark = pytest.mark.integration
ROOT = Path(__file__).resolve().parents[1]
CHECK = invocation("check_node")
BROKEN = [sys.executable, str(ROOT / "tests" / "data" / "broken_node.py")]


def check(*arguments) -> tuple[int, dict[str, str]]:
    done = subprocess.run([*CHECK, "controller", *arguments], capture_output=True, text=True,
                          timeout=180, cwd=ROOT)
    verdicts = {}
    for line in done.stdout.splitlines():
        verdict, said = line[:6].strip(), line[8:]  # "kept  " or "broken", two spaces
        rule = next(rule for rule in RULES if said.startswith(rule))
        verdicts[rule] = verdict.strip() + said[len(rule):]
    assert list(verdicts) == list(RULES), done.stdout + done.stderr
    return done.returncode, verdicts


def running_with(mark: str) -> list[str]:
    """Processes whose command line holds `mark`."""
    found = []
    for entry in Path("/proc").iterdir():
        try:
            if entry.name.isdigit() and mark in (entry / "cmdline").read_bytes().decode():
                found.append(entry.name)
        except OSError:
            continue
    return found


def test_a_node_that_keeps_the_contract_keeps_every_rule():
    status, verdicts = check("--set", "controller.kind=pid", "--set", "controller.preview=2",
                             "--", sys.executable, str(ROOT / "tests" / "data" / "external_pid.py"))
    assert status == 0 and set(verdicts.values()) == {"kept"}, verdicts


@pytest.mark.parametrize("flaw, rule, said", [
    ("no-parameters", "parameters announced", "no 'parameters controller {JSON}'"),
    ("never-ready", "ready announced", "no 'ready controller' within"),
    ("no-clock", "/clock used", "no subscription of /clock"),
    ("latest-horizon", "a command per step, paired correctly", "depends on when its horizon"),
    ("unnamed-outputs", "outputs named", "1 values under 0 names"),
    ("deaf", "shuts down on request", "still running"),
])
def test_a_node_that_breaks_a_rule_is_told_which_and_left_stopped(tmp_path, flaw, rule, said):
    status, verdicts = check("--", *BROKEN, flaw, str(tmp_path))
    assert status == 2
    assert verdicts[rule].startswith("broken: ") and said in verdicts[rule], verdicts[rule]
    others = {verdicts[other] for other in RULES if other != rule}
    assert others == ({"broken: not checked (never ready)", "kept"} if flaw == "never-ready"
                      else {"kept"}), verdicts
    assert running_with(str(tmp_path)) == []


@pytest.mark.parametrize("arguments, words", [
    (["profile", "--", "true"], ["only a controller node"]),
    (["controller"], ["command after --"]),
    (["controller", "--", "no-such-command-here"], ["no-such-command-here", "not found"]),
    (["controller", "--set", "pid.kp=-1", "--", "true"], ["pid.kp"]),
])
def test_a_bad_check_is_refused_in_one_line(arguments, words):
    one_line_exit_2(subprocess.run([*CHECK, *arguments], capture_output=True, text=True,
                                   timeout=60, cwd=ROOT), *words)
