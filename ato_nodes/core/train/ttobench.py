"""Readers of TTOBench's files (msg_config/ttobench/: tracks, trains, journeys; library
versions 1.1-1.5 as each file declares them), ROS-free: a track as the project's Line, a
train as its plant.* values, a journey as its timing points.

Each file is JSON as its folder's README.md states (msg_config/ttobench/*/README.md),
read bounded (core/base/yamlfile), every problem one ScenarioError line naming the file
and the field. Units are checked against the ones each field states; SI inside.

How the library's quantities map onto the project's (docs/reference.md "TTOBench files"):

* Gradients: per mille, uphill positive in both (the library's README: "positive and
  negative gradient values indicate uphill and downhill sections").
* Curvatures: the library gives each section's signed radius at its start and end
  ("infinity" for straight), the curvature 1/R varying linearly between them (a
  clothoid). The project's curve resistance 600/R is linear in 1/R, so a section of
  constant radius 1/mean(|1/R|) has the clothoid's mean curve resistance: the same
  integral over the section, the mass belt's value wherever the belt covers it; a belt
  shorter than the section is off by at most 600 |1/R_end - 1/R_start| / 2 N/kN.
* Tunnels: the Line keeps each tunnel's extent, so the plant applies the project's
  w_s = 0.00013 L_s N/kN (TB/T 1407's tunnel resistance, the one formula its lines use);
  the cross section the library gives is kept on the Track, and the library's own,
  speed-dependent term (a train's extra c(A) V^2 kN in a tunnel of cross section A) is
  tunnel_drag(), which no run applies yet.
* Trains: the library's Davis coefficients are the whole train's, in kN; the project's
  are per kN of weight, converted here at the train's own mass. A train's values set
  plant.davis_absolute, under which plant.mass_factor (a load) leaves the resistance in
  kN as it is (the library's absolute coefficients: air drag does not grow with the
  load), and plant.max_running_speed, the train's maximum speed, which caps the line's
  limits (core/train/lines.py).
* Envelopes: traction the library's force and power, the brake the blended one
  (regenerative plus pneumatic), each capped at the comfort limit of the effective mass
  (Train.traction_envelope, Train.brake_envelope); what the library leaves out of a
  train (length, comfort limits) is SUPPLEMENTS', each with its source.
"""

from __future__ import annotations

import json
import math
import re
import reprlib
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from ..base import yamlfile
from ..base.errors import ScenarioError
from ..base.units import KMH
from .line import MAX_LENGTH, Line, Section, Station

VERSIONS = tuple(f"TTOBench v1.{minor}" for minor in range(1, 6))
IDENTIFIER = re.compile(r"[A-Za-z0-9_]+")
METADATA_REQUIRED = ("id", "library version")
DEFAULT_DWELL = 0.0  # s at a stop no journey gives a dwell for: none required (line files')
LIBRARY_SUFFIX = ".json"  # the library's files are JSON; the project's own are YAML


def is_library_file(path: str | Path) -> bool:
    """Whether a file parameter (line.file, plant.train, a timetable, a timetable's train)
    names a TTOBench file rather than one of the project's (a line file, a train preset,
    a timetable file): by its name, so a bag's copy, which keeps the name, reads as the
    original did."""
    return Path(path).suffix.lower() == LIBRARY_SUFFIX


# ------------------------------------------------------------------ reading JSON ----


def read_json(path: str | Path, what: str) -> Any:
    """A TTOBench file's JSON, read as the project reads a user's file (regular, at most
    1 MiB, UTF-8), without duplicate keys or NaN/Infinity; one line otherwise."""
    return parse_json(yamlfile.read_text(path, what), path)


def parse_json(text: str, path: str | Path) -> Any:
    """read_json of a file's `text` (a copy kept in a bag); `path` names it in errors."""
    def unique(pairs):
        document = dict(pairs)
        if len(document) < len(pairs):
            seen: set[str] = set()
            twice = next(key for key, _ in pairs if key in seen or seen.add(key))
            raise ScenarioError(f"{path}: key {reprlib.repr(twice)} is given twice")
        return document

    def no_constant(name):
        raise ScenarioError(f"{path}: {name} is not a number (JSON has no {name})")

    try:
        return json.loads(text, object_pairs_hook=unique, parse_constant=no_constant)
    except json.JSONDecodeError as exc:
        raise ScenarioError(f"{path} line {exc.lineno}: malformed JSON ({exc.msg})") from None
    except RecursionError:
        raise ScenarioError(f"{path}: nested too deeply") from None


