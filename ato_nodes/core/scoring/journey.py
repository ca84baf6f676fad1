"""Per-station indices of a journey run (ROS-free): where and when the train stopped at
each stop of its timetable (core/targets/timetable.py), against the timetable, and what
each section between two stops took.

The stop at a station is the train's final standstill (speed <= STANDSTILL, the
scorer's) within `window` (STOP_WINDOW) of the station's mark, among the standstills
after the stop before and before the train is beyond the window: the scorer's rule for a
run's one stop (core/scoring/operation.py: arrival at the first sample of the final
standstill, stopping error at its last position), applied station by station. The final
standstill, not the first: a train that halts short and creeps to the mark opens its
doors at the mark, and its arrival counts the creep. The window is wide (a stop metres
off is a stop with a large error, not a missed one) and under half the shortest section
(each standstill belongs to one station at most); a standstill outside every window (a
signal check) is part of its section.

Per station: the stop error (m, + past the mark), the arrival (first standstill sample)
and departure (first sample moving again), their lateness against the timetable (s, +
late; the run's t = 0 is the timetable's first departure, where the journey profile
starts its clock) and the dwell. A station the train went beyond without a standstill in
its window is PASSED (a failure); one the run ended before is NOT_REACHED (not judged).
Per section, between the departure and the next arrival (standstill to standstill, as
the timetable counts): running time, traction energy (the scorer's
traction_energy_kwh) and the largest |target - speed| (m/s). Stations are judged against
StationRequirements: the stop within STOP_TOLERANCE of the mark, the arrival within
ARRIVAL_TOLERANCE of the timetable; the origin has no arrival and its position is the
run's start, so nothing is required of it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple, Protocol

import numpy as np

from ..base.errors import ScenarioError
from ..base.units import MS_TO_KMH
from .operation import BERTHING_TOLERANCE, STANDSTILL, neutral_traction_time, traction_energy_kwh


# What is read of a timetable (core/targets/timetable.py's Stop, JourneySection and
# Timetable): scoring sits below the targets and does not import them.
class Window(Protocol):
    earliest: float | None  # s, timetable clock (None: not set)
    latest: float | None

    def miss(self, time: float) -> float: ...


class Stop(Protocol):
    station: str
    position: float          # m
    arrival: float | None    # s, timetable clock
    departure: float | None  # s
    arrival_window: Window | None    # a TTOBench journey's (None: a timetable file's)
    departure_window: Window | None


class PassingPoint(Protocol):
    name: str
    position: float          # m
    window: Window
    min_speed: float | None  # m/s
    max_speed: float | None


class JourneySection(Protocol):
    origin: str
    destination: str
    start: float         # m
    end: float           # m
    running_time: float  # s


class Timetable(Protocol):
    stops: tuple[Stop, ...]
    sections: tuple[JourneySection, ...]
    passing: tuple[PassingPoint, ...]

STOP_WINDOW = 50.0        # m either side of a station's mark
STOP_TOLERANCE = 0.1      # m: the project's stopping accuracy (docs/tracking.md section 1)
ARRIVAL_TOLERANCE = 5.0   # s either side of the timetable's arrival

STOPPED, PASSED, NOT_REACHED = "stopped", "passed without stopping", "not reached"
PASS, FAIL, NOT_JUDGED = "pass", "fail", "not judged"  # as the report's verdicts
REQUIRED_SERIES = ("t", "position", "speed", "target", "force")


class StationRequirements(NamedTuple):
    stop_error: float = STOP_TOLERANCE           # m: |stop error| at most
    arrival_lateness: float = ARRIVAL_TOLERANCE  # s: |arrival lateness| at most


REQUIRED = StationRequirements()


class StationIndices(NamedTuple):
    station: str
    mark: float                # m along the line
    outcome: str               # STOPPED, PASSED or NOT_REACHED
    stop_error: float          # m, + past the mark (NaN: no stop)
    arrival: float             # s, run clock (NaN: the origin, no stop)
    departure: float           # s (NaN: the last stop, still standing at the run's end)
    arrival_lateness: float    # s, + late
    departure_lateness: float  # s, + late
    dwell: float               # s, departure - arrival
    verdict: str               # PASS, FAIL, NOT_JUDGED; "" at the origin (nothing required)
    reason: str                # what is broken, or why it is not judged


class SectionIndices(NamedTuple):
    """A section's figures, NaN unless the train stopped at both its ends and left the
    first."""

    origin: str
    destination: str
    running_time: float          # s, departure to arrival
    running_time_error: float    # s, + slower than the timetable
    traction_energy_kwh: float
    max_abs_error: float         # m/s, target - speed


DEPARTURE, ARRIVAL, PASSING = "departure", "arrival", "passing"  # a timing point's kind


class TimingIndices(NamedTuple):
    """A TTOBench journey's timing point as the run kept it: when the train departed from,
    arrived at or passed it against its window, and at what speed it passed."""

    point: str        # the stop's station or the passing point's name
    kind: str         # DEPARTURE, ARRIVAL or PASSING
    mark: float       # m along the line
    earliest: float   # s, its window on the timetable's clock (NaN: not set)
    latest: float
    min_speed: float  # m/s, a passing point's speed bounds (NaN: not set)
    max_speed: float
    time: float       # s, run clock (NaN: not reached, or no stop)
    miss: float       # s outside its window: 0 inside, + late, - early (NaN: no time)
    speed: float      # m/s as the head passed it (NaN at a stop)
    verdict: str      # PASS, FAIL, NOT_JUDGED
    reason: str       # what is broken, or why it is not judged


@dataclass(frozen=True)
class JourneyIndices:
    stations: tuple[StationIndices, ...]
    sections: tuple[SectionIndices, ...]
    traction_energy_kwh: float  # the whole run's
    neutral_traction_command_time: float  # s, the whole run's (operation.py; NaN: not told
                                          # where the neutral sections are)
    timing: tuple[TimingIndices, ...] = ()  # a TTOBench journey's timing points, in order

    @property
    def worst_stop(self) -> StationIndices | None:
        """The stop (the origin aside) farthest from its mark, None without one."""
        stops = [s for s in self.stations[1:] if s.outcome == STOPPED]
        return max(stops, key=lambda s: abs(s.stop_error), default=None)

    @property
    def worst_lateness(self) -> StationIndices | None:
        """The arrival farthest from the timetable, early or late; None without one."""
        stops = [s for s in self.stations[1:] if s.outcome == STOPPED]
        return max(stops, key=lambda s: abs(s.arrival_lateness), default=None)

    @property
    def final_arrival_lateness(self) -> float:
        """s, + late; NaN when the train did not stop at the last station."""
        return self.stations[-1].arrival_lateness

    @property
    def verdict(self) -> str:
        """FAIL if a station fails, else NOT_JUDGED if one is not judged, else PASS."""
        verdicts = {item.verdict for item in (*self.stations, *self.timing)}
        return FAIL if FAIL in verdicts else NOT_JUDGED if NOT_JUDGED in verdicts else PASS


class _Stop(NamedTuple):
    """Where a station's stop lies in the samples."""

    outcome: str
    first: int   # first sample of the standstill (-1 without a stop)
    last: int    # its last sample
    resume: int  # the sample the next station's stop is looked for from


