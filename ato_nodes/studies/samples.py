"""A study of numbered samples that streams and resumes (robustness.py's trains; any
study whose runs are known by their number and the study's settings).

Its output directory holds study.json (the settings and a digest of the conditions
they were prepared under) and samples.csv: one row per finished sample, appended and
flushed as it finishes, so a Ctrl-C or a kill loses no finished sample, and a resume
(under the same settings and conditions, else refused before anything is written)
runs only the samples the file lacks. The study's report is made from the file at
the end, in sample order, whatever order the samples finished in and however many
times the study was resumed: the same rows and report as one uninterrupted run.
"""

from __future__ import annotations

import csv
import os
import sys
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.results import jsontext
from ato_nodes.studies.directory import (check_same_settings, conditions_digest,
                                         create_and_hold, hold_directory, name_holder)

NUMBER = "sample"  # the first column: the sample's number, 0 to samples - 1


class SampleFailed(RuntimeError):
    """A sample that cannot run (its drawn values refused): the study stops there, its
    finished samples kept."""


class SampleFile:
    """samples.csv: a header (`columns`, NUMBER first), then one row per finished
    sample, a value in full precision (repr), an empty cell for an index the sample
    does not have. read() checks and changes nothing; start() writes."""

    def __init__(self, path: Path, columns: Mapping[str, type]):
        self.path, self.columns = path, {NUMBER: int, **columns}
        self.done: set[int] = set()
        self.keep = 0  # bytes of the file that hold whole rows (read())
        self.handle = None

    def read(self, samples: int) -> None:
        """The finished samples of a resumed file; a last row cut short (the process
        was killed while writing it) is dropped: that sample runs again."""
        with self.path.open(newline="") as handle:
            if handle.readline() != self._line(list(self.columns)):
                raise ScenarioError(f"{self.path}: its header is not this study's columns; "
                                    "use a new --out")
            self.keep = handle.tell()
            for number, line in enumerate(iter(handle.readline, ""), 2):
                try:
                    row = self._parsed(line)
                except ValueError as exc:
                    if handle.read() == "" and not line.endswith("\n"):  # cut short
                        print(f"warning: {self.path} line {number} is incomplete; that "
                              "sample runs again", file=sys.stderr)
                        break
                    raise ScenarioError(f"{self.path} line {number}: {exc}; remove that line "
                                        "or use a new --out") from None
                if not 0 <= row[NUMBER] < samples or row[NUMBER] in self.done:
                    raise ScenarioError(f"{self.path} line {number}: sample {row[NUMBER]} "
                                        "is not one this study lacks; use a new --out")
                self.done.add(row[NUMBER])
                self.keep = handle.tell()

    def start(self, resume: bool) -> None:
        """Open for appending: what read() kept on resume, else a new file."""
        if resume:
            os.truncate(self.path, self.keep)
            self.handle = self.path.open("a", newline="")
        else:
            self.handle = self.path.open("w", newline="")
            self.handle.write(self._line(list(self.columns)))
            self.handle.flush()

    def append(self, row: Mapping[str, Any]) -> None:
        self.handle.write(self._line(
            ["" if row.get(name) is None else repr(kind(row[name]))
             for name, kind in self.columns.items()]))
        self.handle.flush()
        self.done.add(row[NUMBER])

    def close(self) -> None:
        if self.handle is not None:
            self.handle.close()

    def table(self) -> tuple[np.ndarray, np.ndarray]:
        """(values, present) of a study whose every sample is in the file: one row per
        sample in sample order, one column per
        column (a float; int columns hold integers, exact below 2**53); present is
        False where the sample has no value."""
        count = len(self.done)
        values = np.full((count, len(self.columns)), np.nan)
        present = np.zeros((count, len(self.columns)), dtype=bool)
        with self.path.open(newline="") as handle:
            handle.readline()
            for line in handle:
                row = self._parsed(line)
                for column, value in enumerate(row.values()):
                    present[row[NUMBER], column] = value is not None
                    values[row[NUMBER], column] = np.nan if value is None else value
        return values, present

    def rows(self, values: np.ndarray, present: np.ndarray) -> Iterator[dict[str, Any]]:
        """Each sample's row (table()'s) as a dict of the values it has."""
        for sample_values, sample_present in zip(values, present, strict=True):
            yield {name: kind(value) for (name, kind), value, has in
                   zip(self.columns.items(), sample_values, sample_present, strict=True) if has}

    def _parsed(self, line: str) -> dict[str, Any]:
        cells = next(csv.reader([line]))
        if len(cells) != len(self.columns) or not line.endswith("\n"):
            raise ValueError(f"{len(cells)} cells, not {len(self.columns)}")
        return {name: kind(cell) if cell else None
                for (name, kind), cell in zip(self.columns.items(), cells, strict=True)}

    @staticmethod
    def _line(cells: list[str]) -> str:
        return ",".join(cells) + "\n"  # the names and numbers need no quoting


class SampleStudy:
    """A study of `samples` numbered samples in OUT (see the module), opened before
    anything runs: everything that can refuse it (another process writing OUT, a
    resume under other settings or conditions, a samples file that is not this
    study's) is checked before anything in OUT is written."""

    SETTINGS = "study.json"

    def __init__(self, out: Path, settings: dict[str, Any], values: dict[str, Any],
                 columns: Mapping[str, type], samples: int, resume: bool):
        self.out, self.samples, self.started = out, samples, False
        self.described = jsontext.dumps(
            {**settings, "conditions": conditions_digest(values, settings)}, indent=2)
        self.file = SampleFile(out / "samples.csv", columns)
        self.lock = None
        self.resume = resume and (out / self.SETTINGS).exists()
        if self.resume:  # read and checked; begin() writes
            self.lock = hold_directory(out, "study")
            check_same_settings(out, out / self.SETTINGS, self.described, "study",
                                "scenario, its files, --set, the ranges, seed or samples",
                                "use a new --out")
            self.resume = self.file.path.exists()
            if self.resume:
                self.file.read(samples)

    def begin(self) -> None:
        """OUT made this study's: created if new, held, its settings and samples file
        written (those of a resumed study without a row cut short)."""
        if self.lock is None:
            self.lock = create_and_hold(self.out, "study")
        name_holder(self.lock)
        (self.out / self.SETTINGS).write_text(self.described)
        self.file.start(self.resume)
        self.started = True

    def missing(self) -> Iterator[int]:
        """The numbers of the samples the file lacks, in order."""
        return (number for number in range(self.samples) if number not in self.file.done)

    def close(self) -> None:
        self.file.close()


def write_json_with_rows(path: Path, report: dict[str, Any], name: str,
                         rows: Iterator[dict[str, Any]]) -> None:
    """`report` as strict JSON with one more key, `name`: the list of `rows`, written
    one row a line as they come (none is held), to a temporary file renamed at the
    end: the file is there whole or not at all."""
    temporary = path.with_name(path.name + ".tmp")
    head = jsontext.dumps(report, indent=2).rstrip()[:-1].rstrip()  # without its last "}"
    with temporary.open("w") as handle:
        handle.write(f"{head},\n  {jsontext.dumps(name)}: [")
        for number, row in enumerate(rows):
            handle.write(("," if number else "") + "\n    " + jsontext.dumps(row))
        handle.write("\n  ]\n}\n")
    temporary.replace(path)
