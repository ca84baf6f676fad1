"""The README's commands run as written (scripts/check_readme.py): every runnable block is
found, a failing command is reported as one, and the quick ones pass."""

import re
import subprocess
from pathlib import Path

import pytest
from commands import invocation

ROOT = Path(__file__).resolve().parents[1]
CHECK = [*invocation("check_readme")]


def check(*args, timeout=120):
    return subprocess.run([*CHECK, *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT)


def test_every_runnable_block_of_the_readme_is_parsed():
    fences = {number for number, line in enumerate((ROOT / "README.md").read_text()
                                                  .splitlines(), 1)
              if line.startswith("```") and "runnable" in line}
    listing = check("--list")
    assert listing.returncode == 0, listing.stderr
    blocks = {int(match) for match in re.findall(r"^README\.md:\d+ block (\d+)", listing.stdout,
                                                 re.M)}
    assert fences and blocks == fences
    quick = check("--list", "--quick").stdout
    assert quick and " slow:" not in quick and "scripts/setup.sh" not in quick


def test_each_command_passes_or_fails_with_its_reason(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text("```sh runnable\ntrue\necho first \\\n  second\n"
                      "echo broken >&2; exit 3\n```\n\n```sh\nnot marked: never run\n```\n")
    result = check("--readme", readme)
    assert result.returncode == 1
    lines = result.stdout.splitlines()
    assert [line.split()[0] for line in lines[:3]] == ["pass", "pass", "FAIL"]
    assert lines[1].endswith("README.md:3  echo first second")
    assert lines[3].strip() == "exit 3: broken"
    assert lines[-1].startswith("2 of 3 commands pass")


@pytest.mark.parametrize("text, problem", [
    ("```sh runnable quick\ntrue\n```\n", "say ```LANGUAGE runnable [slow]"),
    ("```sh runnable\ntrue\n", "the block is never closed"),
    ("```sh runnable\n\n```\n", "the runnable block holds no command"),
])
def test_a_malformed_block_is_one_line_and_exit_2(tmp_path, text, problem):
    readme = tmp_path / "README.md"
    readme.write_text(text)
    result = check("--readme", readme)
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr.startswith(f"error: {readme}:1: {problem}")
    assert len(result.stderr.splitlines()) == 1


@pytest.mark.integration
def test_the_quick_commands_of_the_readme_pass():
    """Short runs through the stack (each takes its ROS domain through the launcher's
    lock), scoring, reports, exports, small tunings and replays."""
    result = check("--quick", timeout=900)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "FAIL" not in result.stdout and re.search(r"^(\d+) of \1 commands pass",
                                                     result.stdout, re.M)
