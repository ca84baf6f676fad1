"""Reports on recorded runs: the verdict, the run's identity and the seed papers' figures.

One scorer (core.scoring.score_series) gives the indices, so a report and
score_bag.py always agree. Each index stands beside the run's requirement
(report.require, kept in the bag with the run's other parameters) and passes, fails
or is not judged, with the reason: the run ended before its stop (stopping and
running-time errors), the bag is partial (a requirement met so far may still be
broken later), the run does not give the index. Live parameter changes the bag
records are listed, marked on the time plots and shown in the gains. The report is
Markdown with PNG figures (matplotlib, Agg) and an interactive, self-contained HTML
page (ato_nodes.reports.report_html, Plotly). Names taken from a bag (runs, scenarios,
trains, lines, stations) are escaped in both: a bag is anyone's file.
"""

from __future__ import annotations

import csv
import itertools
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ato_nodes.core.base.registry import Output
from ato_nodes.core.config.components import CONTROLLERS, PROFILES
from ato_nodes.core.config.context import planned_mass
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.base.units import MS_TO_KMH
from ato_nodes.core.config.schema import SPEC_BY_NAME
from ato_nodes.core.run.last_stop import AT_LAST_STOP
from ato_nodes.core.run.located import ODOMETRY_SERIES
from ato_nodes.core.scoring.catalogue import (FITNESS, GROWING_INDICES, STOP_INDICES, Requirement,
                                              journey_last_stop)
from ato_nodes.core.run.scoring import observer_b0, run_line, stop_not_reached, total_disturbance
from ato_nodes.core.scoring.journey import last_stop_missed
from ato_nodes.results.journeys import score_run

if TYPE_CHECKING:  # annotations only: in-process tuning plots without the bag reader
    from ato_nodes.bags.bagio import Run

# One colour per run, in the PNG figures and the page alike: none red, which is the
# speed limit's (drawn dash-dotted as well), nor grey, the reference bands'.
RUN_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#bcbd22",
               "#17becf")
LIMIT_COLOUR = "#d62728"

INDEX_COLUMNS = [  # (key, heading, format)
    ("steps", "steps", "{:d}"),
    ("itae", "ITAE (m/s) s^2", "{:.6g}"),
    ("iae", "IAE m", "{:.6g}"),
    ("ise", "ISE m^2/s", "{:.6g}"),
    ("max_abs_error_kmh", "max abs(e) km/h", "{:.4f}"),
    ("median_abs_error_kmh", "median abs(e) km/h", "{:.4f}"),
    ("p95_abs_error_kmh", "p95 abs(e) km/h", "{:.4f}"),
    ("max_abs_error_outside_steps_kmh", "max abs(e) outside steps km/h", "{:.4f}"),
    ("j_seed004", "J (seed 004)", "{:.6g}"),
    ("eso_speed_max_dev", "max abs(z1-v) m/s", "{:.3g}"),
    ("eso_acceleration_max_dev", "max abs(z2-a) m/s^2", "{:.3g}"),
    ("eso_disturbance_max_dev", "max abs(z3-f) m/s^3", "{:.3g}"),
    ("overshoot_percent", "overshoot %", "{:.3f}"),
    ("traction_energy_kwh", "traction kWh", "{:.2f}"),
    ("regenerated_energy_kwh", "regenerated kWh", "{:.2f}"),
    ("net_energy_kwh", "net energy kWh", "{:.2f}"),
    ("max_jerk", "max jerk (1 s) m/s^3", "{:.3f}"),
    ("comfort_index", "comfort m/s^3", "{:.4f}"),
    ("switch_count", "switches", "{:d}"),
    ("overspeed_time", "overspeed s", "{:.2f}"),
    ("max_overspeed_kmh", "max overspeed km/h", "{:.3f}"),
    ("stopping_error", "stopping error m", "{:+.3f}"),
    ("abs_stopping_error", "abs(stopping error) m", "{:.3f}"),
    ("overrun", "overrun (past 0.3 m)", "{:.0f}"),
    ("arrival_time", "arrival s", "{:.2f}"),
    ("running_time_error", "run-time error s", "{:+.2f}"),
    ("neutral_traction_command_time", "neutral traction commanded s", "{:.1f}"),
    ("neutral_traction_force_time", "neutral traction applied s", "{:.1f}"),
    ("stepped_time", "stepped approach s", "{:.1f}"),
]


