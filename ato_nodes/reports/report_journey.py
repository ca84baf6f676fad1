"""The journey part of a run's report (scripts/analyze.py): for each run of a timetable
(ato_nodes.results.journeys), a table per station (stop error, arrival and departure lateness,
dwell, verdict) and per section (running time, traction energy), the journey's totals
and verdict (core/scoring/journey.py's, the summary line the console and the JSON files
give too), the re-plans the bag recorded (a late departure
and the curve it drove), and speed against position over the line: its
stations marked, its speed limits, its neutral sections shaded, the planned (target)
and driven speed. In report.md (a PNG figure) and report.html (Plotly) alike; SI inside,
km/h and km only as shown.
"""

from __future__ import annotations

import dataclasses
import html
import itertools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ato_nodes.reports.analysis import (LIMIT_COLOUR, MARK, RUN_COLOURS, Figure, Markup, RunReport,
                                        _markdown_rows, md_text, pyplot, save_figure)
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.base.units import MS_TO_KMH
from ato_nodes.core.scoring.journey import REQUIRED, JourneyIndices, summary_line
from ato_nodes.core.targets.restriction import restricted_line
from ato_nodes.core.targets.served import Replan
from ato_nodes.core.targets.timetable import Timetable
from ato_nodes.core.train.line import Line, Station
from ato_nodes.results.journeys import TIMETABLE, is_journey, run_journey, run_timetable
from ato_nodes.reports.report_html import STATUS_COLOURS, Panels, _f32, _line_shapes, _table, _text

STATION_HEADER = ["station", "km", "stop error m", "arrival s", "arrival lateness s",
                  "departure s", "departure lateness s", "dwell s", "verdict"]
SECTION_HEADER = ["section", "km", "running time s", "timetable s", "error s",
                  "traction kWh", "max abs(e) km/h"]
TIMING_HEADER = ["timing point", "kind", "km", "window s", "time s", "outside s", "km/h",
                 "speed bounds km/h", "verdict"]
TIMING_EXPLAINED = ("A TTOBench journey's timing points: when the train arrived at, departed from "
                    "or passed each (the head, interpolated between samples) on the run's "
                    "clock, its window on the journey's (the same clock: t = 0 is the first "
                    "departure), how far outside it (+ late, - early), and a passing point's "
                    "speed against its bounds; the first departure sets the clock and is not "
                    "judged.")
EXPLAINED = (f"Stops found in the series (the final standstill within 50 m of each mark); "
             f"times on the run's clock (t = 0: the first departure), lateness against the "
             f"timetable (+ late). A station passes with its stop within "
             f"{REQUIRED.stop_error:g} m of the mark and its arrival within "
             f"{REQUIRED.arrival_lateness:g} s; sections run standstill to standstill.")


@dataclass
class JourneyReport:
    label: str
    timetable: Timetable
    name: str  # the timetable file's name
    series: dict[str, np.ndarray]
    indices: JourneyIndices
    colour: str
    line: Line  # the bag's line when the bag keeps the timetable, under the run's restrictions
    replans: list[str]  # the recorded re-plans as the profile said them, in step order


def journey_reports(reports: list[RunReport]) -> tuple[list[JourneyReport], list[str]]:
    """The journey runs' reports, and a note for each journey run that cannot be scored
    per station (its timetable nowhere to be found, a series missing)."""
    journeys, notes = [], []
    for report, colour in zip(reports, itertools.cycle(RUN_COLOURS)):
        parameters = report.run.parameters
        if not is_journey(parameters):
            continue
        name = Path(parameters[TIMETABLE]).name
        timetable = run_timetable(parameters)
        if timetable is None:
            notes.append(f"{report.label}: a journey run whose timetable {name} is neither "
                         "kept in the bag nor on this machine: no per-station table")
            continue
        try:
            indices = run_journey(report.run.series, parameters, timetable)
            line = with_stops(restricted_line(parameters, timetable.line), timetable)
        except ScenarioError as exc:
            notes.append(f"{report.label}: no per-station table: {exc}")
            continue
        journeys.append(JourneyReport(report.label, timetable, name, report.run.series,
                                      indices, colour, line, replan_lines(report.run.replans)))
    return journeys, notes


def with_stops(line: Line, timetable: Timetable) -> Line:
    """`line` with a station at each stop of the timetable it lacks (a TTOBench journey's
    stopping points need not be its track's stops), for the plots to mark."""
    have = {station.position for station in line.stations}
    added = tuple(Station(stop.station, stop.position, stop.least_dwell)
                  for stop in timetable.stops if stop.position not in have)
    if not added:
        return line
    return dataclasses.replace(line, stations=tuple(sorted(
        line.stations + added, key=lambda station: station.position)))


