"""Line data: gradients, curves, tunnels, speed limits, neutral sections, stations.

A line file (msg_config/lines/*.yaml) is validated on load; every problem is
one ScenarioError naming the file and the line of the offending entry.
Positions are metres from the line's origin; SI units throughout (speed
limits in m/s). Sections of one kind must be ordered and must not overlap.

The train is a uniform mass belt of length L whose head is at x (seed 002):
the additional specific resistance is the average over the belt [x - L, x]
of the point values, so it equals the single-point value while the train lies
wholly on one section and varies linearly while it straddles a change:

    gradient  i       per mille = N/kN, uphill positive
    curve     600 / R N/kN (R in m)
    tunnel    0.00013 L_s N/kN (L_s the tunnel's length in m)
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, NamedTuple

import numpy as np
import yaml

from ..base import yamlfile
from ..base.errors import ScenarioError
from ..base.kernels import compiled, jitable

MAX_LENGTH = 2.0e6         # m: longer than any line; bounds what the ATO curve allocates
CURVE_CONSTANT = 600.0     # A of w_r = A / R, N/kN m
TUNNEL_CONSTANT = 0.00013  # w_s = 0.00013 L_s, N/kN per m of tunnel


@dataclass(frozen=True)
class Section:
    start: float
    end: float
    value: float  # per kind: grade (per mille), radius (m), limit (m/s), 0 for tunnels etc.


@dataclass(frozen=True)
class Station:
    name: str
    position: float
    dwell: float


@dataclass(frozen=True)
class Line:
    name: str
    length: float
    gradients: tuple[Section, ...]
    curves: tuple[Section, ...]
    tunnels: tuple[Section, ...]
    speed_limits: tuple[Section, ...]
    neutral_sections: tuple[Section, ...]
    stations: tuple[Station, ...]
    planned_run_time: float | None

    def speed_limit(self, position: float) -> float:
        """Line speed limit at a point, m/s (the limits cover the whole line)."""
        return speed_limit(self.tables, position)

    @property
    def stop_position(self) -> float:
        """Where the run ends: the last station's mark, else the end of the line."""
        return self.stations[-1].position if self.stations else self.length

    def in_neutral_section(self, position: float) -> bool:
        return in_neutral_section(self.tables, position)

    def in_neutral_sections(self, positions: np.ndarray, past: float = 0.0) -> np.ndarray:
        """in_neutral_section at each of `positions` (m), at once; with `past` (m) also
        less than that beyond a section's end."""
        positions = np.asarray(positions, dtype=float)
        inside = np.zeros(positions.shape, dtype=bool)
        for section in self.neutral_sections:
            inside |= (section.start <= positions) & (positions < section.end + past)
        return inside

    def additional_resistance(self, head: float, train_length: float) -> float:
        """Gradient + curve + tunnel specific resistance of the mass belt, N/kN."""
        return belt_resistance(self.tables, head, train_length)

    def additional_resistances(self, heads: np.ndarray, train_length: float) -> np.ndarray:
        """additional_resistance at each of `heads` (m), N/kN: one compiled call for the
        whole array when numba is installed (the ATO curve asks it at every cell)."""
        heads = np.asarray(heads, dtype=float)
        if belt_resistances is _belt_resistances:
            return _belt_resistances(self.tables, heads, train_length)
        return belt_resistances(self.arrays, heads, train_length)

    @functools.cached_property
    def arrays(self) -> LineTables:
        """The sections as compiled code reads them (see line_arrays)."""
        return line_arrays(self)

    @functools.cached_property
    def tables(self) -> LineTables:
        """The sections as the line functions below read them (tuples: fast in Python)."""
        return line_tables(self, tuple)


def with_speed_restrictions(line: Line, restrictions: tuple[Section, ...]) -> Line:
    """`line` with its speed limits lowered to at most each restriction's value (m/s) from
    its start to its end (m): the limits split at the restrictions' ends, so that they
    still cover the line in order without overlapping and every reader of a line's
    limits (speed_limit, the ato curve's belt) reads the restricted ones."""
    limits = line.speed_limits
    for restriction in restrictions:
        limits = tuple(piece for section in limits
                       for piece in _restricted(section, restriction))
    return dataclasses.replace(line, speed_limits=limits)