# What a tracking comparison shows (scripts/compare_scenarios.py, scripts/ablation.py).
TRACKING_KEYS = ("max_abs_error_kmh", "max_abs_error_outside_steps_kmh", "p95_abs_error_kmh",
                 "itae", "stopping_error", "max_jerk", "switch_count", "overspeed_time",
                 "neutral_traction_command_time", "net_energy_kwh")


def markdown_table(results: dict[str, dict], keys: tuple[str, ...] = TRACKING_KEYS,
                   extra: dict[str, dict[str, str]] | None = None) -> str:
    """One row per run (`results`: label -> indices), one column per index of `keys`
    that some run has, formatted as in INDEX_COLUMNS; `extra` adds text columns
    (heading -> label -> text)."""
    present = [key for key in keys if any(key in r for r in results.values())]
    extra = extra or {}
    lines = ["| run | " + " | ".join([heading(k) for k in present] + list(extra)) + " |",
             "|---|" + "---|" * (len(present) + len(extra))]
    for name, indices in results.items():
        cells = [format_index(k, indices[k]) if k in indices else "-" for k in present]
        cells += [texts.get(name, "") for texts in extra.values()]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


COLUMNS = {key: (title, form) for key, title, form in INDEX_COLUMNS}
OTHER_FORMAT = "{:.4g}"  # an index the tables do not list, named by a requirement


def heading(key: str) -> str:
    return COLUMNS.get(key, (key, ""))[0]


def format_index(key: str, value) -> str:
    form = COLUMNS.get(key, ("", OTHER_FORMAT))[1]
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return form.format(int(value) if form == "{:d}" else value)


class ReportError(ValueError):
    """An input the report cannot use (one-line message)."""


def md_text(text) -> str:
    """Text as Markdown shows it literally, on one line: what could open an HTML tag or
    an entity is escaped, and Markdown's marks (tables' | included) backslash-escaped."""
    text = " ".join(str(text).split())
    text = re.sub(r"&(?=#?\w+;)", "&amp;", text)
    text = re.sub(r"<(?=[A-Za-z/!?])", "&lt;", text)
    return re.sub(r"([\\`*_\[\]|~])", r"\\\1", text)


@dataclass
class Figure:
    title: str
    path: Path


@dataclass(frozen=True)
class LiveChange:
    """A controller parameter set on the live run: from step `step` (time t, s) on."""

    step: int
    t: float
    name: str
    old: object
    new: object

    @property
    def text(self) -> str:
        return f"{self.name} {_value(self.old)} -> {_value(self.new)}"


def live_changes(run: Run) -> list[LiveChange]:
    """The run's live parameter changes in step order, each with the value it replaced."""
    current = dict(run.parameters or {})
    period = current.get("run.period", math.nan)
    changes = []
    for step in sorted(run.parameter_changes):
        for name, value in sorted(run.parameter_changes[step].items()):
            changes.append(LiveChange(step, step * period, name, current.get(name, "?"), value))
            current[name] = value
    return changes


@dataclass
class Tuning:
    """A tuning directory's convergence (tune.py's history.csv) and its fitness."""

    path: Path
    evaluations: list[int]
    best: list[float]
    fitness: str  # the index key (itae, j_seed004, ...), "" when tuning.json does not say

    @property
    def name(self) -> str:
        return self.path.name or str(self.path)

    @property
    def axis_title(self) -> str:
        return f"best fitness: {heading(self.fitness)}" if self.fitness else "best fitness"


def read_tuning(directory: Path) -> Tuning:
    """A tuning directory's history.csv (and the fitness its tuning.json names); a file
    that is not tune.py's is a ReportError naming it and its line."""
    history = directory / "history.csv"
    evaluations, best = [], []
    try:
        with history.open(newline="") as handle:
            for number, row in enumerate(csv.DictReader(handle), start=2):
                try:
                    evaluations.append(int(row["evaluations"]))
                    best.append(float(row["best_fitness"]))
                except (KeyError, TypeError, ValueError):
                    raise ReportError(f"{history} line {number} is not a tuning's history "
                                      "row (iteration, evaluations, best_fitness, ...)") from None
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise ReportError(f"{history}: cannot read it ({getattr(exc, 'strerror', None) or exc})"
                          ) from None
    if not evaluations:
        raise ReportError(f"{history} holds no history rows")
    try:
        fitness = FITNESS.get(json.loads((directory / "tuning.json").read_text())["fitness"], "")
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        fitness = ""
    return Tuning(directory, evaluations, best, fitness)