class Fields:
    """A file's top-level fields, read one at a time; each problem one line naming the
    file and the field."""

    def __init__(self, path: Path, document: Any, what: str, required: tuple[str, ...],
                 optional: tuple[str, ...]):
        self.path = path
        if not isinstance(document, dict):
            raise ScenarioError(f"{path}: a TTOBench {what} file is a JSON object")
        unknown = sorted(set(document) - {"metadata", *required, *optional})
        if unknown:
            raise ScenarioError(f"{path}: unknown field {reprlib.repr(unknown[0])}")
        missing = next((name for name in ("metadata", *required) if name not in document),
                       None)
        if missing is not None:
            raise ScenarioError(f"{path}: missing field {missing!r}")
        self.document = document

    def error(self, field: str, message: str) -> ScenarioError:
        return ScenarioError(f"{self.path}: {field}: {message}")

    def object(self, field: str, value: Any) -> dict:
        if not isinstance(value, dict):
            raise self.error(field, f"must be a JSON object, not {reprlib.repr(value)}")
        return value

    def number(self, field: str, value: Any) -> float:
        """`value` as a float: a finite JSON number (not true/false; an integer too large
        for a float is not finite)."""
        number = math.nan
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            try:
                number = float(value)
            except OverflowError:
                pass
        if not math.isfinite(number):
            raise self.error(field, f"must be a finite number, not {reprlib.repr(value)}")
        return number

    def metadata(self, extra: tuple[str, ...] = ()) -> dict:
        """The metadata with its required text fields checked: id (letters, digits,
        underscores), library version (one of VERSIONS)."""
        metadata = self.object("metadata", self.document["metadata"])
        for key in (*METADATA_REQUIRED, *extra):
            if not isinstance(metadata.get(key), str):
                raise self.error("metadata", f"{key!r} must be given as text")
        if not IDENTIFIER.fullmatch(metadata["id"]):
            raise self.error("metadata", f"id {reprlib.repr(metadata['id'])} must be "
                             "letters, digits and underscores")
        if metadata["library version"] not in VERSIONS:
            version = reprlib.repr(metadata["library version"])
            raise self.error("metadata", f"library version {version} is not one read here "
                             f"({', '.join(VERSIONS)})")
        return metadata

    def quantity(self, field: str, unit: str, low: float = -math.inf,
                 above: bool = False) -> float | None:
        """{"unit": unit, "value": number} of `field` (None if absent), at least `low`
        (above it when `above`)."""
        if field not in self.document:
            return None
        entry = self.object(field, self.document[field])
        if set(entry) != {"unit", "value"} or entry["unit"] != unit:
            raise self.error(field, f'must be {{"unit": "{unit}", "value": ...}}')
        value = self.number(field, entry["value"])
        if value < low or (above and value == low):
            raise self.error(field, f"{value:g} {unit} must be {'above' if above else 'at least'}"
                             f" {low:g}")
        return value

    def table(self, field: str, units: dict[str, str]) -> list[list]:
        """The rows of {"units": {column: unit, ...}, "values": [[...], ...]}, each with
        one entry per column ([] if absent)."""
        if field not in self.document:
            return []
        entry = self.object(field, self.document[field])
        if set(entry) != {"units", "values"} or entry["units"] != units:
            raise self.error(field, f"must be {{\"units\": {json.dumps(units)}, "
                             "\"values\": [...]}")
        rows = entry["values"]
        if not isinstance(rows, list):
            raise self.error(field, "values must be a list")
        for number, row in enumerate(rows, 1):
            if not isinstance(row, list) or len(row) != len(units):
                raise self.error(f"{field} entry {number}", f"must be a list of "
                                 f"{len(units)} ({', '.join(units)}), not {reprlib.repr(row)}")
        return rows

# ---------------------------------------------------------------------- tracks ----

TRACK_FIELDS = ("stops", "speed limits")
TRACK_OPTIONAL = ("altitude", "gradients", "curvatures", "tunnels", "ETCS braking data")
TRACK_ETCS = ("M_NVAVADH", "Kt_int")
STRAIGHT = "infinity"  # the library's radius of a straight section


@dataclass(frozen=True)
class Curvature:
    """A section whose curvature varies linearly from 1/radius_start to 1/radius_end
    (signed: + right-hand, - left-hand; inf straight): a clothoid, or a circle when equal."""

    start: float          # m
    end: float            # m
    radius_start: float   # m
    radius_end: float     # m

    @property
    def mean_curvature(self) -> float:
        """The mean of |1/R| over the section, 1/m (curve resistance is linear in it)."""
        return mean_curvature(self.radius_start, self.radius_end)


@dataclass(frozen=True)
class Tunnel:
    start: float          # m
    length: float         # m
    cross_section: float  # m^2