def _restricted(section: Section, restriction: Section) -> tuple[Section, ...]:
    """A limit's section as the pieces before, inside and after `restriction`, the
    inside at the lower of the two limits."""
    inside_start = max(section.start, restriction.start)
    inside_end = min(section.end, restriction.end)
    pieces = (Section(section.start, min(section.end, restriction.start), section.value),
              Section(inside_start, inside_end, min(section.value, restriction.value)),
              Section(max(section.start, restriction.end), section.end, section.value))
    return tuple(piece for piece in pieces if piece.end > piece.start)


START, END, VALUE = 0, 1, 2  # a section's columns in LineTables.sections


class LineTables(NamedTuple):
    """A line's sections as compiled code and Python read them, with the same functions:
    one row per section (START m, END m and the VALUE it adds: the grade in per mille =
    N/kN, CURVE_CONSTANT / R, TUNNEL_CONSTANT * the tunnel's length, the limit in m/s, 0
    for a neutral section), kind after kind: gradients, curves, tunnels, speed limits,
    neutral sections, each kind's at the rows from the previous kind's end to its own.
    One table (a tuple of rows in Python, an array in compiled code), because compiled
    code pays for every array it hands to a function."""

    sections: Any
    gradients_end: int
    curves_end: int
    tunnels_end: int
    limits_end: int
    neutral_end: int


def line_tables(line: Line | None, table: Callable) -> LineTables:
    """`line`'s LineTables, its rows made a table by `table` (tuple, or an array maker);
    the open track (no line) has no rows."""
    kinds = () if line is None else (
        (line.gradients, lambda s: s.value),
        (line.curves, lambda s: CURVE_CONSTANT / s.value),
        (line.tunnels, lambda s: TUNNEL_CONSTANT * (s.end - s.start)),
        (line.speed_limits, lambda s: s.value),
        (line.neutral_sections, lambda s: 0.0))
    rows = tuple((s.start, s.end, value(s)) for sections, value in kinds for s in sections)
    ends = np.cumsum([len(sections) for sections, _ in kinds] or [0] * 5).tolist()
    return LineTables(table(rows), *ends)


def line_arrays(line: Line | None) -> LineTables:
    """`line`'s tables as a numpy array, for compiled code (no rows: the open track)."""
    return line_tables(line, lambda rows: np.array(rows, dtype=float).reshape(len(rows), 3))


@jitable(inline=True)
def speed_limit(tables: LineTables, position: float) -> float:
    """The line's speed limit at `position`, m/s (the last one beyond the end)."""
    sections = tables.sections
    for i in range(tables.tunnels_end, tables.limits_end):
        if sections[i][START] <= position < sections[i][END]:
            return sections[i][VALUE]
    return sections[tables.limits_end - 1][VALUE]


@jitable(inline=True)
def in_neutral_section(tables: LineTables, position: float) -> bool:
    sections = tables.sections
    for i in range(tables.limits_end, tables.neutral_end):
        if sections[i][START] <= position < sections[i][END]:
            return True
    return False


@jitable
def neutral_distance(tables: LineTables, position: float) -> float:
    """How far ahead of `position` the next neutral section starts, m: 0 inside one,
    inf with none ahead (the sections are in order)."""
    sections = tables.sections
    for i in range(tables.limits_end, tables.neutral_end):
        if position < sections[i][END]:
            return max(sections[i][START] - position, 0.0)
    return math.inf


@jitable(inline=True)
def belt_resistance(tables: LineTables, head: float, train_length: float) -> float:
    """Gradient + curve + tunnel specific resistance of the mass belt [head - L, head],
    N/kN (0 on the open track, without a call that would hand compiled code the arrays)."""
    if tables.tunnels_end == 0:  # no gradient, curve or tunnel (the open track)
        return 0.0
    return _belt_sum(tables, head, train_length)


@jitable
def _belt_sum(tables: LineTables, head: float, train_length: float) -> float:
    """Per kind, the mean over the belt of its piecewise-constant value (0 outside its
    sections), or the point value when the belt has no length; summed. One pass over the
    rows, so that compiled code makes no call per kind."""
    sections = tables.sections
    tail = head - train_length
    kind_ends = (tables.gradients_end, tables.curves_end, tables.tunnels_end)
    total, first = 0.0, 0
    for kind in range(3):
        end = kind_ends[kind]
        average = 0.0
        if first < end and head <= tail:
            for i in range(first, end):
                if sections[i][START] <= head < sections[i][END]:
                    average = sections[i][VALUE]
                    break
        elif first < end:
            covered = 0.0
            for i in range(first, end):
                overlap = min(head, sections[i][END]) - max(tail, sections[i][START])
                if overlap > 0:
                    covered += overlap * sections[i][VALUE]
            average = covered / (head - tail)
        total = average if kind == 0 else total + average
        first = end
    return total