def run_indices(run: Run) -> dict:
    """The scorer's indices for a run, plus which roles the bag lacked."""
    indices = score_run(run.series, run.parameters)
    indices["skipped"] = run.missing
    return indices


def label(run: Run) -> str:
    return run.path.name if run.path.name else str(run.path)


def pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def save_figure(figure, path: Path) -> Path:
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    pyplot().close(figure)
    return path


def _mark_changes(axes, run: Run, colour: str, named: bool = True) -> None:
    """A dotted vertical line at each live parameter change of the run (in the legend
    if `named`)."""
    for change in live_changes(run):
        axes.axvline(change.t, color=colour, ls=":", lw=1.2,
                     label=f"{label(run)}: {change.text} at {change.t:g} s" if named else None)


def _overlay(runs: list[Run], x, y, labels: tuple[str, str, str], path: Path,
             target=None, bands: tuple[float, ...] = (), limit=None,
             against_time: bool = True) -> Path:
    """One line per run of y(series) against x(series); optionally the first run's
    target as a dashed line, its speed limit, and reference bands +-band; against
    time, each run's live parameter changes marked."""
    plt = pyplot()
    figure, axes = plt.subplots(figsize=(9, 4.5))
    if target is not None:
        axes.plot(x(runs[0].series), target(runs[0].series), "k--", lw=1, label="target")
    if limit is not None and np.any(np.isfinite(runs[0].series.get("speed_limit", [np.inf]))):
        axes.plot(x(runs[0].series), limit(runs[0].series), color=LIMIT_COLOUR, ls="-.",
                  lw=1.2, label="speed limit")
    for run, colour in zip(runs, itertools.cycle(RUN_COLOURS)):
        axes.plot(x(run.series), y(run.series), color=colour, lw=0.9, label=label(run))
        if against_time:
            _mark_changes(axes, run, colour)
    for band, style in zip(bands, itertools.cycle((":", "-.", "--"))):
        for sign in (1, -1):
            axes.axhline(sign * band, color="grey", ls=style, lw=1,
                         label=f"±{band:g} km/h (scenario's band)" if sign > 0 else None)
    axes.set(xlabel=labels[0], ylabel=labels[1], title=labels[2])
    axes.grid(alpha=0.3)
    axes.legend()
    return save_figure(figure, path)


def plot_runs(runs: list[Run], out: Path) -> list[Figure]:
    """Speed against time and distance, error with the scenarios' bands, force, observer."""
    def time(s):
        return s["t"]

    def speed(s):
        return s["speed"] * MS_TO_KMH

    def target(s):
        return s["target"] * MS_TO_KMH

    def limit(s):
        return s["speed_limit"] * MS_TO_KMH

    figures = [Figure("Speed against time", _overlay(
        runs, time, speed, ("time (s)", "speed (km/h)", "Speed tracking"),
        out / "speed_time.png", target=target, limit=limit))]
    with_position = [run for run in runs if "position" in run.series]
    if with_position:
        figures.append(Figure("Speed against distance", _overlay(
            with_position, lambda s: s["position"] / 1000, speed,
            ("distance (km)", "speed (km/h)", "Speed against distance"),
            out / "speed_distance.png", target=target, limit=limit, against_time=False)))
    figures.append(Figure("Tracking error", _overlay(
        runs, time, lambda s: (s["target"] - s["speed"]) * MS_TO_KMH,
        ("time (s)", "target - speed (km/h)", "Tracking error"), out / "error.png",
        bands=tuple(sorted({band for run in runs for band in run_bands(run)})))))
    with_command = [run for run in runs if "command" in run.series]
    if with_command:
        figures.append(Figure("Control force", _overlay(
            with_command, time, lambda s: s["command"],
            ("time (s)", "u (N/kN)", "Control force (specific)"), out / "command.png")))
    for index, (run, colour) in enumerate(zip(runs, itertools.cycle(RUN_COLOURS))):
        for plot, name in ((plot_observer, "observer"), (plot_outputs, "outputs"),
                           (plot_localisation, "localisation")):
            figure = plot(run, out / f"{name}_{index + 1}.png", colour)
            if figure:
                figures.append(figure)
    return figures


