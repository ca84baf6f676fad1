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
from ..base.paths import config_dir, resolve_file
from ..train import ttobench
from ..train.line import (Line, Section, Station, mapping_fields, node_entries, node_error,
                          node_number, node_value)
from ..train.lines import for_train, load_line_file
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
JOURNEYS = config_dir() / "ttobench" / "journeys"  # the shipped TTOBench journeys
TRACKS = config_dir() / "ttobench" / "tracks"


class Window(NamedTuple):
    """A timing point's time window, s on the journey's clock (None: not set)."""

    earliest: float | None
    latest: float | None

    def miss(self, time: float) -> float:
        """How far `time` (s) lies outside the window: 0 inside, - early, + late."""
        if self.earliest is not None and time < self.earliest:
            return time - self.earliest
        if self.latest is not None and time > self.latest:
            return time - self.latest
        return 0.0

    def text(self) -> str:
        """The window as notices and verdicts say it: [earliest, latest] s ('-' unset)."""
        return (f"[{'-' if self.earliest is None else f'{self.earliest:g}'}, "
                f"{'-' if self.latest is None else f'{self.latest:g}'}] s")


class PassingPoint(NamedTuple):
    """A TTOBench journey's timing point the train passes without stopping."""

    name: str                 # its kilometre, as a stop's station is named
    position: float           # m along the line
    window: Window            # when the head passes it
    min_speed: float | None   # m/s (None: not set)
    max_speed: float | None   # m/s
    source_line: int          # its entry in the journey's timing points


@dataclass(frozen=True)
class Stop:
    station: str
    position: float          # m along the line
    arrival: float | None    # s; None at the first stop
    departure: float | None  # s; None at the last stop
    source_line: int         # the line of the timetable file that gives it (a TTOBench
                             # journey's: the entry of its arrival's timing point)
    least_dwell: float = 0.0  # s the train stands at least when it arrived late
    # a TTOBench journey's windows (None: a timetable file's times, kept to a tolerance)
    arrival_window: Window | None = None
    departure_window: Window | None = None

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
    passing: tuple[PassingPoint, ...] = ()  # the timing points between its stops


@dataclass(frozen=True)
class Timetable:
    path: str
    line_file: str   # absolute
    line: Line
    train: str       # the train preset it is planned for
    stops: tuple[Stop, ...]
    load: float = NOMINAL_LOAD  # the mass its running times are planned for, over the nominal
    passing: tuple[PassingPoint, ...] = ()
    journey: str = ""  # a TTOBench journey's id ("" for a timetable file)

    @property
    def sections(self) -> tuple[JourneySection, ...]:
        return tuple(JourneySection(a.station, b.station, a.position, b.position,
                                    b.arrival - a.departure,
                                    tuple(p for p in self.passing
                                          if a.position < p.position < b.position))
                     for a, b in zip(self.stops, self.stops[1:], strict=False))

    @property
    def running_time(self) -> float:
        """The journey's running time: its sections' together, dwells excluded, s."""
        return sum(section.running_time for section in self.sections)

    def where(self, source_line: int) -> str:
        """Where in its file a stop or a timing point is given, as an error names it."""
        return (f"timing points entry {source_line}" if self.journey
                else f"line {source_line}")

    def on_line(self, line: Line | None, values) -> bool:
        """Whether a run of `line` (by contents; None: the open track, no line) with
        `values` may drive it: a timetable file's own line as the run's train runs it
        (lines.for_train: ended, capped); a TTOBench journey's track (its geometry: with
        or without a station at each of its stops, its limits capped at the run's train's
        maximum speed or not)."""
        if line is None:
            return False
        if not self.journey:
            return for_train(self.line, values) == line
        return _geometry(self.line) == _geometry(line)

    def for_train(self, train: str) -> bool:
        """Whether a run of train `train` (plant.train) may drive it: a timetable file's
        own train, a TTOBench train file by its contents (ttobench.same_train: a copy, or
        a bag's run recorded in another checkout, has another path); a TTOBench journey
        (planned for none) any."""
        if self.journey:
            return True
        if ttobench.is_library_file(self.train) and ttobench.is_library_file(train):
            return ttobench.same_train(self.train, train)
        return self.train == train


