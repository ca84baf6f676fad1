"""Timetables of journeys, ROS-free: per stop an arrival and a departure time on a line
with several stations, checked against the line and against the fastest the train can
run each section.

A timetable file (msg_config/timetables/*.yaml) names its line and its train and lists
its stops in the line's order; a station between two stops is passed without stopping:

    line: lines/metro-line.yaml   # relative to this file, else to msg_config/
    train: metro-b                # msg_config/trains/NAME.yaml
    stops:
      - {station: Westgate (synthetic), departure: 0}
      - {station: Market (synthetic), arrival: 131, departure: 156}
      - {station: Depot Road (synthetic), arrival: 1000}
    load: 1.3                     # optional: the mass its times are planned for (1 if not)

Times are seconds on the journey's clock (any origin): the first stop has a departure
only, the last an arrival only, every other stop both. A section's running time is the
arrival at its end less the departure at its start, standstill to standstill; a stop's
dwell is its departure less its arrival and is at least the station's dwell in the line
file (what the station needs for its passengers). A section's minimum running time is
the train's ato curve (core/targets/profiles.py) at its full envelope share, from
standstill to standstill as the on-time curve counts it. A timetable is planned for the
loaded train (`load`: its mass over the nominal, e.g. 1.3 crush-laden), so that a full
train keeps it too; one faster than the minimum at that load is refused. Every problem
is one ScenarioError line naming the file and the line.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import yaml

from ..base import yamlfile
from ..base.errors import ScenarioError
from ..base.paths import resolve_file
from ..train.line import (Line, Section, Station, mapping_fields, node_entries,
                          node_error, node_number, node_value)
from ..train.lines import load_line_file
from ..train.plant import TrainParameters
from .profiles import ato_curve_arguments, new_ato_curve

TOP_KEYS = {"line", "train", "stops", "load"}
REQUIRED_KEYS = TOP_KEYS - {"load"}
NOMINAL_LOAD = 1.0   # a timetable without `load` is planned for the nominal train
HEAVIEST_LOAD = 2.0  # the largest `load`, times the nominal train's mass
STOP_KEYS = {"station", "arrival", "departure"}
DAY = 86400.0  # s
# s: a time on a journey's clock lies within this of its origin, either way (the longest
# line, core/train/line.MAX_LENGTH, at 20 km/h takes about four days)
LATEST_TIME = 7 * DAY


@dataclass(frozen=True)
class Stop:
    station: str
    position: float          # m along the line
    arrival: float | None    # s; None at the first stop
    departure: float | None  # s; None at the last stop
    source_line: int         # the line of the timetable file that gives it

    @property
    def dwell(self) -> float:
        """s at the platform (0 at the journey's ends)."""
        if self.arrival is None or self.departure is None:
            return 0.0
        return self.departure - self.arrival


class JourneySection(NamedTuple):
    """The run from one stop to the next."""

    origin: str
    destination: str
    start: float         # m along the line
    end: float           # m
    running_time: float  # s, standstill to standstill, as the timetable gives it


@dataclass(frozen=True)
class Timetable:
    path: str
    line_file: str   # absolute
    line: Line
    train: str       # the train preset it is planned for
    stops: tuple[Stop, ...]
    load: float = NOMINAL_LOAD  # the mass its running times are planned for, over the nominal

    @property
    def sections(self) -> tuple[JourneySection, ...]:
        return tuple(JourneySection(a.station, b.station, a.position, b.position,
                                    b.arrival - a.departure)
                     for a, b in zip(self.stops, self.stops[1:], strict=False))

    @property
    def running_time(self) -> float:
        """The journey's running time: its sections' together, dwells excluded, s."""
        return sum(section.running_time for section in self.sections)


def load_timetable(path: str | Path) -> Timetable:
    """A timetable file on the line its `line:` names, checked against that line (not
    yet against a train: see check_minimum_times)."""
    text = yamlfile.read_text(path, "timetable file")
    fields = _fields(path, text)
    line_file = resolve_file(_text(fields["line"]), [Path(path).parent])
    try:
        line = load_line_file(line_file)
    except ScenarioError as exc:  # the file the user gave, then what is wrong with its line
        raise node_error(path, fields["line"], f"line: {exc}") from None
    return timetable_on(text, path, line, line_file)


# Cached by the file's text (and the line's contents): a run's validation, profile and
# controller each read the timetable, ~15 ms of YAML each; a Timetable is immutable.
@functools.lru_cache(maxsize=16)
def timetable_on(text: str, path: str | Path, line: Line, line_file: str) -> Timetable:
    """A timetable from its text (a bag's copy of the file at `path`) on `line`, the line
    the run drove (`line_file` names it), whatever the text's `line:` names now."""
    return _timetable(path, _fields(path, text), line, line_file)


@functools.lru_cache(maxsize=16)
def _fields(path, text: str) -> dict[str, yaml.Node]:  # read only: shared by its callers
    yamlfile.check_structure(text, str(path))
    fields = mapping_fields(path, yaml.compose(text), TOP_KEYS,
                            "a timetable file is a mapping (line, train, stops, load)")
    missing = sorted(REQUIRED_KEYS - set(fields))
    if missing:
        raise ScenarioError(f"{path}: missing {missing[0]!r}")
    return fields


def _timetable(path, fields: dict[str, yaml.Node], line: Line, line_file: str) -> Timetable:
    stops = _stops(path, fields["stops"], line)
    load = node_number(path, fields["load"], "load") if "load" in fields else NOMINAL_LOAD
    if not NOMINAL_LOAD <= load <= HEAVIEST_LOAD:
        raise node_error(path, fields["load"], f"load must be from 1 (the nominal train) to "
                         f"{HEAVIEST_LOAD:g} times the train's mass, not {load:g}")
    train = _text(fields["train"])  # a preset's name, or a TTOBench train file by its path
    train = resolve_file(train, [Path(path).parent]) if train.endswith(".json") else train
    return Timetable(str(path), line_file, line, train, stops, load)


def _text(node: yaml.Node) -> str:
    return str(node_value(node))


def _stops(path, node: yaml.Node, line: Line) -> tuple[Stop, ...]:
    """The stops, each a station of the line, in its order, with the times its place in
    the journey needs, each later than the one before."""
    entries = node_entries(path, node, "stops")
    if len(entries) < 2:
        raise node_error(path, node, "stops: a journey needs at least two stops")
    stations = {station.name: station for station in line.stations}
    stops: list[Stop] = []
    for index, (item, entry) in enumerate(entries):
        unknown = sorted(set(entry) - STOP_KEYS)
        if unknown:
            raise node_error(path, item, f"stops: unknown key {unknown[0]!r}")
        name = _text(entry["station"]) if "station" in entry else ""
        if name not in stations:
            raise node_error(path, item, f"stops: {name!r} is not a station of the line "
                         f"(its stations: {', '.join(stations)})")
        times = {key: _time(path, item, entry, key, index, len(entries))
                 for key in ("arrival", "departure")}
        stop = Stop(name, stations[name].position, times["arrival"], times["departure"],
                    item.start_mark.line + 1)
        _check_order(path, item, stop, stops[-1] if stops else None, stations[name])
        stops.append(stop)
    return tuple(stops)


def _time(path, item: yaml.Node, entry: dict, key: str, index: int, count: int
          ) -> float | None:
    """The stop's arrival or departure, s: required where the journey has one (no
    arrival at the first stop, no departure at the last), refused where it has none."""
    needed = index > 0 if key == "arrival" else index < count - 1
    where = {0: "the first stop", count - 1: "the last stop"}.get(index, "a stop on the way")
    if needed and key not in entry:
        raise node_error(path, item, f"stops: {where} needs its {key}")
    if not needed and key in entry:
        raise node_error(path, entry[key], f"stops: {where} has no {key}")
    if not needed:
        return None
    time = node_number(path, entry[key], key)
    if abs(time) > LATEST_TIME:
        raise node_error(path, entry[key], f"stops: {key} {time:g} s is more than "
                         f"{LATEST_TIME:g} s ({LATEST_TIME / DAY:g} days) from the journey's "
                         "clock origin")
    return time


def _check_order(path, item, stop: Stop, previous: Stop | None, station: Station) -> None:
    if stop.arrival is not None and stop.departure is not None:
        if stop.departure < stop.arrival:
            raise node_error(path, item, f"stops: times do not increase: departure "
                         f"{stop.departure:g} s from {stop.station} is before its arrival "
                         f"{stop.arrival:g} s")
        if stop.dwell < station.dwell:
            raise node_error(path, item, f"stops: dwell {stop.dwell:g} s at {stop.station} is "
                         f"shorter than the station's {station.dwell:g} s (the line file's)")
    if previous is None:
        return
    if stop.position <= previous.position:
        raise node_error(path, item, f"stops: {stop.station} is not after {previous.station} "
                     "along the line")
    if not stop.arrival > previous.departure:
        raise node_error(path, item, f"stops: times do not increase: arrival {stop.arrival:g} s at "
                     f"{stop.station} is not after the departure {previous.departure:g} s "
                     f"from {previous.station}")


def section_line(line: Line, start: float, end: float) -> Line:
    """The line from a stop at `start` to one at `end` (m), in metres from `start`: the
    stop mark at its end, every section of the line kept (the train's mass belt lies
    behind the departure point at first), no planned time of its own."""
    def shifted(sections: tuple[Section, ...]) -> tuple[Section, ...]:
        return tuple(Section(s.start - start, s.end - start, s.value) for s in sections)

    stops = tuple(Station(s.name, s.position - start, s.dwell) for s in line.stations
                  if s.position in (start, end))
    return dataclasses.replace(
        line, name=f"{line.name}, {start:g}-{end:g} m", length=line.length - start,
        gradients=shifted(line.gradients), curves=shifted(line.curves),
        tunnels=shifted(line.tunnels), speed_limits=shifted(line.speed_limits),
        neutral_sections=shifted(line.neutral_sections), stations=stops,
        planned_run_time=None)


def minimum_running_time(line: Line, values: dict, load: float = NOMINAL_LOAD) -> float:
    """The fastest the run's nominal train (plant.*), at `load` times its mass, runs
    `line` to its stop mark: the ato curve (profile.ato.*) at the train's full envelope
    share, from standstill to standstill (the on-time curve's count), s."""
    nominal = TrainParameters.from_values(values)
    fastest = {**values, "profile.envelope_share": 1.0, "profile.ato.on_time": True}
    return _minimum_running_time(ato_curve_arguments(
        fastest, line, nominal.loaded(load, values["plant.davis_absolute"])))


# Its own cache, keyed by what the curve is built from: a run's timetable is checked at each
# validation (every run of a study, each with its own weighed train), and these curves are
# not the journey's, which would evict them from the profile's cache (ato_curve's).
@functools.lru_cache(maxsize=32)
def _minimum_running_time(arguments: tuple) -> float:
    return new_ato_curve(*arguments).planned_run_time


def check_minimum_times(timetable: Timetable, values: dict) -> tuple[float, ...]:
    """Each section's minimum running time for the run's nominal train (`values`:
    plant.* and profile.ato.*), s; ScenarioError (the file and the stop's line) for a
    section the timetable gives less than that train's minimum at the timetable's
    load."""
    check_running_times(timetable, values)
    return tuple(minimum_running_time(section_line(timetable.line, s.start, s.end), values)
                 for s in timetable.sections)


def check_running_times(timetable: Timetable, values: dict) -> None:
    """ScenarioError (the file and the stop's line) for a section the timetable gives less
    than its minimum running time at the timetable's load, the train's of `values`: a
    timetable no such train can keep (what a run checks before it starts)."""
    for section, stop in zip(timetable.sections, timetable.stops[1:], strict=True):
        line = section_line(timetable.line, section.start, section.end)
        loaded = minimum_running_time(line, values, timetable.load)
        if section.running_time < loaded:
            raise ScenarioError(
                f"{timetable.path} line {stop.source_line}: the running time "
                f"{section.running_time:g} s from {section.origin} to {section.destination} "
                f"is below its minimum {math.ceil(loaded * 10) / 10:g} s (train "
                f"{values['plant.train'] or '(none)'} at {timetable.load:g} times its mass: "
                "its ato curve at the full envelope)")