def named_outputs(run: Run) -> tuple[str, list[Output]]:
    """(whose, the named outputs to plot): an external node's law's (docs/external-nodes.md)
    or the run's controller kind's; none for a kind with an extended state observer
    (plot_observer) or an unknown kind."""
    from ato_nodes.bags.bagio import EXTERNAL_LAW  # the bag reader: see TYPE_CHECKING above
    external = (run.parameters or {}).get(EXTERNAL_LAW)
    if external:
        return external, external_outputs(run)
    try:
        component = CONTROLLERS[(run.parameters or {}).get("controller.kind", "")]
    except ScenarioError:
        return "", []
    if component.observer_gain is not None:
        return component.kind, []
    return component.kind, [o for o in component.outputs if o.name in run.series]


def plot_outputs(run: Run, path: Path, colour: str = RUN_COLOURS[0]) -> Figure | None:
    """Every named output of the run's controller (with its unit), against time; kinds
    with an extended state observer have plot_observer instead."""
    whose, outputs = named_outputs(run)
    if not outputs:
        return None
    plt = pyplot()
    figure, axes = plt.subplots(len(outputs), 1, figsize=(9, 1.9 * len(outputs) + 0.8),
                                sharex=True, squeeze=False)
    for axis, output in zip(axes[:, 0], outputs, strict=True):
        axis.plot(run.series["t"], run.series[output.name], color=colour, lw=0.8)
        _mark_changes(axis, run, "black", named=axis is axes[0, 0])
        axis.set_ylabel(f"{output.name}\n({output.unit})")
        axis.set_title(output.description, fontsize=9, loc="left")
        axis.grid(alpha=0.3)
    if live_changes(run):
        axes[0, 0].legend(loc="upper right", fontsize=8)
    axes[-1, 0].set_xlabel("time (s)")
    figure.suptitle(f"Controller outputs ({whose}): {label(run)}")
    return Figure(f"Controller outputs: {label(run)}", save_figure(figure, path))


def external_outputs(run: Run) -> list[Output]:
    """The named outputs of an external node's law (docs/external-nodes.md): the series
    its /ato/controller_state gave, named by the messages; their units are the law's."""
    from ato_nodes.bags.bagio import ROLES
    recorded = {name for _, fields in ROLES.values() if isinstance(fields, list)
                for name, _ in fields} | {"t", "preview", *ODOMETRY_SERIES}
    return [Output(name, "as the law gives it", f"{name}, from the external node")
            for name in run.series if name not in recorded]


def plot_observer(run: Run, path: Path, colour: str = RUN_COLOURS[0]) -> Figure | None:
    """Seed 000 figures 10-12: z1, z2, z3 against speed, acceleration, total disturbance."""
    s = run.series
    if not {"z1", "z2", "z3", "speed", "acceleration"} <= s.keys():
        return None
    plt = pyplot()
    figure, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    axes[0].plot(s["t"], s["speed"] * MS_TO_KMH, "k", lw=1, label="speed")
    axes[0].plot(s["t"], s["z1"] * MS_TO_KMH, "r--", lw=0.8, label="z1")
    axes[0].set_ylabel("km/h")
    axes[1].plot(s["t"], s["acceleration"], "k", lw=1, label="acceleration")
    axes[1].plot(s["t"], s["z2"], "r--", lw=0.8, label="z2")
    axes[1].set_ylabel("m/s^2")
    b0 = observer_b0(run.parameters or {})
    if b0 is not None and "command" in s:
        axes[2].plot(s["t"], total_disturbance(s, b0), "k", lw=1, label="total disturbance f")
    axes[2].plot(s["t"], s["z3"], "r--", lw=0.8, label="z3")
    axes[2].set(xlabel="time (s)", ylabel="m/s^3")
    for axis in axes:
        _mark_changes(axis, run, colour, named=axis is axes[0])
        axis.grid(alpha=0.3)
        axis.legend(loc="upper right")
    axes[0].set_title(f"Extended state observer: {label(run)}")
    return Figure(f"Observer: {label(run)}", save_figure(figure, path))