@dataclass(frozen=True)
class Track:
    """A TTOBench track: its stops (m, the first 0, the last its length), speed limits
    (m/s), gradients (per mille, uphill +), curvatures and tunnels, as sections."""

    id: str
    version: str
    path: Path
    altitude: float | None        # m at the start
    stops: tuple[float, ...]      # m
    speed_limits: tuple[Section, ...]
    gradients: tuple[Section, ...]
    curvatures: tuple[Curvature, ...]
    tunnels: tuple[Tunnel, ...]

    @property
    def length(self) -> float:
        return self.stops[-1]

    def line(self, journey: Journey | None = None) -> Line:
        """The project's Line of the track: a station at every stop of the track and of
        `journey` (named by its kilometre), its dwell the journey's least
        (Journey.dwells) or DEFAULT_DWELL; curves of constant mean curvature (module
        docstring); tunnels by their extent; no neutral sections, no planned time."""
        if journey is not None:
            journey.check_on(self)
        dwells = journey.dwells() if journey is not None else {}
        stops = sorted({*self.stops, *dwells})
        curves = tuple(Section(c.start, c.end, 1.0 / c.mean_curvature)
                       for c in self.curvatures if c.mean_curvature > 0.0)
        tunnels = tuple(Section(t.start, t.start + t.length, 0.0)
                        for t in self.tunnels if t.length > 0.0)
        return Line(name=self.id, length=self.length, gradients=self.gradients,
                    curves=curves, tunnels=tunnels, speed_limits=self.speed_limits,
                    neutral_sections=(),
                    stations=tuple(Station(f"km {stop / 1000:g}", stop,
                                           dwells.get(stop, DEFAULT_DWELL)) for stop in stops),
                    planned_run_time=None)


def mean_curvature(radius_start: float, radius_end: float) -> float:
    """Mean of |k| over a section whose curvature k runs linearly from 1/radius_start to
    1/radius_end, 1/m: the mean of the ends, or where k changes sign (a reverse curve's
    transition) (k0^2 + k1^2) / (2 (|k0| + |k1|)), the areas of the two triangles."""
    k0, k1 = 1.0 / radius_start, 1.0 / radius_end
    if k0 * k1 >= 0.0:
        return (abs(k0) + abs(k1)) / 2.0
    return (k0 * k0 + k1 * k1) / (2.0 * (abs(k0) + abs(k1)))


def load_track(path: str | Path) -> Track:
    """A TTOBench track file, validated (one ScenarioError line naming file and field)."""
    return parse_track(yamlfile.read_text(path, "TTOBench track"), path)


def parse_track(text: str, path: str | Path) -> Track:
    """load_track of a track file's `text` (a copy kept in a bag); `path` names it."""
    path = Path(path)
    fields = Fields(path, parse_json(text, path), "track", TRACK_FIELDS, TRACK_OPTIONAL)
    metadata = fields.metadata()
    stops = _stops(fields)
    length = stops[-1]
    _check_object(fields, "ETCS braking data", TRACK_ETCS)
    return Track(
        id=metadata["id"], version=metadata["library version"], path=path,
        altitude=fields.quantity("altitude", "m"), stops=stops,
        speed_limits=_step_sections(fields, "speed limits",
                                    {"position": "m", "velocity": "km/h"}, length, _limit),
        gradients=_step_sections(fields, "gradients", {"position": "m", "slope": "permil"},
                                 length, Fields.number),
        curvatures=_curvatures(fields, length), tunnels=_tunnels(fields, length))


def _limit(fields: Fields, name: str, value: Any) -> float:
    """A speed limit in km/h, above 0, as m/s."""
    limit = fields.number(name, value)
    if not limit > 0.0:
        raise fields.error(name, f"the speed limit {limit:g} km/h must be above 0")
    return limit * KMH


def _stops(fields: Fields) -> tuple[float, ...]:
    """The stops: 0 first, strictly increasing, the last (the track's length) at most
    the longest line a run may have."""
    entry = fields.object("stops", fields.document["stops"])
    if set(entry) != {"unit", "values"} or entry["unit"] != "m" \
            or not isinstance(entry["values"], list):
        raise fields.error("stops", 'must be {"unit": "m", "values": [...]}')
    stops = tuple(fields.number(f"stops entry {number}", value)
                  for number, value in enumerate(entry["values"], 1))
    if len(stops) < 2 or stops[0] != 0.0:
        raise fields.error("stops", "must list at least two positions, the first 0")
    for number in range(1, len(stops)):
        if not stops[number] > stops[number - 1]:
            raise fields.error(f"stops entry {number + 1}", f"{stops[number]:g} m does not "
                               f"follow {stops[number - 1]:g} m (strictly increasing)")
    if stops[-1] > MAX_LENGTH:
        raise fields.error("stops", f"the track's length {stops[-1]:g} m is beyond "
                           f"{MAX_LENGTH:g} m (the longest line a run may have)")
    return stops


