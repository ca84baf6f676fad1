"""Reading the YAML files a user gives (scenarios, train presets, lines) without
letting one exhaust memory or time: a size limit, regular files only, UTF-8 text,
no anchors or aliases (an alias bomb expands a few lines into gigabytes), no
duplicate keys (PyYAML keeps the last one silently), bounded nesting."""

from __future__ import annotations

import stat
from pathlib import Path

import yaml

from .errors import ScenarioError

MAX_BYTES = 1 << 20   # 1 MiB: the largest shipped file is a few kB
MAX_DEPTH = 32


def read_text(path: str | Path, what: str) -> str:
    """The text of a user's file, checked; one ScenarioError line otherwise."""
    path = Path(path)
    try:
        info = path.stat()
        if not stat.S_ISREG(info.st_mode):
            raise ScenarioError(f"{what} {path} is not a regular file")
        with path.open("rb") as handle:
            data = handle.read(MAX_BYTES + 1)
    except OSError as exc:
        raise ScenarioError(f"cannot read {what} {path}: {exc.strerror or exc}") from None
    if len(data) > MAX_BYTES:
        raise ScenarioError(f"{what} {path} is larger than {MAX_BYTES >> 20} MiB")
    try:
        return data.decode("utf-8")
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
