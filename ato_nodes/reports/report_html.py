"""The interactive report page: one self-contained HTML file (plotly.js embedded, so it
opens with no network), the verdict and the runs' identity first, then figures to zoom
and hover: every time subplot shares one time axis (zoom one, all follow), the
distance subplots one distance axis over the line's gradient profile and its neutral
sections, each live parameter change a dotted line across the time subplots. Series
stay SI inside; speeds are shown in km/h. Text from a bag is escaped (html.escape),
in the tables and in Plotly's names and titles alike.

The page counts the figures Plotly has drawn in `data-plots-rendered` on its body,
so a headless browser can tell a rendered page from a blank one
(scripts/screenshot_report.py).
"""

from __future__ import annotations

import html
import itertools
from pathlib import Path

import numpy as np

from ato_nodes.reports.analysis import (CHANGES_HEADER, FAIL, LIMIT_COLOUR, PASS, RUN_COLOURS,
                                        UNMEASURED, RunReport, Tuning, VerdictRow, change_rows,
                                        convergence_axis, live_changes, named_outputs,
                                        report_notes)
from ato_nodes.core.base.units import MS_TO_KMH
from ato_nodes.core.train.line import Line
from ato_nodes.core.scoring.operation import (JERK_WINDOW, SWITCH_THRESHOLD, drive_modes,
                                              windowed_jerk)
from ato_nodes.core.run.scoring import observer_b0, run_line, total_disturbance

# The scorer's traction/brake threshold (N/kN), so the mode timeline shows the switches
# that switch_count counts.
MODES = ((1, "traction", "#2ca02c"), (0, "coast", "#bbbbbb"), (-1, "brake", "#d62728"))
STATUS_COLOURS = {PASS: "#d8f3dc", FAIL: "#ffccd5", UNMEASURED: "#fff3bf", "": "#eeeeee"}
ERROR_INDICES = ("max_abs_error_kmh", "max_abs_error_outside_steps_kmh", "p95_abs_error_kmh")
ROW_HEIGHT = 190  # px of one time or distance subplot
TITLE_ROOM = 30   # px between the legend (above the subplots) and the first subplot: its title
RENDERED_ATTRIBUTE = "data-plots-rendered"
# report.html#t=START:END opens with the time axes on that stretch (seconds).
# Every x axis is set: a relayout of one does not move the axes that match it.
ZOOM_FROM_ADDRESS = """var zoom = location.hash.match(/^#t=([0-9.]+):([0-9.]+)$/);
if (zoom) { var plot = document.getElementById('{plot_id}'), range = {};
  Object.keys(plot.layout).filter(k => /^xaxis\\d*$/.test(k)).forEach(
    k => { range[k + '.range'] = [Number(zoom[1]), Number(zoom[2])]; });
  return Plotly.relayout(plot, range); }"""
COUNT_RENDERED = ("document.body.setAttribute('%s', "
                  "Number(document.body.getAttribute('%s') || 0) + 1);"
                  % (RENDERED_ATTRIBUTE, RENDERED_ATTRIBUTE))
STYLE = ("body{font-family:sans-serif;margin:1em 2em}table{border-collapse:collapse;\n"
         "margin:0.5em 0}td,th{border:1px solid #ccc;padding:2px 8px;text-align:right}\n"
         "th:first-child,td:first-child,table.identity td{text-align:left}"
         ".summary{padding:4px 8px;margin:2px 0;\n"
         "font-weight:bold}")


def _colours():
    return itertools.cycle(RUN_COLOURS)


def _text(text: str) -> str:
    """A bag's text for Plotly, which reads tags (<b>, <a href=...>) in names and titles."""
    return html.escape(str(text))


def _f32(values) -> np.ndarray:
    """Halves the page: single precision is finer than any plotted difference here
    (t to 0.2 ms over 2400 s)."""
    return np.asarray(values, dtype=np.float32)


def mode_segments(t: np.ndarray, modes: np.ndarray, mode: int) -> list:
    """x of the stretches spent in `mode`, each as start, end, None (a gap in the
    line), from a step's time to the next step's."""
    ends = np.append(t[1:], t[-1])
    changes = np.flatnonzero(np.diff(np.concatenate(([0], modes == mode, [0]))))
    xs: list = []
    for first, last in zip(changes[::2], changes[1::2], strict=True):
        xs += [float(t[first]), float(ends[last - 1]), None]
    return xs