def _steps(fields: Fields, field: str, units: dict[str, str], length: float) -> list[list]:
    """A table of rows starting at a position each: the first at 0, strictly
    increasing, the last before the track's end."""
    rows = fields.table(field, units)
    if field in fields.document and not rows:
        raise fields.error(field, "must have at least one entry")
    previous = None
    for number, row in enumerate(rows, 1):
        name = f"{field} entry {number}"
        position = fields.number(name, row[0])
        if previous is None and position != 0.0:
            raise fields.error(name, f"the first position must be 0, not {position:g} m")
        if previous is not None and not position > previous:
            raise fields.error(name, f"{position:g} m does not follow {previous:g} m "
                               "(strictly increasing)")
        if not position < length:
            raise fields.error(name, f"{position:g} m is not before the track's end "
                               f"({length:g} m)")
        previous = position
    return rows


def _step_sections(fields: Fields, field: str, units: dict[str, str], length: float,
                   value) -> tuple[Section, ...]:
    """A table of (position, value) rows (_steps) as sections, each to the next row's
    position (the last to the track's end), its value value(fields, entry's name, value)."""
    rows = _steps(fields, field, units, length)
    ends = [row[0] for row in rows[1:]] + [length][:len(rows)]
    return tuple(Section(float(row[0]), float(end), value(fields, f"{field} entry {number}",
                                                          row[1]))
                 for number, (row, end) in enumerate(zip(rows, ends, strict=True), 1))


def _curvatures(fields: Fields, length: float) -> tuple[Curvature, ...]:
    units = {"position": "m", "radius at start": "m", "radius at end": "m"}
    rows = _steps(fields, "curvatures", units, length)
    ends = [row[0] for row in rows[1:]] + [length][:len(rows)]
    return tuple(Curvature(float(row[0]), float(end),
                           *(_radius(fields, f"curvatures entry {number}", radius)
                             for radius in row[1:]))
                 for number, (row, end) in enumerate(zip(rows, ends, strict=True), 1))


def _radius(fields: Fields, name: str, value: Any) -> float:
    """A signed radius, m: "infinity" (straight) or a number other than 0."""
    if value == STRAIGHT:
        return math.inf
    if isinstance(value, (int, float)) and not isinstance(value, bool) \
            and math.isfinite(value) and value != 0:
        return float(value)
    raise fields.error(name, f'a radius is a number other than 0, or "{STRAIGHT}", not '
                       f"{reprlib.repr(value)}")


def _tunnels(fields: Fields, length: float) -> tuple[Tunnel, ...]:
    """The tunnels: strictly increasing starts, none overlapping the one before (the
    library splits a tunnel into one entry per cross section), each within the track."""
    units = {"position": "m", "length": "m", "cross section": "m^2"}
    tunnels: list[Tunnel] = []
    for number, row in enumerate(fields.table("tunnels", units), 1):
        name = f"tunnels entry {number}"
        start, extent, area = (fields.number(name, value) for value in row)
        if start < 0.0 or extent < 0.0 or not area > 0.0:
            raise fields.error(name, "position and length must be at least 0, the cross "
                               "section above 0")
        if tunnels and start < tunnels[-1].start + tunnels[-1].length:
            raise fields.error(name, f"starts at {start:g} m, before the tunnel before it "
                               f"ends ({tunnels[-1].start + tunnels[-1].length:g} m)")
        if start + extent > length:
            raise fields.error(name, f"ends at {start + extent:g} m, beyond the track's end "
                               f"({length:g} m)")
        tunnels.append(Tunnel(start, extent, area))
    return tuple(tunnels)


def _check_object(fields: Fields, field: str, required: tuple[str, ...]) -> None:
    """An optional object the project does not read (ETCS braking data): when given, an
    object with all of `required` (the library requires them all)."""
    if field in fields.document:
        entry = fields.object(field, fields.document[field])
        missing = next((name for name in required if name not in entry), None)
        if missing is not None:
            raise fields.error(field, f"missing {missing!r} (all of {', '.join(required)} "
                               "must be given)")

# -------------------------------------------------------------------- journeys ----

TIMING_UNITS = {"position": "m", "lower time constraint": "s", "upper time constraint": "s",
                "lower speed constraint": "km/h", "upper speed constraint": "km/h"}


@dataclass(frozen=True)
class TimingPoint:
    """A journey's constraint at a position: a time window [earliest, latest] (s from the
    journey's start) and speed bounds [min_speed, max_speed] (m/s); None = not set."""

    position: float            # m
    earliest: float | None     # s
    latest: float | None       # s
    min_speed: float | None    # m/s
    max_speed: float | None    # m/s

    @property
    def stopping(self) -> bool:
        """A stopping point (both speed bounds 0), else a passing point."""
        return self.min_speed == 0.0 and self.max_speed == 0.0