def journey_indices(series: dict[str, np.ndarray], timetable: Timetable, mass: float,
                    gravity: float = 9.8, efficiency: float = 0.9,
                    window: float = STOP_WINDOW,
                    requirements: StationRequirements = REQUIRED,
                    neutral: np.ndarray | None = None) -> JourneyIndices:
    """Per-station and per-section indices of a run of `timetable` (series of equal
    length: REQUIRED_SERIES; mass in t and `neutral`, the samples with the pantograph
    inside a neutral section, as operation_indices takes them)."""
    _check(series, timetable, window)
    t, position, speed, target, force = (np.asarray(series[name], dtype=float)
                                         for name in REQUIRED_SERIES)
    standstills = _standstills(speed)
    found, start = [], 0
    for stop in timetable.stops:
        found.append(_find_stop(position, standstills, stop.position, window, start))
        start = found[-1].resume
    clock = timetable.stops[0].departure
    stations = tuple(_station(stop, where, t, position, clock, window, requirements)
                     for stop, where in zip(timetable.stops, found, strict=True))
    sections = tuple(
        _section(planned, begin, end, (t, speed, target, force), (mass, gravity, efficiency))
        for planned, begin, end in zip(timetable.sections, found, found[1:], strict=False))
    commanded = math.nan
    if neutral is not None and "command" in series:
        commanded = neutral_traction_time(t, series["command"], neutral)
    return JourneyIndices(stations, sections,
                          traction_energy_kwh(t, speed, force, mass, gravity, efficiency),
                          commanded, timing_indices(timetable, stations, t, position, speed))