def _limits(reports: list[RunReport], keys: tuple[str, ...]) -> dict[float, str]:
    """limit -> its requirement's text, for the runs' requirements on these indices."""
    return {r.requirements[k].limit: r.requirement_text(k)
            for r in reports for k in keys if k in r.requirements}


class Panels:
    """Stacked subplots on one shared x axis; each panel adds its traces."""

    def __init__(self):
        self.panels: list[tuple[str, float, list, list]] = []  # title, height, traces, shapes

    def add(self, title: str, traces: list, shapes: list | None = None, height: float = 1.0):
        if traces:
            self.panels.append((title, height, traces, shapes or []))

    def figure(self, x_title: str, every_row: tuple = ()):
        """The subplots; each of `every_row` (shapes) drawn on all of them."""
        from plotly.subplots import make_subplots
        count = len(self.panels)
        heights = [height for _, height, _, _ in self.panels]
        figure = make_subplots(rows=count, cols=1, shared_xaxes=True, row_heights=heights,
                               vertical_spacing=min(0.06, 0.3 / count),
                               subplot_titles=[title for title, _, _, _ in self.panels])
        for row, (_, _, traces, shapes) in enumerate(self.panels, start=1):
            for trace in traces:
                figure.add_trace(trace, row=row, col=1)
            for shape in (*shapes, *every_row):
                shape(figure, row)
        figure.update_xaxes(title_text=x_title, row=count, col=1)
        figure.update_xaxes(showspikes=True, spikemode="across", spikethickness=1,
                            showticklabels=True)  # each subplot's times, when zoomed
        height = int(ROW_HEIGHT * sum(heights) + 120)
        margin = dict(l=70, r=20, t=40, b=50)
        figure.update_layout(height=height, hovermode="x", margin=margin, legend=dict(
            orientation="h", yanchor="bottom",  # above the first subplot's title
            y=1.0 + TITLE_ROOM / (height - margin["t"] - margin["b"])))
        return figure


def _bands(values: dict[float, str], colour: str, dash: str):
    """Horizontal lines at +-value, labelled on the right."""
    def draw(figure, row):
        for value, text in values.items():
            style = dict(line=dict(color=colour, dash=dash, width=1), row=row, col=1)
            figure.add_hline(y=value, annotation_text=text, annotation_position="top right",
                             **style)
            figure.add_hline(y=-value, **style)
    return draw


def _change_lines(reports: list[RunReport]):
    """Each run's live parameter changes: a dotted line in its colour, named on top."""
    marks = [(change, colour) for report, colour in zip(reports, _colours(), strict=False)
             for change in live_changes(report.run)]

    def draw(figure, row):
        for change, colour in marks:
            label = dict(annotation_text=_text(f"{change.text} at {change.t:g} s"),
                         annotation_position="top right", annotation_font_color=colour,
                         annotation_bgcolor="rgba(255, 255, 255, 0.8)") \
                if row == 1 else {}
            figure.add_vline(x=change.t, line=dict(color=colour, dash="dot", width=1.5),
                             row=row, col=1, **label)
    return (draw,) if marks else ()


def _line(x, y, name, colour, group, first, **style):
    import plotly.graph_objects as go
    return go.Scatter(x=_f32(x), y=_f32(y), name=_text(name), legendgroup=group,
                      showlegend=first, mode="lines",
                      line=dict(color=colour, width=style.pop("width", 1.2), **style))