def plot_localisation(run: Run, path: Path, colour: str = RUN_COLOURS[0]) -> Figure | None:
    """Where the ATO had its train against where it was (odometry.enabled): the located
    position's error with its +-3 sigma band and the marks read, the located speed's
    error, the slides and slips the wheels made and those the localisation saw."""
    s = run.series
    if not {"located_position", "position", "position_sigma", "speed"} <= s.keys():
        return None
    plt = pyplot()
    figure, axes = plt.subplots(3, 1, figsize=(9, 7.5), sharex=True)
    error, band = s["located_position"] - s["position"], 3.0 * s["position_sigma"]
    axes[0].fill_between(s["t"], -band, band, color="0.85", label="+-3 sigma")
    axes[0].plot(s["t"], error, color=colour, lw=0.8, label="located - true")
    marks = np.isfinite(s["mark_reading"])
    axes[0].plot(s["t"][marks], error[marks], "k|", ms=8, label="a balise or beacon read")
    limit = max(float(np.abs(error).max()) * 1.3, 0.05)
    axes[0].set(ylabel="position error (m)", ylim=(-limit, limit))
    axes[1].plot(s["t"], (s["measured_speed"] - s["speed"]) * MS_TO_KMH, color=colour, lw=0.8,
                 label="located - true")
    axes[1].set_ylabel("speed error (km/h)")
    axes[2].plot(s["t"], s["wheel_creep"], "k", lw=0.8, label="the wheels' creep (true)")
    axes[2].plot(s["t"], 0.1 * s["slide_detected"], color=colour, lw=0.8,
                 label="slide (-) or slip (+) seen, x 0.1")
    axes[2].set(xlabel="time (s)", ylabel="creep")
    for axis in axes:
        axis.grid(alpha=0.3)
        axis.legend(loc="upper right", fontsize=8)
    axes[0].set_title(f"On-board localisation: {label(run)}")
    return Figure(f"Localisation: {label(run)}", save_figure(figure, path))


def convergence_axis(tunings: list[Tuning]) -> str:
    """The fitness axis' title: the tunings' fitness and unit when they share one."""
    titles = {tuning.axis_title for tuning in tunings}
    return titles.pop() if len(titles) == 1 else "best fitness (each tuning's own)"


def plot_convergence(tunings: list[Path | Tuning], path: Path) -> Figure:
    """Seed 000 figure 9: best fitness against evaluations, one line per tuning."""
    tunings = [t if isinstance(t, Tuning) else read_tuning(t) for t in tunings]
    plt = pyplot()
    figure, axes = plt.subplots(figsize=(9, 4.5))
    for tuning in tunings:
        axes.step(tuning.evaluations, tuning.best, where="post", marker="o", markersize=3,
                  label=tuning.name)
    axes.set(xlabel="fitness evaluations", ylabel=convergence_axis(tunings), yscale="log",
             title="Tuning convergence (infeasible candidates score above 1e9)")
    axes.grid(alpha=0.3, which="both")
    axes.legend()
    return Figure("Tuning convergence", save_figure(figure, path))


PASS, FAIL, UNMEASURED = "pass", "fail", "not judged"


