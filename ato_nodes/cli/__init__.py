"""The project's commands (run_stack, tune, analyze, replay_bag, score_bag) and the
helpers every script shares: errors in one line, checks made before anything starts.

A command starts through start(): its console entry point (ato_nodes.cli.console,
`ros2 run ato_nodes run_stack`) and its script (scripts/run_stack.py) alike.
Importing this package changes nothing; start() takes over the process's signals.
"""

from __future__ import annotations

import argparse
import importlib
import math
import os
import signal
import sys
import textwrap
from pathlib import Path


# Ctrl-C and SIGTERM (a service manager, `timeout`, `kill`) both mean interrupt: the same
# line, exit status 130, whatever was written kept whole.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def start(command: str) -> None:
    """Run ato_nodes.cli.<command>.main() as a program."""
    handle_signals_while_starting()
    importlib.import_module(f"{__name__}.{command}").main()


def handle_signals_while_starting() -> None:
    """A closed pipe ends the output quietly (`score_bag ... | head`), and Ctrl-C or
    SIGTERM means interrupt, even when started from a shell's background job (which hands
    its children SIGINT ignored); interrupted_quietly() takes over in main()."""
    signal.signal(signal.SIGPIPE, signal.SIG_DFL)
    for number in STOP_SIGNALS:
        signal.signal(number, _interrupted_while_starting)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)  # held since scripts/_cli.py


def _interrupted_while_starting(signum, frame) -> None:
    """A stop before main() runs (while importing): nothing started, nothing to keep."""
    os.write(2, b"interrupted\n")
    os._exit(130)


def argument_parser(doc: str, plugins: bool = True) -> argparse.ArgumentParser:
    """A command's parser from its module docstring: the first paragraph, whole, as the
    description; the rest (usage examples) as the epilog, as written. With `plugins`,
    its --plugin option (PluginOption)."""
    description, _, rest = doc.strip().partition("\n\n")
    parser = argparse.ArgumentParser(
        description=textwrap.fill(" ".join(description.split()), 79), epilog=rest,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    if plugins:
        parser.add_argument("--plugin", action=PluginOption, metavar="MODULE",
                            help="import a plug-in's controller or profile kinds (MODULE or "
                                 "MODULE:ATTRIBUTE; docs/plugins.md) before anything is "
                                 "read (repeatable)")
    return parser


class PluginOption(argparse.Action):
    """--plugin MODULE: the plug-in imported (and checked) as the option is read, so the
    scenario, --set and --params that follow know its kinds; the runs that use them name
    it in run.plugins, and every process of theirs imports it. A plug-in refused is one
    line, exit 2, before anything starts."""

    def __call__(self, parser, namespace, value, option_string=None) -> None:
        from ato_nodes.core.base.errors import ScenarioError
        from ato_nodes.core.config.schema import load_plugins
        try:
            load_plugins((value,))
        except ScenarioError as exc:
            fail(f"--plugin: {exc}")
        setattr(namespace, self.dest, [*(getattr(namespace, self.dest) or []), value])


def fail(message: str, status: int = 2) -> None:
    print(f"error: {message}", file=sys.stderr)
    sys.exit(status)


def new_directory(path: Path, what: str = "--out") -> None:
    """Fail (one line, exit 2) unless `path` can be created as a new directory and
    written in: checked before anything starts, by making it (with a file in it) and
    removing it again, not when the first file is written."""
    if any(len(part.encode()) > 255 for part in path.parts):
        fail(f"{what} {path}: a name in it is longer than 255 bytes")
    if len(os.fsencode(path.absolute())) >= os.pathconf("/", "PC_PATH_MAX"):
        fail(f"{what}: the path is longer than the system allows")
    try:
        if path.exists() or path.is_symlink():
            fail(f"{what} {path} exists already; choose another")
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        fail(f"{what} {path}: cannot create {path.parent}: {exc.strerror or exc}")
    if not path.parent.is_dir() or not os.access(path.parent, os.W_OK | os.X_OK):
        fail(f"{what} {path}: {path.parent} is not a writable directory")
    probe = path / ".write-test"
    held = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)  # a stop waits: none left
    try:
        path.mkdir()
        try:
            probe.write_bytes(b"")
            probe.unlink()
        finally:
            path.rmdir()
    except OSError as exc:
        fail(f"{what} {path}: cannot be written: {exc.strerror or exc}")
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, held)


def seconds(value: float | None, what: str) -> None:
    """A wall-time option: positive and finite, or not given."""
    if value is not None and not (math.isfinite(value) and value > 0):
        fail(f"{what} must be a positive number of seconds, not {value}")


def interrupted_quietly(main):
    """Run a script's main(); a Ctrl-C or SIGTERM outside its own handling is one line,
    exit 130: either raises KeyboardInterrupt, so both take the same way out."""
    for number in STOP_SIGNALS:
        signal.signal(number, signal.default_int_handler)
    try:
        main()
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        sys.exit(130)
    finally:  # its outcome is decided: a Ctrl-C while the interpreter exits changes nothing.
        # Ignored, not only blocked: the mask is this thread's, and the interpreter's exit
        # puts Python's handlers back to the default (death by the signal) while another
        # thread (the fork server's reader) could still take one.
        for number in STOP_SIGNALS:
            signal.signal(number, signal.SIG_IGN)