def _run_traces(report: RunReport, colour: str, base: RunReport, panels: dict[str, list],
                outputs: dict[str, list], modes: list) -> None:
    """One run's traces, added to `panels` (by name), `outputs` (by title) and `modes`;
    its differences to `base` (the first run) when it is another run."""
    s, name = report.run.series, report.label
    t = s["t"]

    def add(panel, y, what, x=t, **style):
        panels[panel].append(_line(x, y, f"{name} {what}", colour, name, panel == "speed",
                                   **style))
    add("speed", s["speed"] * MS_TO_KMH, "speed")
    if "measured_speed" in s and np.any(s["measured_speed"] != s["speed"]):
        add("speed", s["measured_speed"] * MS_TO_KMH, "measured speed", width=0.6,
            dash="dot")
        add("measured", (s["measured_speed"] - s["speed"]) * MS_TO_KMH, "measured - true")
    add("error", (s["target"] - s["speed"]) * MS_TO_KMH, "error")
    if "command" in s:
        add("command", s["command"], "command u")
    if "force" in s:
        add("command", s["force"], "applied force", dash="dot")
    drive = s.get("force", s.get("command"))
    if drive is not None:
        modes.append((name, drive_modes(drive), t))
    if "acceleration" in s:
        _acceleration_traces(add, report)
    for output in _outputs(report):
        outputs.setdefault(f"{output.name} ({output.unit}): {output.description}", []
                           ).append(_line(t, s[output.name], f"{name} {output.name}", colour,
                                          name, False))
    if report is not base:
        first_series = base.run.series
        add("speed_diff", (s["speed"] - np.interp(t, first_series["t"],
                                                  first_series["speed"])) * MS_TO_KMH,
            f"speed - {base.label}")
        if "command" in s and "command" in first_series:
            add("command_diff", s["command"] - np.interp(t, first_series["t"],
                                                         first_series["command"]),
                f"u - {base.label}")


def _acceleration_traces(add, report: RunReport) -> None:
    """A run's acceleration, its jerk and, with an observer's z1..z3, those against the
    true speed, acceleration and total disturbance; `add` as in _run_traces."""
    s = report.run.series
    t = s["t"]
    add("acceleration", s["acceleration"], "acceleration")
    if len(t) > 1:
        centres, jerk = windowed_jerk(t, s["acceleration"])
        add("jerk", jerk, "jerk (1 s)", x=centres)
    if {"z1", "z2", "z3"} <= s.keys():
        add("z1", (s["z1"] - s["speed"]) * MS_TO_KMH, "z1 - v")
        add("z2", s["acceleration"], "acceleration a")
        add("z2", s["z2"], "z2", dash="dash")
        b0 = observer_b0(report.run.parameters or {})
        if b0 is not None and "command" in s:
            add("z3", total_disturbance(s, b0), "total disturbance f")
        add("z3", s["z3"], "z3", dash="dash")


def time_figure(reports: list[RunReport]):
    panels = {name: [] for name in ("speed", "measured", "error", "command", "acceleration",
                                    "jerk", "z1", "z2", "z3", "outputs", "speed_diff",
                                    "command_diff")}
    outputs: dict[str, list] = {}
    modes = []
    s = reports[0].run.series
    panels["speed"].append(_line(s["t"], s["target"] * MS_TO_KMH, "target", "black",
                                 "target", True, dash="dash"))
    if np.any(np.isfinite(s.get("speed_limit", [np.inf]))):
        panels["speed"].append(_line(s["t"], s["speed_limit"] * MS_TO_KMH, "speed limit",
                                     LIMIT_COLOUR, "limit", True, dash="dashdot"))
    for report, colour in zip(reports, _colours(), strict=False):
        _run_traces(report, colour, reports[0], panels, outputs, modes)

    figure = Panels()
    figure.add("speed (km/h): target, true and measured", panels["speed"])
    figure.add("measured - true speed (km/h): the speed sensor", panels["measured"],
               height=0.6)
    limits = _limits(reports, ERROR_INDICES)
    figure.add("tracking error target - true speed (km/h)", panels["error"],
               [_bands({b: f"±{b:g} band" for r in reports for b in r.bands
                        if b not in limits}, "grey", "dot"), _bands(limits, "red", "dash")])
    figure.add("command u and applied force (N/kN)", panels["command"])
    figure.add(f"drive mode (|force| > {SWITCH_THRESHOLD:g} N/kN)", _mode_traces(modes),
               height=0.25 + 0.15 * len(modes))
    figure.add("acceleration (m/s²)", panels["acceleration"])
    figure.add(f"jerk, mean over {JERK_WINDOW:g} s (m/s³)", panels["jerk"],
               [_bands(_limits(reports, ("max_jerk",)), "red", "dash")])
    figure.add("observer: z1 - true speed (km/h)", panels["z1"], height=0.7)
    figure.add("observer: z2 and acceleration (m/s²)", panels["z2"])
    figure.add("observer: z3 and total disturbance (m/s³)", panels["z3"])
    for title, traces in outputs.items():
        figure.add(title, traces, height=0.7)
    figure.add(_text(f"speed difference to {reports[0].label} (km/h)"), panels["speed_diff"])
    figure.add(_text(f"command difference to {reports[0].label} (N/kN)"),
               panels["command_diff"])
    return figure.figure("time (s)", _change_lines(reports))