def timing_indices(timetable: Timetable, stations: tuple[StationIndices, ...],
                   t: np.ndarray, position: np.ndarray, speed: np.ndarray
                   ) -> tuple[TimingIndices, ...]:
    """Every timing point of a TTOBench journey in the order of the line (none for a
    timetable file): each arrival and departure at a stop (the stations' times), each
    passing point (when and how fast the head passed it). The first departure sets the
    journey's clock (the run's t = 0) and is not judged."""
    if timetable.stops[0].departure_window is None:
        return ()
    clock = timetable.stops[0].departure
    points = []
    for stop, station in zip(timetable.stops[1:], stations[1:], strict=True):
        for kind, window, time in ((ARRIVAL, stop.arrival_window, station.arrival),
                                   (DEPARTURE, stop.departure_window, station.departure)):
            if window is not None:
                points.append(_timed_point(station, kind, window, time, clock))
    points += [_passing(point, t, position, speed, clock) for point in timetable.passing]
    return tuple(sorted(points, key=lambda p: (p.mark, p.kind != ARRIVAL)))


def _timed_point(station: StationIndices, kind: str, window: Window, time: float,
                 clock: float) -> TimingIndices:
    """A stop's arrival or departure against its window."""
    nan = math.nan
    point = TimingIndices(station.station, kind, station.mark, *_bounds(window), nan, nan,
                          nan, "", "")
    if not math.isfinite(time):
        if station.outcome == STOPPED:  # standing at the run's end: not left
            return point._replace(verdict=NOT_JUDGED, reason="still standing at the run's end")
        return point._replace(verdict=FAIL if station.outcome == PASSED else NOT_JUDGED,
                              reason=station.reason or station.outcome)
    miss = window.miss(time + clock)
    return point._replace(time=time, miss=miss, verdict=FAIL if miss else PASS,
                          reason=f"{miss:+.1f} s outside {window.text()}" if miss else "")


def _bounds(window: Window, low: float | None = None, high: float | None = None
            ) -> tuple[float, float, float, float]:
    """A timing point's window and speed bounds as TimingIndices holds them (NaN unset)."""
    return tuple(math.nan if value is None else float(value)
                 for value in (window.earliest, window.latest, low, high))


def _passing(point: PassingPoint, t: np.ndarray, position: np.ndarray, speed: np.ndarray,
             clock: float) -> TimingIndices:
    """When and how fast the head first reached a passing point (interpolated between
    the samples either side), against its window and speed bounds."""
    bounds = _bounds(point.window, point.min_speed, point.max_speed)
    beyond = np.flatnonzero(position >= point.position)
    if not beyond.size or beyond[0] == 0:
        return TimingIndices(point.name, PASSING, point.position, *bounds, math.nan, math.nan,
                             math.nan, NOT_JUDGED, "the run ended before it")
    k = int(beyond[0])
    share = (point.position - position[k - 1]) / (position[k] - position[k - 1])
    time = float(t[k - 1] + share * (t[k] - t[k - 1]))
    passed = float(speed[k - 1] + share * (speed[k] - speed[k - 1]))
    miss = point.window.miss(time + clock)
    broken = [f"{miss:+.1f} s outside {point.window.text()}"] if miss else []
    if point.min_speed is not None and passed < point.min_speed:
        broken.append(f"{passed * MS_TO_KMH:.1f} km/h below {point.min_speed * MS_TO_KMH:g} km/h")
    if point.max_speed is not None and passed > point.max_speed:
        broken.append(f"{passed * MS_TO_KMH:.1f} km/h above {point.max_speed * MS_TO_KMH:g} km/h")
    return TimingIndices(point.name, PASSING, point.position, *bounds, time, miss, passed,
                         FAIL if broken else PASS, "; ".join(broken))