@dataclass(frozen=True)
class Journey:
    """A TTOBench journey: timing points on its track, in order, from the departure of
    its first section to the arrival of its last; an intermediate stop is an arrival and
    a departure stopping point at the same position."""

    id: str
    version: str
    path: Path
    track_id: str
    points: tuple[TimingPoint, ...]

    @property
    def sections(self) -> tuple[tuple[TimingPoint, ...], ...]:
        """The journey sections: from a departure stopping point to the next arrival
        stopping point, the passing points between them included."""
        stops = [number for number, point in enumerate(self.points) if point.stopping]
        return tuple(self.points[start:end + 1]
                     for start, end in zip(stops[::2], stops[1::2], strict=True))

    def dwells(self) -> dict[float, float]:
        """The stops (m) with the least dwell their windows allow, s: the departure's
        earliest time less the arrival's latest, at least 0 (0 where either is not set);
        the first and last stops 0."""
        dwells = {self.points[0].position: 0.0, self.points[-1].position: 0.0}
        for before, after in zip(self.sections, self.sections[1:], strict=False):
            arrival, departure = before[-1], after[0]
            least = 0.0
            if arrival.latest is not None and departure.earliest is not None:
                least = max(departure.earliest - arrival.latest, 0.0)
            dwells[arrival.position] = least
        return dwells

    def check_on(self, track: Track) -> None:
        """ScenarioError (one line) unless the journey is `track`'s and lies on it."""
        if track.id != self.track_id:
            raise ScenarioError(f"{self.path}: metadata: associated track "
                                f"{reprlib.repr(self.track_id)} is not {track.path}'s "
                                f"({reprlib.repr(track.id)})")
        beyond = next((point for point in self.points if point.position > track.length), None)
        if beyond is not None:
            raise ScenarioError(f"{self.path}: timing points: {beyond.position:g} m is beyond "
                                f"the end of track {track.id} ({track.length:g} m)")


def load_journey(path: str | Path, track: Track | None = None) -> Journey:
    """A TTOBench journey file, validated by the library's rules (journeys/README.md), on
    `track` when given (its associated track, every point on it); one ScenarioError line
    naming the file and the field."""
    journey = parse_journey(yamlfile.read_text(path, "TTOBench journey"), path)
    if track is not None:
        journey.check_on(track)
    return journey


def parse_journey(text: str, path: str | Path) -> Journey:
    """load_journey of a journey file's `text` (a copy kept in a bag); `path` names it."""
    path = Path(path)
    fields = Fields(path, parse_json(text, path), "journey", ("timing points",), ())
    metadata = fields.metadata(("associated track",))
    if not metadata["id"].startswith(metadata["associated track"] + "_"):
        raise fields.error("metadata", f"id {reprlib.repr(metadata['id'])} must start with "
                           f"the associated track {reprlib.repr(metadata['associated track'])} "
                           "and an underscore")
    rows = fields.table("timing points", TIMING_UNITS)
    points = tuple(_timing_point(fields, f"timing points entry {number}", row)
                   for number, row in enumerate(rows, 1))
    _check_points(fields, points)
    return Journey(metadata["id"], metadata["library version"], path,
                   metadata["associated track"], points)


def _timing_point(fields: Fields, name: str, row: list) -> TimingPoint:
    """A row as a TimingPoint: numbers at least 0 or null, each lower bound at most its
    upper; speeds km/h -> m/s."""
    position, *bounds = (None if value is None else fields.number(name, value)
                         for value in row)
    if position is None or any(value is not None and value < 0.0 for value in bounds) \
            or position < 0.0:
        raise fields.error(name, "the position must be given; every value at least 0")
    earliest, latest, low, high = bounds
    if earliest is not None and latest is not None and earliest > latest:
        raise fields.error(name, f"the lower time constraint {earliest:g} s is above the "
                           f"upper {latest:g} s")
    if low is not None and high is not None and low > high:
        raise fields.error(name, f"the lower speed constraint {low:g} km/h is above the "
                           f"upper {high:g} km/h")
    return TimingPoint(position, earliest, latest, *(None if value is None else value * KMH
                                                      for value in (low, high)))


def _check_points(fields: Fields, points: tuple[TimingPoint, ...]) -> None:
    """The library's rules on the order: two points at least, the first and last
    stopping, positions non-decreasing, an intermediate stopping point one of an
    arrival-departure pair at one position (and only such a pair shares a position), no
    time window wholly before an earlier point's."""
    if len(points) < 2 or not points[0].stopping or not points[-1].stopping:
        raise fields.error("timing points", "at least two, the first and the last stopping "
                           "points (both speed constraints 0)")
    earliest = None  # the latest lower time constraint of the points before
    for number in range(2, len(points) + 1):
        before, point = points[number - 2], points[number - 1]
        name = f"timing points entry {number}"
        if before.earliest is not None:
            earliest = before.earliest if earliest is None else max(earliest, before.earliest)
        if point.position < before.position:
            raise fields.error(name, f"{point.position:g} m is before {before.position:g} m "
                               "(positions must not decrease)")
        pair = point.position == before.position
        if pair and not (point.stopping and before.stopping):
            raise fields.error(name, f"shares {point.position:g} m with the point before: "
                               "only an arrival and a departure stopping point may")
        if earliest is not None and point.latest is not None and point.latest < earliest:
            raise fields.error(name, f"its upper time constraint {point.latest:g} s is before "
                               f"an earlier point's lower one ({earliest:g} s)")
    _check_pairs(fields, points)