def _belt_resistances(tables: LineTables, heads: np.ndarray, train_length: float) -> np.ndarray:
    """belt_resistance at each of `heads`, in order (the same operations per head)."""
    resistances = np.empty(len(heads))
    for i in range(len(heads)):
        resistances[i] = belt_resistance(tables, heads[i], train_length)
    return resistances


belt_resistances = compiled(_belt_resistances) or _belt_resistances

# ---------------------------------------------------------------- loading ----

SECTION_KEYS = {  # kind -> (value key or None, allowed keys)
    "gradients": ("grade", {"start", "end", "grade"}),
    "curves": ("radius", {"start", "end", "radius"}),
    "tunnels": (None, {"start", "end"}),
    "speed_limits": ("limit", {"start", "end", "limit"}),
    "neutral_sections": (None, {"start", "end"}),
}
TOP_KEYS = {"name", "length", "planned_run_time", "stations", *SECTION_KEYS}


def load_line(path: str | Path) -> Line:
    """A project line file (a run reads line.file by core/train/lines.load_line_file,
    which takes a TTOBench track file too)."""
    return parse_line(yamlfile.read_text(path, "line file"), Path(path))


def planned_to(line: Line | None, values) -> Line | None:
    """`line` with the run's line.planned_run_time (> 0) in place of its file's
    planned_run_time: a service timetabled for another train than the file's (values
    without the parameter, a bag recorded before it existed, keep the file's)."""
    planned = values.get("line.planned_run_time")
    if line is None or not planned:
        return line
    return dataclasses.replace(line, planned_run_time=float(planned))