def _check(series: dict[str, np.ndarray], timetable: Timetable, window: float) -> None:
    missing = [name for name in REQUIRED_SERIES if name not in series]
    if missing:
        raise ScenarioError(f"journey indices need the series {', '.join(missing)} "
                            f"(the run has {', '.join(sorted(series)) or 'none'})")
    lengths = {len(series[name]) for name in REQUIRED_SERIES}
    if len(lengths) > 1 or 0 in lengths:
        raise ScenarioError(f"journey indices need series of one nonzero length, not "
                            f"{sorted(lengths)} samples")
    check_stop_window(timetable, window)


def check_stop_window(timetable: Timetable, window: float = STOP_WINDOW) -> None:
    """ScenarioError unless `window` is positive and under half the timetable's shortest
    section (each standstill belongs to one station at most): what a journey run's
    stations must leave room for, checked before it runs."""
    shortest = min(timetable.sections, key=lambda s: s.end - s.start)
    if not 0.0 < window < (shortest.end - shortest.start) / 2:
        raise ScenarioError(f"the stop window {window:g} m must be positive and under half "
                            f"the shortest section ({shortest.origin} - "
                            f"{shortest.destination}, {shortest.end - shortest.start:g} m)")


def _standstills(speed: np.ndarray) -> np.ndarray:
    """(first, last) sample of each run of standing samples, in order."""
    standing = np.concatenate(([0], (speed <= STANDSTILL).astype(int), [0]))
    return np.flatnonzero(np.diff(standing)).reshape(-1, 2) - [0, 1]


def _find_stop(position: np.ndarray, standstills: np.ndarray, mark: float, window: float,
               start: int) -> _Stop:
    """The stop at the station marked `mark` (m), looked for from sample `start`: the
    last standstill within the window before the train is beyond it."""
    beyond = np.flatnonzero(position[start:] > mark + window)
    beyond_at = start + int(beyond[0]) if beyond.size else len(position)
    within = [(first, last) for first, last in standstills
              if start <= first < beyond_at and abs(position[last] - mark) <= window]
    if within:
        first, last = within[-1]
        return _Stop(STOPPED, int(first), int(last), int(last) + 1)
    if beyond.size:
        return _Stop(PASSED, -1, -1, beyond_at)
    return _Stop(NOT_REACHED, -1, -1, len(position))


def _station(stop: Stop, where: _Stop, t: np.ndarray, position: np.ndarray, clock: float,
             window: float, requirements: StationRequirements) -> StationIndices:
    """A station's indices and verdict from where its stop lies (`clock`: the
    timetable's time at the run's t = 0)."""
    nan = math.nan
    stopped = where.outcome == STOPPED
    left = stopped and where.last + 1 < len(t) and stop.departure is not None
    arrival = float(t[where.first]) if stopped and stop.arrival is not None else nan
    departure = float(t[where.last + 1]) if left else nan
    indices = StationIndices(
        stop.station, stop.position, where.outcome,
        float(position[where.last]) - stop.position if stopped else nan, arrival, departure,
        _lateness(arrival, stop.arrival, stop.arrival_window, clock),
        _lateness(departure, stop.departure, stop.departure_window, clock),
        departure - arrival, "", "")
    if stop.arrival is None:
        return indices
    windowed = stop.arrival_window is not None  # judged on its windows, not a tolerance
    verdict, reason = _verdict(indices, requirements, t, position, window, windowed)
    if windowed and indices.outcome == STOPPED:
        timed, why = _window_verdict(stop, indices)
        verdict, reason = (FAIL if FAIL in (verdict, timed) else PASS,
                           "; ".join(filter(None, (reason, why))))
    return indices._replace(verdict=verdict, reason=reason)



def _lateness(time: float, planned: float | None, window: Window | None, clock: float
              ) -> float:
    """s + late against the timetable's time (run clock `time`, `clock` the timetable's
    time at t = 0); against its window where the stop has one: 0 inside, + after it, -
    before it; NaN without a planned time."""
    if planned is None:
        return math.nan
    if window is None:
        return time - (planned - clock)
    return window.miss(time + clock) if math.isfinite(time) else math.nan


def _window_verdict(stop: Stop, station: StationIndices) -> tuple[str, str]:
    """A TTOBench stop's verdict on its windows: the arrival inside its window, and the
    departure inside its window once the train has left."""
    broken = [f"{what} {lateness:+.1f} s outside its window {window.text()}"
              for what, lateness, window in (
                  ("arrival", station.arrival_lateness, stop.arrival_window),
                  ("departure", station.departure_lateness, stop.departure_window))
              if window is not None and math.isfinite(lateness) and lateness != 0.0]
    return (FAIL, "; ".join(broken)) if broken else (PASS, "")