def replan_lines(recorded: list[dict]) -> list[str]:
    """Each re-plan a bag recorded (Replan's fields and its step), with its time on the
    run's clock, in the words the profile said it on the events topic."""
    return [f"t = {replan['time']:.1f} s: "
            f"{Replan(**{name: replan[name] for name in Replan._fields}).text()}"
            for replan in recorded]


REPLANS = "Re-plans (a late departure and the curve it drove, as recorded)"
NO_REPLANS = "No re-plan recorded: every departure on time, or a run the stack did not record."


def _number(value: float, form: str) -> str:
    return form.format(value) if math.isfinite(value) else "-"


def station_rows(indices: JourneyIndices) -> list[tuple[list[str], str, str]]:
    """(cells of STATION_HEADER but the verdict, verdict, reason) per station."""
    return [([s.station, f"{s.mark / 1000:.3f}", _number(s.stop_error, "{:+.3f}"),
              _number(s.arrival, "{:.1f}"), _number(s.arrival_lateness, "{:+.1f}"),
              _number(s.departure, "{:.1f}"), _number(s.departure_lateness, "{:+.1f}"),
              _number(s.dwell, "{:.1f}")], s.verdict, s.reason or
             ("" if s.outcome == "stopped" else s.outcome))
            for s in indices.stations]


def timing_rows(indices: JourneyIndices) -> list[tuple[list[str], str, str]]:
    """(cells of TIMING_HEADER but the verdict, verdict, reason) per timing point."""
    def bounds(low: float, high: float, scale: float = 1.0) -> str:
        if not (math.isfinite(low) or math.isfinite(high)):
            return "-"
        return f"{_number(low * scale, '{:g}')}-{_number(high * scale, '{:g}')}"

    return [([p.point, p.kind, f"{p.mark / 1000:.3f}", bounds(p.earliest, p.latest),
              _number(p.time, "{:.1f}"), _number(p.miss, "{:+.1f}"),
              _number(p.speed * MS_TO_KMH, "{:.1f}"),
              bounds(p.min_speed, p.max_speed, MS_TO_KMH)], p.verdict, p.reason)
            for p in indices.timing]


def section_rows(journey: JourneyReport) -> list[list[str]]:
    return [[f"{s.origin} - {s.destination}", f"{planned.start / 1000:.3f}-"
             f"{planned.end / 1000:.3f}", _number(s.running_time, "{:.1f}"),
             f"{planned.running_time:g}", _number(s.running_time_error, "{:+.1f}"),
             _number(s.traction_energy_kwh, "{:.2f}"),
             _number(s.max_abs_error * MS_TO_KMH, "{:.3f}")]
            for s, planned in zip(journey.indices.sections, journey.timetable.sections,
                                  strict=True)]


def markdown_sections(journeys: list[JourneyReport], notes: list[str]) -> list[str]:
    """report.md's journey tables, after the verdict."""
    lines = [f"- {md_text(note)}" for note in notes]
    for journey in journeys:
        verdict = journey.indices.verdict
        lines += ["", f"## Journey: {md_text(journey.label)} ({md_text(journey.name)})", "",
                  f"- **{verdict.upper()}** {md_text(summary_line(journey.indices))}", "",
                  md_text(EXPLAINED), ""]
        lines += _markdown_rows(STATION_HEADER, [
            cells + [Markup(": ".join(filter(None, (MARK[verdict], md_text(reason)))) or "-")]
            for cells, verdict, reason in station_rows(journey.indices)])
        if journey.indices.timing:
            lines += ["", md_text(TIMING_EXPLAINED), ""] + _markdown_rows(TIMING_HEADER, [
                cells + [Markup(": ".join(filter(None, (MARK[verdict], md_text(reason)))))]
                for cells, verdict, reason in timing_rows(journey.indices)])
        lines += [""] + _markdown_rows(SECTION_HEADER, section_rows(journey))
        lines += ["", f"{REPLANS}:", ""] + [f"- {md_text(replan)}" for replan in journey.replans] \
            if journey.replans else ["", NO_REPLANS]
    return lines