@dataclass
class RunReport:
    """One run as the report judges it: its indices, its own requirements (from its
    parameters, so runs of different scenarios are each judged by theirs), the
    reference bands of its tracking-error plot and what the run was."""

    run: Run
    label: str
    indices: dict
    requirements: dict  # index -> tuning.Requirement
    bands: tuple[float, ...]
    identity: dict[str, str]

    def __post_init__(self):
        self.partial = self.run.partial
        self.stop_not_reached = last_stop_missed(self.indices["journey"]) \
            if "journey" in self.indices else stop_not_reached(self.run.series,
                                                               self.run.parameters)

    def judged(self, key: str) -> tuple[str, str]:
        """(PASS, FAIL or UNMEASURED, why it is not judged) for a required index;
        ("", "") for one without requirement."""
        requirement = self.requirements.get(key)
        if requirement is None:
            return "", ""
        if key in STOP_INDICES and self.stop_not_reached:
            return UNMEASURED, self.stop_not_reached
        value = self.indices.get(key)
        if key not in self.indices:
            return UNMEASURED, "this run does not give it"
        if not isinstance(value, (int, float)) or not math.isfinite(value):
            return UNMEASURED, "not measured in this run"
        met = requirement.violation(self.indices) == 0.0
        if self.partial and (met or key not in GROWING_INDICES):
            return UNMEASURED, ("met" if met else "broken") + " over the steps recorded, " \
                "but the run is partial"
        return (PASS if met else FAIL), ""

    def index_text(self, key: str) -> str:
        """An index's value as the verdict table gives it: a journey's stop index without
        a stop at its last stop says why ("- (not reached)")."""
        value = self.indices[key]
        if key in STOP_INDICES and "journey" in self.indices and not math.isfinite(value):
            return f"- ({journey_last_stop(self.indices['journey'])[1]})"
        return format_index(key, value)

    def status(self, key: str) -> str:
        """PASS, FAIL or UNMEASURED for a required index, "" for one without requirement."""
        return self.judged(key)[0]

    def requirement_text(self, key: str) -> str:
        return f"{heading(key)} <= {self.requirements[key].limit:g}"

    @property
    def summary(self) -> tuple[str, str]:
        """(overall status, one line): FAIL if any requirement is broken, else
        UNMEASURED if any cannot be judged from the bag, else PASS ("" without any);
        the line says why each not judged is not."""
        judged = {key: self.judged(key) for key in self.requirements}
        broken = [f"{heading(k)} {format_index(k, self.indices[k])} > "
                  f"{self.requirements[k].limit:g}" for k, (v, _) in judged.items() if v == FAIL]
        reasons: dict[str, list[str]] = {}
        for key, (status, reason) in judged.items():
            if status == UNMEASURED:
                reasons.setdefault(reason, []).append(heading(key))
        partial = f" (partial: {self.partial})" if self.partial else ""
        if not judged:
            return "", f"{self.label}{partial}: no requirements (the scenario sets no " \
                       "report.require)"
        unjudged = sum(len(keys) for keys in reasons.values())
        text = f"{self.label}{partial}: {len(judged) - len(broken) - unjudged} of " \
               f"{len(judged)} requirements met"
        if broken:
            text += f"; broken: {', '.join(broken)}"
        if reasons:
            text += f"; {UNMEASURED}: " + "; ".join(f"{', '.join(keys)} ({reason})"
                                                    for reason, keys in reasons.items())
        overall = FAIL if broken else UNMEASURED if reasons else PASS
        return overall, text


def _checked_text(run: Run, name: str) -> str:
    """A report.* parameter of the run (its default for a bag without parameters),
    checked as a scenario's is: a bag is anyone's file."""
    value = (run.parameters or {}).get(name, SPEC_BY_NAME[name].default)
    return SPEC_BY_NAME[name].check(value, label(run))


def run_requirements(run: Run) -> dict:
    """The run's report.require as Requirements (tune.py's), by index name."""
    requirements = Requirement.parse_list(_checked_text(run, "report.require"),
                                          f"{label(run)}: report.require")
    return {r.name: r for r in requirements}


def run_bands(run: Run) -> tuple[float, ...]:
    """The run's report.error_bands, km/h."""
    return tuple(float(item) for item in _checked_text(run, "report.error_bands").split(",")
                 if item.strip())


def scenario_name(run: Run) -> str:
    """The scenario run_stack.py named in the bag's summary.json; '-' for other bags."""
    try:
        return str(json.loads((run.path / "summary.json").read_text())["scenario"])
    except (OSError, ValueError, KeyError, TypeError):
        return "-"


def _value(value) -> str:
    return f"{value:g}" if isinstance(value, float) else Path(value).name \
        if isinstance(value, str) and "/" in value else str(value)