def _verdict(station: StationIndices, requirements: StationRequirements, t: np.ndarray,
             position: np.ndarray, window: float, windowed: bool = False) -> tuple[str, str]:
    """(PASS, FAIL or NOT_JUDGED, what is broken or why it is not judged)."""
    if station.outcome == NOT_REACHED:
        short = station.mark - float(position[-1])
        return NOT_JUDGED, (f"the run ended at t = {float(t[-1]):.1f} s, {abs(short):.1f} m "
                            f"{'short of' if short > 0 else 'past'} the mark, before a stop")
    if station.outcome == PASSED:
        return FAIL, f"no standstill within {window:g} m of the mark"
    broken = []
    if not abs(station.stop_error) <= requirements.stop_error:
        broken.append(f"stop error {station.stop_error:+.3f} m (within "
                      f"{requirements.stop_error:g} m required)")
    if not abs(station.arrival_lateness) <= requirements.arrival_lateness \
            and not windowed:
        broken.append(f"arrival {station.arrival_lateness:+.1f} s against the timetable "
                      f"(within {requirements.arrival_lateness:g} s required)")
    return (FAIL, "; ".join(broken)) if broken else (PASS, "")


def _section(planned: JourneySection, begin: _Stop, end: _Stop, series: tuple[np.ndarray, ...],
             energy_terms: tuple[float, float, float]) -> SectionIndices:
    """A section's indices between the departure at `begin` and the arrival at `end`
    (`series`: t, speed, target, force)."""
    t, speed, target, force = series
    measured = begin.outcome == STOPPED and end.outcome == STOPPED and begin.last + 1 < len(t)
    if not measured:
        return SectionIndices(planned.origin, planned.destination, *[math.nan] * 4)
    # From the departure's last standing sample: the trapezoids cover the whole section.
    span = slice(begin.last, end.first + 1)
    running_time = float(t[end.first] - t[begin.last + 1])
    return SectionIndices(
        planned.origin, planned.destination, running_time,
        running_time - planned.running_time,
        traction_energy_kwh(t[span], speed[span], force[span], *energy_terms),
        float(np.max(np.abs(target[span] - speed[span]))))


def summary_line(indices: JourneyIndices) -> str:
    """The journey's totals on one line, as the report and the console say them."""
    judged = [s for s in indices.stations if s.verdict]
    unjudged = sum(s.verdict == NOT_JUDGED for s in judged)
    parts = [f"{sum(s.verdict == PASS for s in judged)} of {len(judged)} stations met"
             + (f", {unjudged} not judged" if unjudged else "")]
    if indices.timing:
        kept = sum(point.verdict == PASS for point in indices.timing)
        parts.append(f"{kept} of {len(indices.timing)} timing points kept")
    if indices.worst_stop is not None:
        parts.append(f"worst stop {indices.worst_stop.stop_error:+.3f} m at "
                     f"{indices.worst_stop.station}")
    if indices.worst_lateness is not None:
        parts.append(f"worst arrival {indices.worst_lateness.arrival_lateness:+.1f} s at "
                     f"{indices.worst_lateness.station}")
    running = sum(s.running_time for s in indices.sections)
    if math.isfinite(indices.final_arrival_lateness):
        parts.append(f"final arrival {indices.final_arrival_lateness:+.1f} s")
    if math.isfinite(running):  # every section run
        parts.append(f"running time {running:.1f} s")
    if math.isfinite(indices.neutral_traction_command_time):
        parts.append(f"traction commanded in neutral sections "
                     f"{indices.neutral_traction_command_time:.1f} s")
    return "; ".join(parts + [f"traction {indices.traction_energy_kwh:.2f} kWh"])


def journey_record(indices: JourneyIndices) -> dict:
    """The journey's results as the run's JSON files hold them (summary.json, score_bag
    --json, indices.json): its verdict and summary line, a row per station and per
    section with StationIndices' and SectionIndices' fields, SI (m, s, kWh, m/s); NaN
    where nothing was measured (null in the files)."""
    record = {"verdict": indices.verdict, "summary": summary_line(indices),
              "stations": [station._asdict() for station in indices.stations],
              "sections": [section._asdict() for section in indices.sections]}
    if indices.timing:  # a TTOBench journey's
        record["timing_points"] = [point._asdict() for point in indices.timing]
    return record


