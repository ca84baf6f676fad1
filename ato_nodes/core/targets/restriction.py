"""Temporary speed restrictions of a journey (profile.journey.speed_restriction), ROS-free:
stretches of the line where the limit is lowered for the run, issued before the service
and so known when the profile builds its curves at start-up.

A restriction is START:END:SPEED (m along the line, m/s as the line files give limits).
It lowers the line's limits on its stretch (train/line.with_speed_restrictions) before
the journey's sections are cut from the line (core/targets/served.journey_table), so
the sections' curves, on time and catching up, are planned under it, with the train's
tail rule, and the plan's limits, which the run records as its speed limit and the
scorer judges overspeed against, are the restricted ones.
"""

from __future__ import annotations

from ..base.errors import ScenarioError
from ..base.spec import PROFILE_NODES, TextForm, param
from ..train.line import Line, Section, speed_limit, with_speed_restrictions

_NUMBER = r"\s*\d+(?:\.\d*)?\s*"
_RESTRICTION = rf"{_NUMBER}:{_NUMBER}:{_NUMBER}"
NAME = "profile.journey.speed_restriction"

SPEED_RESTRICTION = param(
    NAME, "", "temporary speed restrictions issued for the run: START:END:SPEED[,START:END:"
    "SPEED...], the line's limit lowered to SPEED (m/s) from START to END (m along the "
    "line) for the planning of the sections over it and for the limit the run is judged "
    "against; a section whose running time cannot then be met is driven minimum-time "
    "(said at start-up) and the sections after it catch up", PROFILE_NODES,
    form=TextForm(rf"\s*|{_RESTRICTION}(?:,{_RESTRICTION})*",
                  "START:END:SPEED[,START:END:SPEED...] (m along the line, m/s)"))


def speed_restrictions(values, line: Line) -> tuple[Section, ...]:
    """profile.journey.speed_restriction on `line` as sections (start, end, the limit in
    m/s); ScenarioError (one line) for a stretch that is empty or off the line, or a
    speed the curve cannot keep under (not above profile.ato.margin) or that lowers no
    limit of the stretch."""
    margin = values["profile.ato.margin"]
    restrictions = []
    for item in filter(None, (part.strip() for part in values[NAME].split(","))):
        start, end, speed = (float(number) for number in item.split(":"))
        said = f"{NAME}: {item}:"
        if not start < end:
            raise ScenarioError(f"{said} its start {start:g} m is not before its end {end:g} m")
        if end > line.length:
            raise ScenarioError(f"{said} {start:g}-{end:g} m is off the line (0-"
                                f"{line.length:g} m)")
        if not speed > margin:
            raise ScenarioError(f"{said} {speed:g} m/s is not above profile.ato.margin "
                                f"{margin:g} m/s (the curve keeps that much under a limit)")
        highest = max(speed_limit(line.tables, position)
                      for position in _limit_changes(line, start, end))
        if speed >= highest:
            raise ScenarioError(f"{said} {speed:g} m/s lowers no limit: the line's on "
                                f"{start:g}-{end:g} m are at most {highest:g} m/s")
        restrictions.append(Section(start, end, speed))
    return tuple(restrictions)


def restricted_line(values, line: Line) -> Line:
    """`line` under the run's speed restrictions: what the journey plans on and its report
    draws (a run's values from before the parameter existed have none)."""
    if values.get(NAME, SPEED_RESTRICTION.default) == SPEED_RESTRICTION.default:
        return line
    return with_speed_restrictions(line, speed_restrictions(values, line))


def _limit_changes(line: Line, start: float, end: float) -> list[float]:
    """`start` and every start of a limit's section within start-end: one position on
    each limit the stretch crosses."""
    return [start, *(section.start for section in line.speed_limits
                     if start < section.start < end)]
