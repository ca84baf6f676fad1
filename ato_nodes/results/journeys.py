"""The journey a run drove and its per-station indices, from the run's parameters and
series alone (a bag's or an in-process run's): the report (ato_nodes.reports.report_journey)
and scripts/robustness.py (score_with_journey) read a journey through here.

A journey run (profile.kind journey) names its timetable in profile.journey.timetable;
its bag keeps the file's copy (core/run/scoring.KEPT_FILES) beside the line's, and the
copy is read on the kept line itself (never on a file its `line:` names), so a bag is
scored per station on the timetable and the line it ran, wherever their files were and
whatever became of them since.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ato_nodes.core.base import yamlfile
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.run.scoring import (common_steps, energy_terms, kept_file,
                                        pantograph_in_neutral, run_line, score_series)
from ato_nodes.core.scoring.catalogue import (STOP_INDICES, TIMING_MISSED, WORST_ARRIVAL,  # noqa: F401
                                              WORST_STOP)  # (studies read them here)
from ato_nodes.core.scoring.journey import (PASS, STOPPED, JourneyIndices, journey_indices,
                                            journey_record, last_stop_indices)
from ato_nodes.core.targets.timetable import Timetable, timetable_on

TIMETABLE = "profile.journey.timetable"


def is_journey(parameters: dict | None) -> bool:
    return bool(parameters) and parameters.get("profile.kind") == "journey" \
        and bool(parameters.get(TIMETABLE))


def run_timetable(parameters: dict) -> Timetable | None:
    """The timetable of a journey run (the copy its bag keeps, else the file it names) on
    the line the run drove (the bag's copy, else its line.file: run_line), whatever the
    timetable's `line:` names now and wherever that is; None when there is no timetable or
    no line (or not a journey run). A kept copy that does not match its digest or does not
    load is a ScenarioError."""
    if not is_journey(parameters):
        return None
    try:
        content = kept_file(parameters, TIMETABLE)
    except ValueError as exc:
        raise ScenarioError(str(exc)) from None
    named = Path(parameters[TIMETABLE])
    if content is None and not named.is_file():
        return None
    line = run_line(parameters)
    if line is None:
        return None
    try:
        text = yamlfile.read_text(named, "timetable file") if content is None \
            else content.decode("utf-8")
    except UnicodeDecodeError:
        raise ScenarioError(f"the copy of {TIMETABLE} kept in the bag is not UTF-8 text") \
            from None
    return timetable_on(text, named, line, parameters.get("line.file") or "<bag>")


def run_journey(series: dict[str, np.ndarray], parameters: dict, timetable: Timetable
                ) -> JourneyIndices:
    """Per-station indices of a run of `timetable` (series cut to the steps all hold:
    an interrupted run's stations ahead are not reached). ScenarioError (one line)
    when the run lacks a series they need."""
    series = common_steps(series)
    neutral = pantograph_in_neutral(series, parameters, run_line(parameters)) \
        if "position" in series else None  # without it, journey_indices says what is missing
    terms = energy_terms(parameters)
    return journey_indices(series, timetable, terms["mass"], terms["gravity"],
                           terms["efficiency"], neutral=neutral)


def score_run(series: dict[str, np.ndarray], parameters: dict | None) -> dict:
    """score_series' indices of a run, as summary.json, score_bag and the report's
    indices.json give them. A journey run's results per station and section are under
    `journey` (its timetable's name and core/scoring/journey.journey_record) and its stop
    indices are its last stop's (last_stop_indices: NaN without a stop there); one that
    cannot be scored per station (its timetable nowhere, a series missing) has NaN stop
    indices and `journey` says why."""
    return _scored(series, parameters)[0]


def _scored(series: dict[str, np.ndarray], parameters: dict | None
            ) -> tuple[dict, JourneyIndices | None]:
    """score_run's indices and the journey they were read from (None: not a journey run,
    or one that cannot be scored per station)."""
    indices = score_series(series, parameters)
    if not is_journey(parameters):
        return indices, None
    name = Path(parameters[TIMETABLE]).name
    stop_indices = [key for key in STOP_INDICES if key in indices]
    try:
        timetable = run_timetable(parameters)
        if timetable is None:
            raise ScenarioError(f"the timetable {name} is neither kept in the bag nor on "
                                "this machine")
        journey = run_journey(series, parameters, timetable)
    except ScenarioError as exc:
        indices.update(dict.fromkeys(stop_indices, math.nan))
        indices["journey"] = {"timetable": name, "error": str(exc)}
        return indices, None
    last_stop = last_stop_indices(journey, timetable.line.planned_run_time)
    indices.update({key: last_stop[key] for key in stop_indices})
    indices["journey"] = {"timetable": name, **journey_record(journey)}
    return indices, journey




def worst_stations(indices: JourneyIndices) -> dict[str, float]:
    """The largest |stop error| (m) and |arrival lateness| (s: against the window of a
    TTOBench journey's stop) over the stations after the origin, inf if one of them has
    no stop; with timing points, how many the run did not keep (window, speed bounds,
    or not reached)."""
    stations = indices.stations[1:]
    missed = {TIMING_MISSED: float(sum(point.verdict != PASS for point in indices.timing))} \
        if indices.timing else {}
    if any(station.outcome != STOPPED for station in stations):
        return {WORST_STOP: math.inf, WORST_ARRIVAL: math.inf, **missed}
    return {WORST_STOP: max(abs(station.stop_error) for station in stations),
            WORST_ARRIVAL: max(abs(station.arrival_lateness) for station in stations),
            **missed}


def score_with_journey(values: dict, series: dict[str, np.ndarray] | None = None) -> dict:
    """score_run's indices of the run of `values` in-process (or of its recorded
    `series`: a stack run's), with worst_stations for a journey run (a study's worker:
    the series stay in its process)."""
    indices, journey = _scored(simulate(values) if series is None else series, values)
    if journey is not None:
        indices.update(worst_stations(journey))
    return indices