def last_stop_indices(indices: JourneyIndices, planned_run_time: float | None
                      ) -> dict[str, float]:
    """A journey's whole-run stop indices (catalogue.STOP_INDICES): its last stop's, the
    timetable's last (not the line's last station, nor the last stop reached), as an
    interstation run's are its one stop's; NaN when the train did not stop there."""
    last = indices.stations[-1]  # NaN stop error and arrival without a stop
    stop = {"stopping_error": last.stop_error, "abs_stopping_error": abs(last.stop_error),
            "overrun": float(last.stop_error > BERTHING_TOLERANCE)
            if math.isfinite(last.stop_error) else math.nan, "arrival_time": last.arrival}
    if planned_run_time is not None:
        stop["running_time_error"] = last.arrival - planned_run_time
        stop["abs_running_time_error"] = abs(stop["running_time_error"])
    return stop


def _known(value) -> bool:
    return isinstance(value, (int, float)) and math.isfinite(value)


def last_stop_missed(record: dict) -> str | None:
    """Why a journey's stop indices judge nothing (None when the train stopped at its
    last stop), from its journey_record (or read back from JSON); `error`: the
    journey could not be scored per station."""
    if "error" in record:
        return f"no per-station results: {record['error']}"
    last = record["stations"][-1]
    if last["outcome"] == STOPPED:
        return None
    return f"{last['station']}, the last stop: {last['outcome']} ({last['reason']})"


def _cell(value, form: str) -> str:
    return form.format(value) if _known(value) else "-"


def _timed(time, lateness) -> str:
    """A time on the run's clock (s) with its lateness (s, + late), "-" without one."""
    return f"{time:.1f} ({lateness:+.1f})" if _known(time) else "-"


def format_journey(record: dict) -> list[str]:
    """Console lines of a journey_record (or one read back from JSON): its verdict and
    a row per station; or why it has none."""
    if "error" in record:
        return [f"{'journey':<17}{record['timetable']}: no per-station results: "
                f"{record['error']}"]
    width = max(len(station["station"]) for station in record["stations"])
    lines = [f"{'journey':<17}{record['timetable']}: {record['verdict'].upper()}: "
             f"{record['summary']}",
             f"  {'station':<{width}}  {'stop error m':>12}  {'arrival s (late)':>16}  "
             f"{'departure s (late)':>18}  {'dwell s':>7}  verdict"]
    for s in record["stations"]:
        why = s["reason"] or ("" if s["outcome"] == STOPPED else s["outcome"])
        lines.append(f"  {s['station']:<{width}}  {_cell(s['stop_error'], '{:+.3f}'):>12}  "
                     f"{_timed(s['arrival'], s['arrival_lateness']):>16}  "
                     f"{_timed(s['departure'], s['departure_lateness']):>18}  "
                     f"{_cell(s['dwell'], '{:.1f}'):>7}  "
                     f"{': '.join(filter(None, (s['verdict'] or '-', why)))}")
    return lines + format_timing_points(record.get("timing_points", []))


def format_timing_points(points: list[dict]) -> list[str]:
    """Console lines of a journey_record's timing points (none for a timetable file)."""
    if not points:
        return []
    width = max(len(point["point"]) for point in points)
    lines = [f"  {'timing point':<{width + 10}}  {'window s':>13}  {'time s':>8}  "
             f"{'outside s':>9}  {'km/h':>6}  verdict"]
    for p in points:
        window = f"{_cell(p['earliest'], '{:g}')}-{_cell(p['latest'], '{:g}')}"
        speed = p["speed"] * MS_TO_KMH if _known(p["speed"]) else None
        lines.append(f"  {p['point']:<{width}} {p['kind']:>9}  {window:>13}  "
                     f"{_cell(p['time'], '{:.1f}'):>8}  {_cell(p['miss'], '{:+.1f}'):>9}  "
                     f"{_cell(speed, '{:.1f}'):>6}  "
                     f"{': '.join(filter(None, (p['verdict'], p['reason'])))}")
    return lines
