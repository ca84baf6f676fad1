"""Reports on recorded runs: the index table and the seed papers' figures.

One scorer (core.scoring.score_series) gives the indices, so a report and
score_bag.py always agree. Plots are PNG (matplotlib, Agg); the report is
Markdown plus a self-contained HTML page with the PNGs embedded.
"""

from __future__ import annotations

import base64
import csv
import html
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ato_nodes.bagio import Run
from ato_nodes.core.components import CONTROLLERS
from ato_nodes.core.errors import ScenarioError
from ato_nodes.core.indices import MS_TO_KMH
from ato_nodes.core.scoring import observer_b0, score_series, total_disturbance

SEED000_BANDS_KMH = (0.05, 0.4)  # seed 000: body text and abstract
INDEX_COLUMNS = [  # (key, heading, format)
    ("steps", "steps", "{:d}"),
    ("itae", "ITAE", "{:.6g}"),
    ("iae", "IAE", "{:.6g}"),
    ("ise", "ISE", "{:.6g}"),
    ("max_abs_error_kmh", "max abs(e) km/h", "{:.4f}"),
    ("median_abs_error_kmh", "median abs(e) km/h", "{:.4f}"),
    ("p95_abs_error_kmh", "p95 abs(e) km/h", "{:.4f}"),
    ("max_abs_error_outside_steps_kmh", "max abs(e) outside steps km/h", "{:.4f}"),
    ("j_seed004", "J (seed 004)", "{:.6g}"),
    ("eso_speed_max_dev", "max abs(z1-v) m/s", "{:.3g}"),
    ("eso_acceleration_max_dev", "max abs(z2-a) m/s^2", "{:.3g}"),
    ("eso_disturbance_max_dev", "max abs(z3-f)", "{:.3g}"),
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
    ("running_time_error", "run-time error s", "{:+.2f}"),
]


# What a tracking comparison shows (scripts/compare_scenarios.py, scripts/ablation.py).
TRACKING_KEYS = ("max_abs_error_kmh", "max_abs_error_outside_steps_kmh", "p95_abs_error_kmh",
                 "itae", "stopping_error", "max_jerk", "switch_count", "overspeed_time",
                 "net_energy_kwh")


def markdown_table(results: dict[str, dict], keys: tuple[str, ...] = TRACKING_KEYS,
                   extra: dict[str, dict[str, str]] | None = None) -> str:
    """One row per run (`results`: label -> indices), one column per index of `keys`
    that some run has, formatted as in INDEX_COLUMNS; `extra` adds text columns
    (heading -> label -> text)."""
    columns = {key: (heading, form) for key, heading, form in INDEX_COLUMNS}
    present = [key for key in keys if any(key in r for r in results.values())]
    extra = extra or {}
    lines = ["| run | " + " | ".join([columns[k][0] for k in present] + list(extra)) + " |",
             "|---|" + "---|" * (len(present) + len(extra))]
    for name, indices in results.items():
        cells = [columns[k][1].format(int(indices[k]) if columns[k][1] == "{:d}" else indices[k])
                 if k in indices else "-" for k in present]
        cells += [texts.get(name, "") for texts in extra.values()]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


@dataclass
class Figure:
    title: str
    path: Path


def run_indices(run: Run) -> dict:
    """The scorer's indices for a run, plus which roles the bag lacked."""
    indices = score_series(run.series, run.parameters)
    indices["skipped"] = run.missing
    return indices


def label(run: Run) -> str:
    return run.path.name if run.path.name else str(run.path)


def _pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _save(figure, path: Path) -> Path:
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    _pyplot().close(figure)
    return path


def _overlay(runs: list[Run], x, y, labels: tuple[str, str, str], path: Path,
             target=None, bands: bool = False, limit=None) -> Path:
    """One line per run of y(series) against x(series); optionally the first run's
    target as a dashed line, its speed limit, and seed 000's error bands."""
    plt = _pyplot()
    figure, axes = plt.subplots(figsize=(9, 4.5))
    if target is not None:
        axes.plot(x(runs[0].series), target(runs[0].series), "k--", lw=1, label="target")
    if limit is not None and np.any(np.isfinite(runs[0].series.get("speed_limit", [np.inf]))):
        axes.plot(x(runs[0].series), limit(runs[0].series), "r-", lw=1, label="speed limit")
    for run in runs:
        axes.plot(x(run.series), y(run.series), lw=0.9, label=label(run))
    if bands:
        for band, style in zip(SEED000_BANDS_KMH, (":", "-.")):
            for sign in (1, -1):
                axes.axhline(sign * band, color="grey", ls=style, lw=1,
                             label=f"±{band} km/h (seed 000)" if sign > 0 else None)
    axes.set(xlabel=labels[0], ylabel=labels[1], title=labels[2])
    axes.grid(alpha=0.3)
    axes.legend()
    return _save(figure, path)


def plot_runs(runs: list[Run], out: Path) -> list[Figure]:
    """Speed against time and distance, error with seed 000's bands, force, observer."""
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
            out / "speed_distance.png", target=target, limit=limit)))
    figures.append(Figure("Tracking error", _overlay(
        runs, time, lambda s: (s["target"] - s["speed"]) * MS_TO_KMH,
        ("time (s)", "target - speed (km/h)", "Tracking error"), out / "error.png", bands=True)))
    with_command = [run for run in runs if "command" in run.series]
    if with_command:
        figures.append(Figure("Control force", _overlay(
            with_command, time, lambda s: s["command"],
            ("time (s)", "u (N/kN)", "Control force (specific)"), out / "command.png")))
    for index, run in enumerate(runs):
        for plot, name in ((plot_observer, "observer"), (plot_outputs, "outputs")):
            figure = plot(run, out / f"{name}_{index + 1}.png")
            if figure:
                figures.append(figure)
    return figures


