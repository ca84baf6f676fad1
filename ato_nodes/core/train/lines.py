"""A run's line from its file, whichever of the two formats it is in, as the run's train
may run it: every reader of line.file (validation, the stages, the scorer, a bag's copy)
reads it here.

* A project line file (msg_config/lines/*.yaml): core/train/line.py.
* A TTOBench track file (a .json path, msg_config/ttobench/tracks/): the Line of
  core/train/ttobench.Track.line(), a station at every stop of the track.

The format follows the file's name (ttobench.is_library_file), so a bag, which keeps
line.file's path and its text, re-reads the same line from its copy. The run may end the line early
(line.end: a track's first interstation), and the run's train caps the line's limits at
its maximum speed (plant.max_running_speed: a TTOBench train's), so that the plan and the
scorer's overspeed read the limits the train runs under.
"""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

from ..base import yamlfile
from ..base.errors import ScenarioError
from .line import Line, Section, parse_line, planned_to, with_speed_restrictions
from .ttobench import is_library_file, parse_track


def load_line_file(path: str | Path) -> Line:
    """The Line of a line file or of a TTOBench track file (by its name), validated: one
    ScenarioError line naming the file and the field."""
    what = "TTOBench track" if is_library_file(path) else "line file"
    return parse_line_file(yamlfile.read_text(path, what), str(path))


@functools.lru_cache(maxsize=32)
def parse_line_file(text: str, path: str) -> Line:
    """load_line_file of a file's `text` (a bag's copy), its format by `path`'s name.
    Cached (a Line is immutable): a run's validation, stages and scorer read the same."""
    if is_library_file(path):
        return parse_track(text, path).line()
    return parse_line(text, path)


def line_of(values) -> Line | None:
    """The line of a run's values: line.file's (None: the open track) as the run runs it
    (for_train)."""
    if not values["line.file"]:
        return None
    return for_train(load_line_file(values["line.file"]), values)


def for_train(line: Line, values) -> Line:
    """`line` as the run (`values`) runs it: ended at line.end, its limits capped at
    plant.max_running_speed, planned to line.planned_run_time (core/train/line.planned_to);
    values without the first two (a bag recorded before they existed) have neither."""
    ended = ended_at(line, values.get("line.end", 0.0))
    return planned_to(capped(ended, values.get("plant.max_running_speed", 0.0)), values)


# Cached (a Line is immutable, and hashed by its contents): every stage and the scorer of a
# run ask for the same line, which then keeps the tables it computed (Line.tables).
@functools.lru_cache(maxsize=32)
def ended_at(line: Line, end: float) -> Line:
    """`line` ending at `end` (m; 0: as it is): the sections beyond it dropped, those across
    it cut there but a tunnel (its resistance is its whole length's), the stations beyond
    it dropped. ScenarioError (one line) for an end beyond the line's."""
    if not end:
        return line
    if end > line.length:
        raise ScenarioError(f"line.end {end:g} m is beyond the end of line {line.name!r} "
                            f"({line.length:g} m)")

    def cut(sections: tuple[Section, ...]) -> tuple[Section, ...]:
        return tuple(Section(s.start, min(s.end, end), s.value) for s in sections
                     if s.start < end)

    return dataclasses.replace(
        line, length=end, gradients=cut(line.gradients), curves=cut(line.curves),
        tunnels=tuple(s for s in line.tunnels if s.start < end),
        speed_limits=cut(line.speed_limits), neutral_sections=cut(line.neutral_sections),
        stations=tuple(s for s in line.stations if s.position <= end))


@functools.lru_cache(maxsize=32)
def capped(line: Line, max_speed: float) -> Line:
    """`line` with no speed limit above `max_speed` (m/s; 0: as it is): a train's maximum
    speed below the line's limits (core/train/line.with_speed_restrictions)."""
    if not max_speed or all(section.value <= max_speed for section in line.speed_limits):
        return line
    return with_speed_restrictions(line, (Section(0.0, line.length, max_speed),))