def _check_pairs(fields: Fields, points: tuple[TimingPoint, ...]) -> None:
    """Every stopping point but the first and the last is one of a pair, an arrival and
    a departure at one position, which no other point shares."""
    number = 1
    while number < len(points) - 1:
        if not points[number].stopping:
            number += 1
            continue
        arrival, departure = points[number], points[number + 1]
        if not (departure.stopping and departure.position == arrival.position) \
                or number + 1 == len(points) - 1 \
                or points[number - 1].position == arrival.position \
                or points[number + 2].position == arrival.position:
            raise fields.error(f"timing points entry {number + 1}", f"a stop at "
                               f"{arrival.position:g} m is an arrival and a departure stopping "
                               "point at that position, and no other point there")
        number += 2

# ---------------------------------------------------------------------- trains ----

TRAIN_FIELDS = ("mass", "max traction power", "max reg braking power", "max traction force",
                "max reg braking force", "max speed", "rolling resistance r0",
                "rolling resistance r1", "rolling resistance r2")
TRAIN_OPTIONAL = ("num seats", "num coaches", "length", "rho", "max pn braking force",
                  "max acceleration", "max deceleration", "efficiency traction",
                  "efficiency reg brake", "tunnel resistance", "ETCS braking data")
TRAIN_ETCS = ("A_brake_emergency", "A_brake_service", "K_dry_rst", "K_wet_rst", "T_traction",
              "T_be", "T_bs", "v_uncertainty")
KN, KW = 1000.0, 1000.0  # N per kN, W per kW


@dataclass(frozen=True)
class Supplement:
    """What the library does not give of a train, and where the project's value is from."""

    length: float | None            # m (None: the library's own, or a point mass)
    max_acceleration: float | None  # m/s^2, when the library gives none
    max_deceleration: float | None  # m/s^2, when the library gives none
    source: str


# What the library leaves out of a train, in one place (docs/reference.md "TTOBench
# files"): its length and comfort limits where the file gives none, here, with the source
# (a limit the file gives wins; with none here either, the envelope alone bounds); the
# brake envelope's shape, Train.brake_envelope's stated rule; dead time, actuator lag and
# pantograph offset, none given: the schema's defaults.
SUPPLEMENTS = {
    "CN_Beijing_Subway": Supplement(
        118.0, 1.0, 1.0, "the project's metro-b preset (msg_config/trains/metro-b.yaml: the "
        "6-car B-type metro of this line, public figures): length 118 m, |a| <= 1 m/s^2"),
    "CH_Stadler_KISS_SBB": Supplement(
        150.0, None, None, "length 150 m: the 6-car SBB RABe 511 (KISS), an assumption (the "
        "commonly quoted length, not checked against a published source)"),
    "NL_Intercity_VIRM6": Supplement(
        162.1, None, None, "length 162.1 m: the 6-car NS VIRM, an assumption (the commonly "
        "quoted length, not checked against a published source); no acceleration limit: the "
        "envelope's "
        "213.9 kN / 414.5 t = 0.52 m/s^2 binds first"),
}