def _geometry(line: Line) -> Line:
    return dataclasses.replace(line, stations=(), speed_limits=())


def load_timetable(path: str | Path) -> Timetable:
    """A timetable file on the line its `line:` names, checked against that line (not
    yet against a train: see check_minimum_times); a TTOBench journey file (.json) on its
    associated track (journey_timetable)."""
    if ttobench.is_library_file(path):
        return journey_timetable(path)
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
    the run drove (`line_file` names it), whatever the text's `line:` names now; a
    TTOBench journey's (.json) on that line alike."""
    if ttobench.is_library_file(path):
        return journey_on(ttobench.parse_journey(text, path), line, line_file)
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
    if ttobench.is_library_file(train):
        train = resolve_file(train, [Path(path).parent])
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
                    item.start_mark.line + 1, stations[name].dwell)
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


# ------------------------------------------------------- TTOBench journeys ----


def journey_file(given: str) -> str:
    """A TTOBench journey as a user gives it: a file (a path with a folder or a .json
    suffix, from anywhere), else the id of one in msg_config/ttobench/journeys/;
    ScenarioError naming what was given."""
    path = Path(given)
    if ttobench.is_library_file(path) or len(path.parts) > 1:
        return str(path.resolve())
    shipped = JOURNEYS / f"{given}.json"
    if not shipped.is_file():
        known = ", ".join(sorted(p.stem for p in JOURNEYS.glob("*.json")))
        raise ScenarioError(f"unknown TTOBench journey {given!r}: neither a .json file nor "
                            f"the id of one in {JOURNEYS} ({known})")
    return str(shipped)


def journey_track(journey: ttobench.Journey) -> Path:
    """The file of a journey's associated track: beside the journey's folder, as the
    library lays them out (../tracks/ID.json), else msg_config/ttobench/tracks/ID.json."""
    beside = journey.path.parent.parent / "tracks" / f"{journey.track_id}.json"
    return beside if beside.is_file() else TRACKS / f"{journey.track_id}.json"


def journey_timetable(path: str | Path) -> Timetable:
    """A TTOBench journey file as a timetable on its associated track (journey_track),
    with a station at each of its stops (Track.line(journey))."""
    journey = ttobench.load_journey(path)
    track_file = journey_track(journey)
    if not track_file.is_file():
        raise ScenarioError(f"{path}: metadata: associated track {journey.track_id!r}: no "
                            f"file {track_file}")
    track = ttobench.load_track(track_file)
    return journey_on(journey, track.line(journey), str(track_file.resolve()))


def journey_on(journey: ttobench.Journey, line: Line, line_file: str) -> Timetable:
    """The timetable of a TTOBench journey on `line` (its track's): a stop at each
    stopping point, arriving at its window's latest time (the least-energy choice a
    cruise curve has), departing at its window's earliest (not before the arrival); the
    passing points between; ScenarioError (one line, the file and the entry) for a
    stop the planner has no time for, times that do not increase or a time beyond
    LATEST_TIME."""
    beyond = next((p for p in journey.points if p.position > line.length), None)
    if beyond is not None:
        raise ScenarioError(f"{journey.path}: timing points: {beyond.position:g} m is beyond "
                            f"the end of the line ({line.length:g} m)")
    dwells, names = journey.dwells(), {s.position: s.name for s in line.stations}
    stops: list[Stop] = []
    passing: list[PassingPoint] = []
    for number, point in enumerate(journey.points, 1):
        window = Window(point.earliest, point.latest)
        if max(filter(None, window), default=0.0) > LATEST_TIME:
            raise ScenarioError(f"{journey.path}: timing points entry {number}: a time more "
                                f"than {LATEST_TIME:g} s ({LATEST_TIME / DAY:g} days) from the "
                                "journey's start")
        name = names.get(point.position, kilometre(point.position))
        if not point.stopping:
            passing.append(PassingPoint(kilometre(point.position), point.position, window,
                                        point.min_speed, point.max_speed, number))
        elif stops and stops[-1].position == point.position:  # the departure of a stop
            arrival = stops[-1]
            departure = max(arrival.arrival, _first(point.earliest, point.latest,
                                                    arrival.arrival))
            stops[-1] = dataclasses.replace(arrival, departure=departure,
                                            departure_window=window)
        elif not stops:  # the journey's first departure
            stops.append(Stop(name, point.position, None, _first(point.earliest,
                              point.latest, 0.0), number, 0.0, None, window))
        else:
            stops.append(_journey_arrival(journey, stops[-1], point, number, name,
                                          dwells.get(point.position, 0.0)))
    return Timetable(str(journey.path), line_file, line, "", tuple(stops),
                     passing=tuple(passing), journey=journey.id)


