"""The journey a run drove and its per-station indices, from the run's parameters and
series alone (a bag's or an in-process run's): the report (ato_nodes.report_journey)
and scripts/robustness.py read a journey through here.

A journey run (profile.kind journey) names its timetable in profile.journey.timetable;
its bag keeps the file's copy (core/run/scoring.KEPT_FILES) beside the line's, so a bag
moved to another machine is scored per station on the timetable and the line it ran,
not on whatever files that machine has under those names.
"""

from __future__ import annotations

import base64
import tempfile
from pathlib import Path

import numpy as np
import yaml

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.run.scoring import LINE_BASE64, common_steps, energy_terms, kept_file
from ato_nodes.core.scoring.journey import JourneyIndices, journey_indices
from ato_nodes.core.targets.timetable import Timetable, load_timetable

TIMETABLE = "profile.journey.timetable"


def is_journey(parameters: dict | None) -> bool:
    return bool(parameters) and parameters.get("profile.kind") == "journey" \
        and bool(parameters.get(TIMETABLE))


def run_timetable(parameters: dict) -> Timetable | None:
    """The timetable of a journey run: the copy its bag keeps, read on the line the bag
    keeps; else the file it names; None when it is neither (or not a journey run).
    A kept copy that does not match its digest or does not load is a ScenarioError."""
    if not is_journey(parameters):
        return None
    try:
        content = kept_file(parameters, TIMETABLE)
    except ValueError as exc:
        raise ScenarioError(str(exc)) from None
    if content is None:
        named = Path(parameters[TIMETABLE])
        return load_timetable(named) if named.is_file() else None
    with tempfile.TemporaryDirectory(prefix="timetable-") as folder:
        copy = Path(folder) / Path(parameters[TIMETABLE]).name
        copy.write_bytes(content)
        _place_line(content, parameters.get(LINE_BASE64), Path(folder))
        return load_timetable(copy)


def _place_line(timetable: bytes, line_base64: str | None, folder: Path) -> None:
    """The bag's line written where the timetable's copy in `folder` looks for its line
    first (its `line:`, relative to the file). An absolute or climbing `line:` is left
    to resolve as it would: nothing is written outside the folder."""
    try:
        named = yaml.safe_load(timetable).get("line")
    except (yaml.YAMLError, AttributeError):
        return  # load_timetable says what is wrong, in one line
    if not (line_base64 and isinstance(named, str)) or Path(named).is_absolute() \
            or ".." in Path(named).parts:
        return
    place = folder / named
    place.parent.mkdir(parents=True, exist_ok=True)
    place.write_bytes(base64.b64decode(line_base64))


def run_journey(series: dict[str, np.ndarray], parameters: dict, timetable: Timetable
                ) -> JourneyIndices:
    """Per-station indices of a run of `timetable` (series cut to the steps all hold:
    an interrupted run's stations ahead are not reached). ScenarioError (one line)
    when the run lacks a series they need."""
    return journey_indices(common_steps(series), timetable, **energy_terms(parameters))