def plot_outputs(run: Run, path: Path) -> Figure | None:
    """Every named output the run's controller kind declares (with its unit), against
    time; kinds with an extended state observer have plot_observer instead."""
    try:
        component = CONTROLLERS[(run.parameters or {}).get("controller.kind", "")]
    except ScenarioError:
        return None
    outputs = [o for o in component.outputs if o.name in run.series]
    if component.observer_gain is not None or not outputs:
        return None
    plt = _pyplot()
    figure, axes = plt.subplots(len(outputs), 1, figsize=(9, 1.9 * len(outputs) + 0.8),
                                sharex=True, squeeze=False)
    for axis, output in zip(axes[:, 0], outputs):
        axis.plot(run.series["t"], run.series[output.name], lw=0.8)
        axis.set_ylabel(f"{output.name}\n({output.unit})")
        axis.set_title(output.description, fontsize=9, loc="left")
        axis.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time (s)")
    figure.suptitle(f"Controller outputs ({component.kind}): {label(run)}")
    return Figure(f"Controller outputs: {label(run)}", _save(figure, path))


def plot_observer(run: Run, path: Path) -> Figure | None:
    """Seed 000 figures 10-12: z1, z2, z3 against speed, acceleration, total disturbance."""
    s = run.series
    if not {"z1", "z2", "z3", "speed", "acceleration"} <= s.keys():
        return None
    plt = _pyplot()
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
        axis.grid(alpha=0.3)
        axis.legend(loc="upper right")
    axes[0].set_title(f"Extended state observer: {label(run)}")
    return Figure(f"Observer: {label(run)}", _save(figure, path))


def plot_convergence(tunings: list[Path], path: Path) -> Figure:
    """Seed 000 figure 9: best fitness against evaluations, one line per tuning."""
    plt = _pyplot()
    figure, axes = plt.subplots(figsize=(9, 4.5))
    for directory in tunings:
        with (directory / "history.csv").open() as handle:
            rows = list(csv.DictReader(handle))
        axes.step([int(r["evaluations"]) for r in rows], [float(r["best_fitness"]) for r in rows],
                  where="post", marker="o", markersize=3, label=directory.name)
    axes.set(xlabel="fitness evaluations", ylabel="best fitness", yscale="log",
             title="Tuning convergence")
    axes.grid(alpha=0.3, which="both")
    axes.legend()
    return Figure("Tuning convergence", _save(figure, path))


def index_table(runs: list[Run], indices: list[dict]) -> tuple[list[str], list[list[str]]]:
    present = [c for c in INDEX_COLUMNS if any(c[0] in i for i in indices)]
    header = ["run"] + [heading for _, heading, _ in present] + ["skipped roles"]
    rows = []
    for run, values in zip(runs, indices):
        cells = [label(run)]
        for key, _, fmt in present:
            cells.append(fmt.format(values[key]) if key in values else "")
        cells.append(", ".join(values["skipped"]) or "-")
        rows.append(cells)
    return header, rows


def write_report(runs: list[Run], tunings: list[Path], out: Path) -> tuple[Path, Path]:
    out.mkdir(parents=True, exist_ok=True)
    indices = [run_indices(run) for run in runs]
    figures = plot_runs(runs, out) if runs else []
    if tunings:
        figures.append(plot_convergence(tunings, out / "convergence.png"))
    header, rows = index_table(runs, indices)
    notes = [f"{label(run)}: {note}" for run in runs for note in run.notes]
    markdown = ["# ATO run report", "", "Indices from the bags alone (e = target - true speed, "
                "trapezoidal integrals from t = 0).", ""]
    if rows:
        markdown += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        markdown += ["| " + " | ".join(row) + " |" for row in rows]
    markdown += [""] + [f"- {note}" for note in notes]
    for figure in figures:
        markdown += ["", f"## {figure.title}", "", f"![{figure.title}]({figure.path.name})"]
    (out / "indices.json").write_text(json.dumps(
        {label(run): values for run, values in zip(runs, indices)}, indent=2))
    md_path = out / "report.md"
    md_path.write_text("\n".join(markdown) + "\n")

    parts = ["<!doctype html><html><head><meta charset='utf-8'><title>ATO run report</title>",
             "<style>body{font-family:sans-serif;max-width:1000px;margin:auto}"
             "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:3px 6px;"
             "text-align:right}img{max-width:100%}</style></head><body><h1>ATO run report</h1>"]
    if rows:
        parts.append("<table><tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in header)
                     + "</tr>")
        parts += ["<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in row) + "</tr>"
                  for row in rows]
        parts.append("</table>")
    parts += [f"<p>{html.escape(note)}</p>" for note in notes]
    for figure in figures:
        data = base64.b64encode(figure.path.read_bytes()).decode()
        parts.append(f"<h2>{html.escape(figure.title)}</h2>"
                     f"<img alt='{html.escape(figure.title)}' src='data:image/png;base64,{data}'>")
    parts.append("</body></html>")
    html_path = out / "report.html"
    html_path.write_text("\n".join(parts))
    return md_path, html_path
