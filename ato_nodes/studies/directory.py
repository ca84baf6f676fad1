"""A study's output directory as a resume finds it, shared by the tuner and the study
scripts: held by one process at a time, and holding the settings and conditions it
was started with (a resume under others is refused before anything is written)."""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
from pathlib import Path
from typing import Any, TextIO

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.schema import FILE_PARAMETERS


def hold_directory(out: Path, what: str) -> TextIO:
    """An exclusive lock on OUT for this `what`'s (a tuning's, a study's) lifetime
    (released when the process ends, however it ends): two never write one directory."""
    handle = (out / ".lock").open("a+")
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        handle.seek(0)
        holder = handle.read().strip() or "another process"
        handle.close()
        raise ScenarioError(f"{out} is being written by another {what} (pid {holder}); wait "
                            "for it or use another --out") from None
    return handle


def create_and_hold(out: Path, what: str) -> TextIO:
    """OUT created if new (one line if it cannot be) and held (hold_directory)."""
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ScenarioError(f"cannot create {out}: {exc.strerror or exc}") from None
    return hold_directory(out, what)


def name_holder(lock: TextIO) -> None:
    """This process's pid in the held lock file (what a refused second one names)."""
    lock.seek(0)
    lock.truncate()
    lock.write(str(os.getpid()))
    lock.flush()


def conditions_digest(values: dict[str, Any], settings: dict[str, Any]) -> str:
    """A digest of everything that makes a recorded result mean what it means: every
    parameter of the base run, the text of its line and table files, and the study's
    `settings`."""
    files = {}
    for name in FILE_PARAMETERS:
        if values.get(name):
            try:
                files[name] = hashlib.sha256(Path(values[name]).read_bytes()).hexdigest()
            except OSError:
                files[name] = "unreadable"
    text = json.dumps({"values": values, "files": files, "settings": settings},
                      sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def check_same_settings(out: Path, settings_file: Path, described: str, what: str,
                        changes: str, instead: str) -> None:
    """A resumed OUT's settings file must hold `described` (JSON text): the same
    settings under the same conditions; else a ScenarioError naming what may have
    `changes` and what to do `instead`."""
    try:
        before = json.loads(settings_file.read_text())
    except (OSError, json.JSONDecodeError):
        raise ScenarioError(f"{settings_file} is not readable JSON; {instead}") from None
    if before != json.loads(described):
        raise ScenarioError(f"{out} holds a {what} with other settings or conditions "
                            f"({changes}); resume it with the same options or {instead}")
