"""The commands as console entry points (setup.py): declared, importable, and, where the
package is installed (scripts/setup.sh: pip install -e .), the same as their scripts."""

import importlib
import runpy
import subprocess
import sys
from pathlib import Path

import pytest
import setuptools

from test_bag_integrity import write

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent


def declared_console_scripts(monkeypatch) -> dict[str, str]:
    """name -> "module:attribute", as setup.py hands them to setuptools."""
    captured = {}
    monkeypatch.setattr(setuptools, "setup", captured.update)
    monkeypatch.chdir(ROOT)
    runpy.run_path(str(ROOT / "setup.py"))
    return dict(line.replace(" ", "").split("=") for line in
                captured["entry_points"]["console_scripts"])


def commands(monkeypatch) -> dict[str, str]:
    """The ato_nodes.cli commands the declared entry points start, by command (an entry
    point of another name, `ato-check-node`, is the same command as `check_node`)."""
    return {target.split(":")[1]: target for target in
            declared_console_scripts(monkeypatch).values() if target.startswith("ato_nodes.cli.")}


def test_every_script_of_a_command_is_a_declared_entry_point(monkeypatch):
    declared = commands(monkeypatch)
    shims = {path.stem for path in (ROOT / "scripts").glob("*.py")
             if '_cli.start("' in path.read_text()}
    assert shims and shims == set(declared)


def test_every_entry_point_imports_to_a_callable_and_its_command_has_a_main(monkeypatch):
    for name, target in declared_console_scripts(monkeypatch).items():
        module, attribute = target.split(":")
        assert callable(getattr(importlib.import_module(module), attribute)), name
    for name in commands(monkeypatch):
        assert callable(importlib.import_module(f"ato_nodes.cli.{name}").main), name


def test_importing_the_commands_leaves_the_signals_alone(monkeypatch):
    import signal
    before = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGPIPE)
    for name in commands(monkeypatch):
        importlib.import_module(f"ato_nodes.cli.{name}")
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGPIPE)) == before


@pytest.mark.skipif(not (BIN / "score_bag").exists(),
                    reason="package not installed in this environment (pip install -e .)")
@pytest.mark.slow
def test_the_installed_command_scores_a_bag_as_the_script_does(tmp_path):
    bag = tmp_path / "small"
    write(bag, 40)
    missing = tmp_path / "absent"
    results = {how: [subprocess.run([*how, str(path)], capture_output=True, text=True,
                                    cwd=tmp_path, timeout=60) for path in (bag, missing)]
               for how in ((str(BIN / "score_bag"),),
                           (sys.executable, str(ROOT / "scripts" / "score_bag.py")))}
    (command_ok, command_bad), (script_ok, script_bad) = results.values()
    assert command_ok.returncode == 0 and "steps            40" in command_ok.stdout
    assert (command_ok.stdout, command_ok.stderr) == (script_ok.stdout, script_ok.stderr)
    assert command_bad.returncode == script_bad.returncode == 2
    assert command_bad.stderr == script_bad.stderr == f"error: {missing} does not exist\n"


def test_once_a_command_has_its_outcome_a_signal_cannot_change_its_exit_status():
    """interrupted_quietly() leaves SIGINT and SIGTERM ignored, process-wide: blocking them
    in the main thread alone let a late Ctrl-C reach another thread once the interpreter
    had put the default handler back (the process then died of the signal: exit -2)."""
    code = ("import os, signal, threading, time; from ato_nodes import cli\n"
            "threading.Thread(target=time.sleep, args=(5,), daemon=True).start()\n"
            "cli.interrupted_quietly(lambda: None)\n"
            "os.kill(os.getpid(), signal.SIGINT)  # taken by the thread that does not block it\n"
            "sum(range(10**6))  # bytecodes, at which Python runs a handler\n"
            "raise SystemExit(7)\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 7, result.stderr