@dataclass(frozen=True)
class Train:
    """A TTOBench train as the library gives it, SI: the whole train's forces (N),
    powers (W) and Davis coefficients r0 N, r1 N/(m/s), r2 N/(m/s)^2 (absolute: they do
    not grow with the load); None where an optional field is absent."""

    id: str
    version: str
    path: Path
    mass: float                      # kg
    rotating_share: float            # rho / 100: the rotating mass factor is 1 + this
    max_speed: float                 # m/s
    traction_force: float            # N
    traction_power: float            # W
    regenerative_force: float        # N
    regenerative_power: float        # W
    pneumatic_force: float           # N (0 when not given)
    max_acceleration: float | None   # m/s^2, passenger comfort
    max_deceleration: float | None   # m/s^2, passenger comfort
    davis: tuple[float, float, float]
    traction_efficiency: float | None      # 0-1
    regenerative_efficiency: float | None  # 0-1
    length: float | None             # m
    tunnel_coefficients: tuple[tuple[float, float], ...]  # (m^2, N/(m/s)^2) extra in a tunnel

    @property
    def effective_mass(self) -> float:
        """The mass with its rotating share, kg: what a force accelerates."""
        return self.mass * (1.0 + self.rotating_share)

    @property
    def comfort(self) -> tuple[float | None, float | None]:
        """(max acceleration, max deceleration), m/s^2: the library's, else SUPPLEMENTS'
        (None: the envelope alone bounds)."""
        supplement = SUPPLEMENTS.get(self.id)
        return (self.max_acceleration if self.max_acceleration is not None
                else getattr(supplement, "max_acceleration", None),
                self.max_deceleration if self.max_deceleration is not None
                else getattr(supplement, "max_deceleration", None))

    @property
    def train_length(self) -> float | None:
        """m: the library's, else SUPPLEMENTS' (None: unknown)."""
        supplement = SUPPLEMENTS.get(self.id)
        return self.length if self.length is not None else getattr(supplement, "length", None)

    def traction_envelope(self) -> tuple[float, float]:
        """(force N, power W) of the project's traction envelope min(F, P / v): the
        library's force, capped at the comfort acceleration of the effective mass where
        there is one (min(cap, F, P / v) = min(min(cap, F), P / v): exact)."""
        force = self.traction_force
        if self.comfort[0] is not None:
            force = min(force, self.effective_mass * self.comfort[0])
        return force, self.traction_power

    def brake_envelope(self) -> tuple[float, float]:
        """(force F N, power P W) of the project's brake envelope min(F, P / v) for the
        blended brake: regenerative min(F_r, P_r / v) plus pneumatic F_p, capped at the
        comfort deceleration of the effective mass. F = min(F_r + F_p, cap); P makes the
        envelope meet the blended brake where that first falls below F and stay under it
        above: P = F P_r / (F - F_p) (P_r without a pneumatic brake); when the pneumatic
        brake alone gives F, or the speed where it falls below F is beyond the train's
        v_max, the blended brake is F at every speed it runs: P = F v_max."""
        force = self.regenerative_force + self.pneumatic_force
        if self.comfort[1] is not None:
            force = min(force, self.effective_mass * self.comfort[1])
        knee = self.max_speed  # m/s where the blended brake first falls below `force`
        if force * self.max_speed > self.pneumatic_force * self.max_speed \
                + self.regenerative_power:
            knee = self.regenerative_power / (force - self.pneumatic_force)
        return force, force * knee

    def specific_davis(self, mass: float, gravity: float) -> tuple[float, float, float]:
        """The project's Davis a N/kN, b N/kN per m/s, c N/kN per (m/s)^2 of this train at
        `mass` (t; its own, or loaded) under `gravity` (m/s^2): the absolute coefficients
        over the weight m g (kN), so that the resistance in kN stays the library's."""
        weight = mass * gravity  # kN
        return tuple(coefficient / KN / weight * 1000.0 for coefficient in self.davis)

    def plant_values(self, gravity: float) -> dict[str, Any]:
        """The project's plant.* values of the train (a train preset's), under `gravity`
        (plant.gravity): mass t, gamma = rho / 100, Davis per kN at its own mass and kept
        absolute under a load (plant.davis_absolute), the envelopes in kN and kW, the
        maximum speed (plant.max_running_speed), plant.efficiency the traction efficiency,
        the regenerative brake's force, power and efficiency (plant.regenerative_*), the
        length where known (else the schema's point mass); no seed 000 test disturbance
        (plant.disturbance.amplitude 0, as every realistic preset)."""
        a, b, c = self.specific_davis(self.mass / 1000.0, gravity)
        traction, brake = self.traction_envelope(), self.brake_envelope()
        values = {"plant.mass": self.mass / 1000.0, "plant.gamma": self.rotating_share,
                  "plant.davis_a": a, "plant.davis_b": b, "plant.davis_c": c,
                  "plant.davis_absolute": True, "plant.max_running_speed": self.max_speed,
                  "plant.disturbance.amplitude": 0.0,
                  "plant.envelope": True,
                  "plant.max_traction_force": traction[0] / KN,
                  "plant.max_traction_power": traction[1] / KW,
                  "plant.max_brake_force": brake[0] / KN, "plant.max_brake_power": brake[1] / KW,
                  "plant.regenerative_limits": True,
                  "plant.regenerative_force": self.regenerative_force / KN,
                  "plant.regenerative_power": self.regenerative_power / KW}
        if self.traction_efficiency is not None:
            values["plant.efficiency"] = self.traction_efficiency
        if self.regenerative_efficiency is not None:
            values["plant.regenerative_efficiency"] = self.regenerative_efficiency
        if self.train_length is not None:
            values["plant.length"] = self.train_length
        return values

    def planning_values(self) -> dict[str, float]:
        """The ATO curve's planned acceleration and deceleration (profile.ato.*): the
        comfort limits where known."""
        names = ("profile.ato.acceleration", "profile.ato.deceleration")
        return {name: limit for name, limit in zip(names, self.comfort, strict=True)
                if limit is not None}

    def tunnel_drag(self, cross_section: float, speed: float) -> float:
        """The library's extra aerodynamic resistance in a tunnel of `cross_section` (m^2)
        at `speed` (m/s), N: c(A) v^2 with the train's coefficient for that cross
        section; ScenarioError (one line) when it gives none for it."""
        for area, coefficient in self.tunnel_coefficients:
            if area == cross_section:
                return coefficient * speed * speed
        given = ", ".join(f"{area:g}" for area, _ in self.tunnel_coefficients) or "none"
        raise ScenarioError(f"{self.path}: tunnel resistance: no coefficient for a cross "
                            f"section of {cross_section:g} m^2 (given: {given})")