def _gain(run: Run, name: str, changes: list[LiveChange]) -> str:
    """A gain's value, then each live change of it: "b1 40 -> 100 at 59.2 s"."""
    text = f"{name.split('.', 1)[1]} {_value(run.parameters[name])}"
    return text + "".join(f" -> {_value(c.new)} at {c.t:g} s" for c in changes if c.name == name)


def identity(run: Run) -> dict[str, str]:
    """What the run was: scenario, train, target, controller and its gains, line."""
    values = run.parameters
    if not values:
        return {"scenario": "-", "parameters": "none in the bag (not recorded by this stack)"}
    described = {"scenario": scenario_name(run)}
    described["train"] = (values.get("plant.train") or "the scenario's own plant.* values") + \
        f" ({values.get('plant.mass', math.nan):g} t; speed sensor noise " \
        f"{values.get('plant.speed_noise', 0.0):g} m/s)"
    for registry in (PROFILES, CONTROLLERS):
        kind = values.get(registry.kind_parameter.name, "")
        try:
            component = registry[kind]
        except ScenarioError:
            described[registry.role] = f"{kind} (a kind this version does not know)"
            continue
        described[registry.role] = f"{kind}: {component.description}"
        if registry is CONTROLLERS:
            changes = live_changes(run)
            described["gains"] = ", ".join(_gain(run, spec.name, changes)
                                           for spec in component.parameters
                                           if spec.name in values) or "-"
    described["limits"] = (f"u in [{values.get('controller.u_min', math.nan):g}, "
                           f"{values.get('controller.u_max', math.nan):g}] N/kN, rate "
                           f"{values.get('controller.max_rate', math.nan):g} N/kN/s, preview "
                           f"{values.get('controller.preview', 0)} steps")
    described["load"] = plan_mass(run)
    line = run_line(values)
    if line is None:
        described["line"] = "open track (no line file)"
    else:
        stations = ", ".join(f"{s.name} ({s.position:g} m)" for s in line.stations)
        described["line"] = (
            f"{line.name}: {line.length / 1000:g} km, stop at {line.stop_position:g} m"
            + (f", planned run time {line.planned_run_time:g} s" if line.planned_run_time
               else "") + (f"; stations {stations}" if stations else ""))
    described["run"] = (f"{values.get('run.duration', math.nan):g} s in steps of "
                        f"{values.get('run.period', math.nan):g} s"
                        + (f"; partial: {run.partial}" if run.partial else "")
                        + (f"; ended {AT_LAST_STOP} at step {run.recorded_steps}, standing "
                           f"{values['run.last_stop_hold']:g} s (run.last_stop_hold)"
                           if run.ended_at_last_stop else ""))
    return described


def plan_mass(run: Run) -> str:
    """Which mass the plan used when, and from where: the load weighing's reading or the
    given one, the bound planned for (profile.replan), each re-plan from the on-board
    estimate (the bag's re-plans that carry a mass)."""
    values = run.parameters
    reading = values.get("train.mass_reading", 1.0)
    source = (f"the load weighing's reading {reading:.3f}"
              + (f" (its cells reading {values['train.load_weighing_bias']:+g} off)"
                 if values.get("train.load_weighing_bias") else "")
              if values.get("train.load_weighing") else
              f"no load weighing: train.mass_reading {reading:g} as given")
    if not values.get("profile.replan.enabled"):
        return f"{source}; planned for it, once"
    planned = planned_mass({name: values.get(name, spec.default)  # an older bag: defaults
                            for name, spec in SPEC_BY_NAME.items()})
    replans = [replan for replan in run.replans if "mass" in replan]
    return (f"{source}; planned for {planned:.3f} (its bound, profile.replan)" + "".join(
        f"; re-planned at {replan['time']:.1f} s for {replan['mass']:.3f} (the on-board "
        f"estimate)" for replan in replans))


def judge(run: Run) -> RunReport:
    return RunReport(run, label(run), run_indices(run), run_requirements(run), run_bands(run),
                     identity(run))


@dataclass
class VerdictRow:
    """One index across the runs: its requirement ("" none, "per run" if they differ)
    and per run the value's text and its status."""

    key: str
    heading: str
    requirement: str
    cells: list[tuple[str, str]] = field(default_factory=list)