def html_sections(journeys: list[JourneyReport], notes: list[str]) -> list[str]:
    """report.html's journey tables, after the verdict."""
    parts = [f"<p>{html.escape(note)}</p>" for note in notes]
    for journey in journeys:
        verdict = journey.indices.verdict
        parts += [f"<h2>Journey: {html.escape(journey.label)} ({html.escape(journey.name)})"
                  f"</h2><div class='summary' style='background:{STATUS_COLOURS[verdict]}'>"
                  f"{html.escape(verdict.upper())}: {html.escape(summary_line(journey.indices))}"
                  f"</div><p>{html.escape(EXPLAINED)}</p>"]
        parts.append(_table(STATION_HEADER, [
            [(cell, "") for cell in cells] + [(verdict or "-", verdict, reason)]
            for cells, verdict, reason in station_rows(journey.indices)]))
        if journey.indices.timing:
            parts.append(f"<p>{html.escape(TIMING_EXPLAINED)}</p>" + _table(TIMING_HEADER, [
                [(cell, "") for cell in cells] + [(verdict, verdict, reason)]
                for cells, verdict, reason in timing_rows(journey.indices)]))
        parts.append(_table(SECTION_HEADER, [[(cell, "") for cell in row]
                                             for row in section_rows(journey)]))
        parts.append(f"<p>{REPLANS}:</p><ul>" + "".join(
            f"<li>{html.escape(replan)}</li>" for replan in journey.replans) + "</ul>"
            if journey.replans else f"<p>{html.escape(NO_REPLANS)}</p>")
    return parts


def limit_steps(line: Line) -> tuple[list[float], list[float]]:
    """The line's speed limits (a temporary restriction's included) as a step line: km,
    km/h."""
    return ([x / 1000 for s in line.speed_limits for x in (s.start, s.end)],
            [s.value * MS_TO_KMH for s in line.speed_limits for _ in "ab"])


def marks(journey: JourneyReport) -> list[tuple[str, float, str]]:
    """(name, m, line style) of each place the plot marks: the line's stations, solid;
    the timetable's passing points, dotted."""
    return ([(s.name, s.position, "-") for s in journey.line.stations]
            + [(p.name, p.position, ":") for p in journey.timetable.passing])


def plot_journey(journey: JourneyReport, path: Path) -> Figure:
    """report.md's speed against position over the line."""
    plt = pyplot()
    figure, axes = plt.subplots(figsize=(11, 4.8))
    for number, section in enumerate(journey.line.neutral_sections):
        axes.axvspan(section.start / 1000, section.end / 1000, color="orange", alpha=0.3,
                     lw=0, label="neutral section" if number == 0 else None)
    axes.plot(*limit_steps(journey.line), color=LIMIT_COLOUR, ls="-.", lw=1.2,
              label="line speed limit")
    s, km = journey.series, journey.series["position"] / 1000
    axes.plot(km, s["target"] * MS_TO_KMH, "k--", lw=1, label="planned (target)")
    axes.plot(km, s["speed"] * MS_TO_KMH, color=journey.colour, lw=1, label="driven")
    for name, position, style in marks(journey):
        axes.axvline(position / 1000, color="purple", lw=0.8, ls=style)
        axes.text(position / 1000, 1.01, name, rotation=30, fontsize=7,
                  transform=axes.get_xaxis_transform(), ha="left", va="bottom")
    axes.set(xlabel="position (km)", ylabel="speed (km/h)")
    axes.set_title(f"Journey: {journey.label}", pad=40)
    axes.grid(alpha=0.3)
    axes.legend(loc="lower right", fontsize=8)
    return Figure(f"Journey, speed against position: {journey.label}", save_figure(figure, path))


def journey_figure(journey: JourneyReport):
    """report.html's speed against position over the line (Plotly)."""
    import plotly.graph_objects as go
    s, km = journey.series, _f32(journey.series["position"] / 1000)
    limit_x, limit_y = limit_steps(journey.line)
    traces = [go.Scatter(x=limit_x, y=limit_y, name="line speed limit",
                         line=dict(color=LIMIT_COLOUR, dash="dashdot", width=1.2)),
              go.Scatter(x=km, y=_f32(s["target"] * MS_TO_KMH), name="planned (target)",
                         line=dict(color="black", dash="dash", width=1.2)),
              go.Scatter(x=km, y=_f32(s["speed"] * MS_TO_KMH),
                         name=_text(f"{journey.label} driven"),
                         line=dict(color=journey.colour, width=1.2))]
    panels = Panels()
    panels.add("speed (km/h) against position: stations, neutral sections shaded", traces,
               [_line_shapes(journey.line, 1)], height=2.0)
    return panels.figure("position (km)")
