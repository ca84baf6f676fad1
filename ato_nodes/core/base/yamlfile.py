"""Reading the files a user gives (scenarios, train presets, lines; strategy and model
files through read_bytes) without letting one exhaust memory or time: a size limit
checked before reading, regular files only, UTF-8 text, no anchors or aliases (an
alias bomb expands a few lines into gigabytes), no duplicate keys (PyYAML keeps the
last one silently), bounded nesting."""

from __future__ import annotations

import stat
from pathlib import Path

import yaml

from .errors import ScenarioError

MAX_BYTES = 1 << 20   # 1 MiB: the largest shipped file is a few kB
MAX_DEPTH = 32


def read_bytes(path: str | Path, what: str, limit: int = MAX_BYTES) -> bytes:
    """The content of a user's regular file of at most `limit` bytes (its size checked
    before it is read, and the read bounded: a file may grow meanwhile); one
    ScenarioError line otherwise."""
    path = Path(path)
    try:
        info = path.stat()
        if not stat.S_ISREG(info.st_mode):
            kind = "a directory" if stat.S_ISDIR(info.st_mode) else "not a regular file"
            raise ScenarioError(f"{what} {path} is {kind}")
        if info.st_size <= limit:
            with path.open("rb") as handle:
                data = handle.read(limit + 1)
    except OSError as exc:
        raise ScenarioError(f"cannot read {what} {path}: {exc.strerror or exc}") from None
    if info.st_size > limit or len(data) > limit:
        raise ScenarioError(f"{what} {path} is larger than {limit / (1 << 20):g} MiB")
    return data


def read_text(path: str | Path, what: str, limit: int = MAX_BYTES) -> str:
    """The UTF-8 text of a user's file, checked as read_bytes checks it."""
    try:
        return read_bytes(path, what, limit).decode("utf-8")
    except UnicodeDecodeError:
        raise ScenarioError(f"{what} {path} is not UTF-8 text") from None


def check_structure(text: str, where: str) -> None:
    """Refuse anchors, aliases, duplicate keys and deep nesting, naming the line."""
    depth = 0
    keys: list[set | None] = []
    expect_key: list[bool] = []
    try:
        for event in yaml.parse(text):
            mark = f"{where} line {event.start_mark.line + 1}"
            if isinstance(event, yaml.AliasEvent) or getattr(event, "anchor", None):
                raise ScenarioError(f"{mark}: YAML anchors and aliases are not accepted")
            if isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
                _as_value(keys, expect_key)
                depth += 1
                if depth > MAX_DEPTH:
                    raise ScenarioError(f"{mark}: nested deeper than {MAX_DEPTH} levels")
                mapping = isinstance(event, yaml.MappingStartEvent)
                keys.append(set() if mapping else None)
                expect_key.append(mapping)
            elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
                depth -= 1
                keys.pop()
                expect_key.pop()
            elif isinstance(event, yaml.ScalarEvent):
                if keys and keys[-1] is not None and expect_key[-1]:
                    if event.value in keys[-1]:
                        raise ScenarioError(f"{mark}: key {event.value!r} is given twice")
                    keys[-1].add(event.value)
                    expect_key[-1] = False
                else:
                    _as_value(keys, expect_key)
    except yaml.YAMLError as exc:
        problem_mark = getattr(exc, "problem_mark", None)
        at = f" line {problem_mark.line + 1}" if problem_mark else ""
        problem = getattr(exc, "problem", None) or "not valid YAML"
        raise ScenarioError(f"{where}{at}: malformed YAML ({problem})") from None


def _as_value(keys: list, expect_key: list) -> None:
    """A value was read in the enclosing mapping: its next scalar is a key again."""
    if keys and keys[-1] is not None:
        expect_key[-1] = True


def load(path: str | Path, what: str):
    """A user's YAML file, read and checked, as Python data."""
    text = read_text(path, what)
    check_structure(text, str(path))
    return yaml.safe_load(text)