def verdict_rows(reports: list[RunReport]) -> list[VerdictRow]:
    """One row per index: the required ones first (in the order the scenarios name
    them), then every other index some run has, in INDEX_COLUMNS order."""
    required = list(dict.fromkeys(k for r in reports for k in r.requirements))
    listed = [key for key, _, _ in INDEX_COLUMNS if any(key in r.indices for r in reports)]
    rows = []
    for key in required + [k for k in listed if k not in required]:
        limits = {f"<= {r.requirements[key].limit:g}" for r in reports if key in r.requirements}
        row = VerdictRow(key, heading(key), limits.pop() if len(limits) == 1 else
                         "per run" if limits else "")
        for report in reports:
            text = report.index_text(key) if key in report.indices else "-"
            if row.requirement == "per run" and key in report.requirements:
                text += f" (<= {report.requirements[key].limit:g})"
            row.cells.append((text, report.status(key)))
        rows.append(row)
    return rows


MARK = {PASS: "pass", FAIL: "**FAIL**", UNMEASURED: "not judged", "": ""}
CHANGES_HEADER = ["run", "step", "t (s)", "parameter", "old -> new"]


def change_rows(reports: list[RunReport]) -> list[list[str]]:
    """One row per live parameter change of every run (CHANGES_HEADER)."""
    return [[r.label, str(c.step), f"{c.t:g}", c.name, f"{_value(c.old)} -> {_value(c.new)}"]
            for r in reports for c in live_changes(r.run)]


def report_notes(reports: list[RunReport]) -> list[str]:
    """What the report leaves out or qualifies, run by run."""
    notes = [f"{r.label}: partial, {r.partial}: the indices cover the steps recorded"
             for r in reports if r.partial]
    notes += [f"{r.label}: no {', '.join(r.indices['skipped'])} topic; indices needing them "
              f"skipped" for r in reports if r.indices["skipped"]]
    return notes + [f"{r.label}: {note}" for r in reports for note in r.run.notes]


def _markdown_rows(header: list[str], rows: list[list[str]]) -> list[str]:
    """A Markdown table of plain text cells (escaped here); a cell already in Markdown
    is a Markup."""
    def cell(text) -> str:
        return text if isinstance(text, Markup) else md_text(text)
    return ["| " + " | ".join(map(cell, header)) + " |", "|" + "---|" * len(header)] + \
        ["| " + " | ".join(map(cell, row)) + " |" for row in rows]


class Markup(str):
    """Markdown text, written as it is."""


def markdown_report(reports: list[RunReport], rows: list[VerdictRow],
                    figures: list[Figure], sections: list[str] = ()) -> str:
    """`sections`: Markdown lines after the verdict and notes (the journeys')."""
    labels = [r.label for r in reports]
    lines = ["# ATO run report", ""]
    for report in reports:
        overall, text = report.summary
        lines.append(f"- **{overall.upper() or 'NO VERDICT'}** {md_text(text)}")
    if reports:
        keys = list(dict.fromkeys(k for r in reports for k in r.identity))
        lines += ["", "## The run" + ("s" if len(reports) > 1 else ""), ""]
        lines += _markdown_rows([""] + labels, [[key] + [r.identity.get(key, "-") for r in reports]
                                                for key in keys])
        changes = change_rows(reports)
        if changes:
            lines += ["", "## Live parameter changes", "", "Set on the running controller "
                      "(`ros2 param set`), recorded in the bag; from that step on.", ""]
            lines += _markdown_rows(CHANGES_HEADER, changes)
        lines += ["", "## Verdict", "", "Indices from the bags alone (e = target - true speed, "
                  "trapezoidal integrals from t = 0), against each run's requirements "
                  "(`report.require` of its scenario).", ""]
        lines += _markdown_rows(["index", "requirement"] + labels, [
            [row.heading, row.requirement] + [Markup(" ".join(filter(None, (
                md_text(text), MARK[status])))) for text, status in row.cells] for row in rows])
    lines += [""] + [f"- {md_text(note)}" for note in report_notes(reports)] + list(sections)
    for figure in figures:
        title = md_text(figure.title)
        lines += ["", f"## {title}", "", f"![{title}]({figure.path.name})"]
    return "\n".join(lines) + "\n"