def _outputs(report: RunReport):
    """The named outputs of a controller kind without an observer (one with has z1..z3),
    or of an external node's law."""
    return named_outputs(report.run)[1]


def _mode_traces(modes: list[tuple[str, np.ndarray, np.ndarray]]) -> list:
    """One thick horizontal line per mode and run, on the run's row."""
    import plotly.graph_objects as go
    traces = []
    for number, (name, mode_of_step, t) in enumerate(modes):
        for mode, word, colour in MODES:
            xs = mode_segments(t, mode_of_step, mode)
            traces.append(go.Scatter(
                x=xs, y=[None if x is None else _text(name) for x in xs], mode="lines",
                name=word, legendgroup=word, showlegend=number == 0,
                line=dict(color=colour, width=14),
                hovertemplate=f"{word}<extra>{_text(name)}</extra>"))
    return traces


def _line_shapes(line: Line, top_row: int):
    """Neutral sections shaded, stations marked, on every distance subplot."""
    def draw(figure, row):
        for number, section in enumerate(line.neutral_sections):
            label = dict(annotation_text="neutral section", annotation_position="top left") \
                if row == top_row and number == 0 else {}
            figure.add_vrect(x0=section.start / 1000, x1=section.end / 1000,
                             fillcolor="orange", opacity=0.3, line_width=0, row=row, col=1,
                             **label)
        for station in line.stations:
            label = dict(annotation_text=_text(station.name)) if row == top_row else {}
            figure.add_vline(x=station.position / 1000, line=dict(color="purple", width=1),
                             row=row, col=1, **label)
    return draw


def distance_figure(reports: list[RunReport]):
    """Speed and error against distance over the line's gradients (None without
    positions)."""
    import plotly.graph_objects as go
    with_position = [(r, c) for r, c in zip(reports, _colours(), strict=False)
                     if "position" in r.run.series]
    if not with_position:
        return None
    lines = (run_line(r.run.parameters) for r, _ in with_position if r.run.parameters)
    line = next((found for found in lines if found is not None), None)
    speed, error = [], []
    first = with_position[0][0].run.series
    km = first["position"] / 1000
    speed.append(go.Scatter(x=_f32(km), y=_f32(first["target"] * MS_TO_KMH), name="target",
                            line=dict(color="black", dash="dash", width=1.2)))
    if np.any(np.isfinite(first.get("speed_limit", [np.inf]))):
        speed.append(go.Scatter(x=_f32(km), y=_f32(first["speed_limit"] * MS_TO_KMH),
                                name="speed limit",
                                line=dict(color=LIMIT_COLOUR, dash="dashdot", width=1.2)))
    for report, colour in with_position:
        s = report.run.series
        x = _f32(s["position"] / 1000)
        speed.append(go.Scatter(x=x, y=_f32(s["speed"] * MS_TO_KMH),
                                name=_text(f"{report.label} speed"), legendgroup=report.label,
                                line=dict(color=colour, width=1.2)))
        error.append(go.Scatter(x=x, y=_f32((s["target"] - s["speed"]) * MS_TO_KMH),
                                name=_text(f"{report.label} error"), legendgroup=report.label,
                                showlegend=False, line=dict(color=colour, width=1.2)))
    panels = Panels()
    shapes = [_line_shapes(line, 1)] if line else []
    panels.add("speed (km/h) against distance", speed, shapes, height=1.4)
    panels.add("tracking error target - true speed (km/h)", error, shapes)
    if line is not None and line.gradients:
        edges = [(g.start / 1000, g.end / 1000, g.value) for g in line.gradients]
        panels.add("gradient (per mille, uphill +)", [go.Scatter(
            x=[x for a, b, _ in edges for x in (a, b)], y=[v for *_, v in edges for _ in "ab"],
            name="gradient", fill="tozeroy", line=dict(color="saddlebrown", width=1))],
            shapes, height=0.7)
    return panels.figure("distance (km)")


def convergence_figure(tunings: list[Tuning]):
    import plotly.graph_objects as go
    figure = go.Figure()
    for tuning in tunings:
        figure.add_trace(go.Scatter(x=tuning.evaluations, y=tuning.best, name=_text(tuning.name),
                                    mode="lines+markers", line_shape="hv"))
    figure.update_layout(xaxis_title="fitness evaluations",
                         yaxis_title=_text(convergence_axis(tunings)), yaxis_type="log",
                         height=420, title="infeasible candidates score above 1e9")
    return figure