def _first(*times: float | None) -> float:
    return next(time for time in times if time is not None)


def _journey_arrival(journey: ttobench.Journey, previous: Stop,
                     point: ttobench.TimingPoint, number: int, name: str,
                     least_dwell: float) -> Stop:
    """An arrival stopping point as a stop, arriving at its window's latest time (its
    earliest when it has no latest)."""
    where = f"{journey.path}: timing points entry {number}"
    if point.earliest is None and point.latest is None:
        raise ScenarioError(f"{where}: a stop needs a lower or an upper time constraint "
                            "(the planner plans the section to arrive by it)")
    arrival = _first(point.latest, point.earliest)
    if not arrival > previous.departure:
        raise ScenarioError(f"{where}: the arrival {arrival:g} s at {point.position:g} m is "
                            f"not after the departure {previous.departure:g} s from "
                            f"{previous.station}")
    return Stop(name, point.position, arrival, None, number, least_dwell,
                Window(point.earliest, point.latest))


def kilometre(position: float) -> str:
    """A TTOBench stop's or passing point's name: its kilometre (Track.line's names)."""
    return f"km {position / 1000:g}"


def section_line(line: Line, start: float, end: float) -> Line:
    """The line from a stop at `start` to one at `end` (m), in metres from `start`: the
    stop mark at its end, every section of the line kept (the train's mass belt lies
    behind the departure point at first), no planned time of its own."""
    def shifted(sections: tuple[Section, ...]) -> tuple[Section, ...]:
        return tuple(Section(s.start - start, s.end - start, s.value) for s in sections)

    stops = tuple(Station(s.name, s.position - start, s.dwell) for s in line.stations
                  if s.position in (start, end))
    if end not in (s.position for s in line.stations):  # a journey's stop the line lacks
        stops += (Station(kilometre(end), end - start, 0.0),)
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
    line = for_train(timetable.line, values)
    return tuple(minimum_running_time(section_line(line, s.start, s.end), values)
                 for s in timetable.sections)


def check_running_times(timetable: Timetable, values: dict) -> None:
    """ScenarioError (the file and the stop's line) for a section the timetable gives less
    than its minimum running time at the timetable's load, the train's of `values`: a
    timetable no such train can keep (what a run checks before it starts), on the line
    as that train runs it (its limits capped at its maximum speed: lines.for_train)."""
    runs = for_train(timetable.line, values)
    for section, stop in zip(timetable.sections, timetable.stops[1:], strict=True):
        line = section_line(runs, section.start, section.end)
        loaded = minimum_running_time(line, values, timetable.load)
        if section.running_time < loaded:
            raise ScenarioError(
                f"{timetable.path} {timetable.where(stop.source_line)}: the running time "
                f"{section.running_time:g} s from {section.origin} to {section.destination} "
                f"is below its minimum {math.ceil(loaded * 10) / 10:g} s (train "
                f"{values['plant.train'] or '(none)'} at {timetable.load:g} times its mass: "
                "its ato curve at the full envelope)")