def load_train(path: str | Path) -> Train:
    """A TTOBench train file, validated (one ScenarioError line naming file and field)."""
    path = Path(path)
    fields = Fields(path, read_json(path, "TTOBench train"), "train", TRAIN_FIELDS,
                    TRAIN_OPTIONAL)
    metadata = fields.metadata()
    _check_object(fields, "ETCS braking data", TRAIN_ETCS)
    for field in ("num seats", "num coaches"):
        count = fields.quantity(field, "-", 0.0)
        if count is not None and count != int(count):
            raise fields.error(field, f"{count:g} is not a whole number")
    forces = _forces(fields)
    if not forces["regenerative_force"] + forces["pneumatic_force"] > 0.0:
        raise fields.error("max reg braking force", "a train without a brake (no "
                           "regenerative and no pneumatic braking force)")
    return Train(
        id=metadata["id"], version=metadata["library version"], path=path,
        mass=fields.quantity("mass", "kg", 0.0, above=True),
        rotating_share=(fields.quantity("rho", "%", 0.0) or 0.0) / 100.0,
        max_speed=fields.quantity("max speed", "km/h", 0.0, above=True) * KMH, **forces,
        max_acceleration=fields.quantity("max acceleration", "m/s^2", 0.0, above=True),
        max_deceleration=fields.quantity("max deceleration", "m/s^2", 0.0, above=True),
        davis=(fields.quantity("rolling resistance r0", "kN", 0.0) * KN,
               fields.quantity("rolling resistance r1", "kN/(km/h)", 0.0) * KN / KMH,
               fields.quantity("rolling resistance r2", "kN/(km/h)^2", 0.0) * KN / KMH ** 2),
        traction_efficiency=_efficiency(fields, "efficiency traction"),
        regenerative_efficiency=_efficiency(fields, "efficiency reg brake"),
        length=fields.quantity("length", "m", 0.0, above=True),
        tunnel_coefficients=_tunnel_coefficients(fields))


def same_train(path: str | Path, other: str | Path) -> bool:
    """Whether two TTOBench train files give the same train: the same path, or the same
    contents wherever each lies (a copy, a bag's run recorded in another checkout); one
    ScenarioError line for a file that cannot be read."""
    return Path(path) == Path(other) or _wherever(path) == _wherever(other)


def _wherever(path: str | Path) -> Train:
    return replace(load_train(path), path=Path())


def _forces(fields: Fields) -> dict[str, float]:
    """The envelopes' forces (N) and powers (W): traction above 0, braking at least 0,
    the pneumatic force 0 when not given (the library's rule)."""
    def given(field: str, unit: str, scale: float, above: bool = False) -> float:
        return (fields.quantity(field, unit, 0.0, above) or 0.0) * scale

    return {"traction_force": given("max traction force", "kN", KN, above=True),
            "traction_power": given("max traction power", "kW", KW, above=True),
            "regenerative_force": given("max reg braking force", "kN", KN),
            "regenerative_power": given("max reg braking power", "kW", KW),
            "pneumatic_force": given("max pn braking force", "kN", KN)}


def _efficiency(fields: Fields, field: str) -> float | None:
    """An efficiency in %, above 0 and at most 100, as a share (None if absent)."""
    percent = fields.quantity(field, "%", 0.0, above=True)
    if percent is not None and percent > 100.0:
        raise fields.error(field, f"{percent:g} % is above 100 %")
    return None if percent is None else percent / 100.0


def _tunnel_coefficients(fields: Fields) -> tuple[tuple[float, float], ...]:
    """(cross section m^2, coefficient N/(m/s)^2) of each row, cross sections above 0 and
    each once, coefficients at least 0."""
    units = {"cross section": "m^2", "coefficient": "kN/(km/h)^2"}
    coefficients: dict[float, float] = {}
    for number, row in enumerate(fields.table("tunnel resistance", units), 1):
        name = f"tunnel resistance entry {number}"
        area, coefficient = (fields.number(name, value) for value in row)
        if not area > 0.0 or coefficient < 0.0 or area in coefficients:
            raise fields.error(name, "the cross section must be above 0 and given once, the "
                               "coefficient at least 0")
        coefficients[area] = coefficient * KN / KMH ** 2
    return tuple(coefficients.items())