def _table(header: list[str], rows: list[list[tuple[str, ...]]], css: str = "") -> str:
    """Cells are (text, status[, why]): a status colours its cell, why is its tooltip."""
    def cell(tag, text, status="", why=""):
        style = f" style='background:{STATUS_COLOURS[status]}'" if status else ""
        tip = f" title='{html.escape(why)}'" if why else ""
        return f"<{tag}{style}{tip}>{html.escape(text)}</{tag}>"
    return (f"<table class='{css}'><tr>" + "".join(cell("th", h) for h in header) + "</tr>"
            + "".join("<tr>" + "".join(cell("td", *c) for c in row) + "</tr>" for row in rows)
            + "</table>")


def page_sections(reports: list[RunReport], rows: list[VerdictRow]) -> list[str]:
    """The verdict first (a line per run, then one row per index), then the runs."""
    labels = [r.label for r in reports]
    parts = []
    for report in reports:
        overall, text = report.summary
        parts.append(f"<div class='summary' style='background:{STATUS_COLOURS[overall]}'>"
                     f"{html.escape(overall.upper() or 'NO VERDICT')}: {html.escape(text)}</div>")
    keys = list(dict.fromkeys(k for r in reports for k in r.identity))
    parts.append("<h2>The run" + ("s" if len(reports) > 1 else "") + "</h2>")
    parts.append(_table([""] + labels, [[(key, "")] + [(r.identity.get(key, "-"), "")
                                                         for r in reports] for key in keys],
                        "identity"))
    changes = change_rows(reports)
    if changes:
        parts.append("<h2>Live parameter changes</h2><p>Set on the running controller "
                     "(<code>ros2 param set</code>), recorded in the bag; from that step on "
                     "(dotted lines on the time plots).</p>")
        parts.append(_table(CHANGES_HEADER, [[(cell, "") for cell in row] for row in changes]))
    parts.append("<h2>Verdict</h2><p>Each index from the bag (e = target - true speed) "
                 "against the run's requirement (<code>report.require</code> of its "
                 "scenario): green met, red broken, yellow not judged (the line above says "
                 "why; so does the cell's tooltip).</p>")
    whys = [{key: report.judged(key)[1] for key in report.requirements} for report in reports]
    parts.append(_table(["index", "requirement"] + labels, [
        [(row.heading, ""), (row.requirement, "")]
        + [(text + (f" {status}" if status else ""), status, why.get(row.key, ""))
           for (text, status), why in zip(row.cells, whys, strict=True)]
        for row in rows]))
    parts += [f"<p>{html.escape(note)}</p>" for note in report_notes(reports)]
    return parts


def write_html(reports: list[RunReport], rows: list[VerdictRow], tunings: list[Tuning],
               path: Path, sections: list[str] = (), more_figures: list[tuple] = ()) -> Path:
    """`sections` (HTML) follow the verdict, `more_figures` ((title, figure): the
    journeys') the distance figure."""
    figures = []  # (title, figure, scripts once drawn)
    if reports:
        figures.append(("Against time (zoom any subplot: all follow; report.html#t=START:END "
                        "opens on that stretch)", time_figure(reports), [ZOOM_FROM_ADDRESS]))
        distance = distance_figure(reports)
        if distance is not None:
            figures.append(("Against distance, over the line", distance, []))
        figures += [(title, figure, []) for title, figure in more_figures]
    if tunings:
        figures.append(("Tuning convergence", convergence_figure(tunings), []))
    parts = ["<!doctype html><html><head><meta charset='utf-8'><title>ATO run report</title>",
             f"<style>{STYLE}</style></head><body><h1>ATO run report</h1>"]
    parts += page_sections(reports, rows) + list(sections)
    for number, (title, figure, scripts) in enumerate(figures):
        parts.append(f"<h2>{html.escape(title)}</h2>")
        parts.append(figure.to_html(full_html=False, include_plotlyjs=number == 0,
                                    post_script=[*scripts, COUNT_RENDERED],
                                    config={"displaylogo": False, "scrollZoom": False}))
    parts.append("</body></html>")
    path.write_text("\n".join(parts))
    return path