@functools.lru_cache(maxsize=32)
def parse_line(text: str, path: str | Path = "<line>") -> Line:
    """A line from the text of a line file; `path` names it in error messages.
    Cached (a Line is immutable): a run's validation, profile, plant and scorer all
    read the same line, ~15 ms of YAML each, in every tuning evaluation."""
    yamlfile.check_structure(text, str(path))
    try:
        root = yaml.compose(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f" line {mark.line + 1}" if mark else ""
        raise ScenarioError(f"{path}{at}: malformed YAML") from None
    fields = mapping_fields(path, root, TOP_KEYS, "a line file is a mapping (name, length, "
                                                  "gradients, ...)")
    for required in ("name", "length", "speed_limits"):
        if required not in fields:
            raise ScenarioError(f"{path}: missing {required!r}")
    length = node_number(path, fields["length"], "length", positive=True)
    if length > MAX_LENGTH:
        raise node_error(path, fields["length"], f"length {length:g} m is beyond {MAX_LENGTH:g} m "
                     "(the longest line a run may have)")
    sections = {name: _sections(path, name, fields.get(name), length) for name in SECTION_KEYS}
    _check_limits_cover(path, fields["speed_limits"], sections["speed_limits"], length)
    stations = _stations(path, fields.get("stations"), length)
    run_time = fields.get("planned_run_time")
    return Line(
        name=str(node_value(fields["name"])), length=length,
        stations=stations,
        planned_run_time=node_number(path, run_time, "planned_run_time", positive=True)
        if run_time is not None else None,
        **sections)


def mapping_fields(path: Path, root: yaml.Node, known: frozenset[str] | set[str],
                   shape: str) -> dict[str, yaml.Node]:
    """The top-level fields of a file's `root` by key, each a known one; else one line
    (`shape` says what the file is)."""
    if not isinstance(root, yaml.MappingNode):
        raise ScenarioError(f"{path}: {shape}")
    fields = {}
    for key_node, value_node in root.value:
        if key_node.value not in known:
            raise node_error(path, key_node, f"unknown key {key_node.value!r}")
        fields[key_node.value] = value_node
    return fields


def node_error(path: Path, node: yaml.Node, message: str) -> ScenarioError:
    return ScenarioError(f"{path} line {node.start_mark.line + 1}: {message}")


def node_value(node: yaml.Node):
    """A node's value as YAML reads it; None for an empty one (`key:` with nothing after it,
    which yaml.serialize cannot write back)."""
    if isinstance(node, yaml.ScalarNode) and node.tag == "tag:yaml.org,2002:null":
        return None
    return yaml.safe_load(yaml.serialize(node))


def node_number(path: Path, node: yaml.Node, name: str, positive: bool = False) -> float:
    value = node_value(node)
    if isinstance(value, str):  # YAML 1.1 reads 1e9 (no dot) as text
        try:
            value = float(value)
        except ValueError:
            pass
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise node_error(path, node, f"{name} must be a finite number, not {value!r}")
    if positive and not value > 0:
        raise node_error(path, node, f"{name} must be positive, not {value}")
    return float(value)


def node_entries(path: Path, node: yaml.Node | None, kind: str):
    if node is None:
        return []
    if not isinstance(node, yaml.SequenceNode):
        raise node_error(path, node, f"{kind} must be a list")
    entries = []
    for item in node.value:
        if not isinstance(item, yaml.MappingNode):
            raise node_error(path, item, f"each entry of {kind} is a mapping")
        entries.append((item, {k.value: v for k, v in item.value}))
    return entries


def _sections(path: Path, kind: str, node: yaml.Node | None, length: float) -> tuple:
    value_key, allowed = SECTION_KEYS[kind]
    sections, previous_end = [], None
    for item, entry in node_entries(path, node, kind):
        unknown = sorted(set(entry) - allowed)
        if unknown:
            raise node_error(path, item, f"{kind}: unknown key {unknown[0]!r}")
        missing = sorted(allowed - set(entry))
        if missing:
            raise node_error(path, item, f"{kind}: missing {missing[0]!r}")
        start = node_number(path, entry["start"], "start")
        end = node_number(path, entry["end"], "end")
        if end <= start:
            raise node_error(path, item, f"{kind}: section from {start:g} to {end:g} m has no "
                         "positive length")
        if start < 0 or end > length:
            raise node_error(path, item, f"{kind}: section {start:g}-{end:g} m is off the line "
                         f"(0-{length:g} m)")
        if previous_end is not None and start < previous_end:
            raise node_error(path, item, f"{kind}: section starting at {start:g} m overlaps or "
                         f"precedes the one ending at {previous_end:g} m")
        value = 0.0
        if value_key is not None:
            value = node_number(path, entry[value_key], value_key,
                            positive=value_key in ("radius", "limit"))
        sections.append(Section(start, end, value))
        previous_end = end
    return tuple(sections)


def _check_limits_cover(path, node, limits, length) -> None:
    """Speed limits must cover the open line without gaps."""
    position = 0.0
    for section in limits:
        if section.start > position:
            raise node_error(path, node, f"speed_limits: no limit between {position:g} and "
                         f"{section.start:g} m")
        position = section.end
    if position < length:
        raise node_error(path, node, f"speed_limits: no limit from {position:g} m to the end")


def _stations(path: Path, node: yaml.Node | None, length: float) -> tuple[Station, ...]:
    stations = []
    for item, entry in node_entries(path, node, "stations"):
        unknown = sorted(set(entry) - {"name", "position", "dwell"})
        if unknown:
            raise node_error(path, item, f"stations: unknown key {unknown[0]!r}")
        if "position" not in entry:
            raise node_error(path, item, "stations: missing 'position'")
        position = node_number(path, entry["position"], "position")
        if not 0 <= position <= length:
            raise node_error(path, item, f"stations: {position:g} m is off the line")
        dwell = node_number(path, entry["dwell"], "dwell") if "dwell" in entry else 0.0
        if dwell < 0:
            raise node_error(path, entry["dwell"], f"stations: dwell {dwell:g} s is negative")
        name = _station_name(path, item, entry, stations)
        if stations and position <= stations[-1].position:
            raise node_error(path, item, "stations must be in increasing position order")
        stations.append(Station(name, position, dwell))
    return tuple(stations)


def _station_name(path: Path, item: yaml.Node, entry: dict, before: list[Station]) -> str:
    """The station's name: text (a timetable's stops and a report's rows name stations by
    it), given, and no other station's of the line."""
    if "name" not in entry:
        raise node_error(path, item, "stations: missing 'name'")
    value = node_value(entry["name"])
    if not isinstance(entry["name"], yaml.ScalarNode) or value is None or not str(value).strip():
        raise node_error(path, entry["name"], f"stations: a name is text, not {value!r}")
    name = str(value)
    same = next((station for station in before if station.name == name), None)
    if same is not None:
        raise node_error(path, entry["name"], f"stations: {name!r} is already the name of the "
                         f"station at {same.position:g} m (names are unique on a line)")
    return name
