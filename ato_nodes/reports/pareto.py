"""A multi-objective tuning's figure (pareto.png): its front, the first two objectives
against each other (the three in 3-D beside them when there are three), the chosen member
marked, the least energy the train could run on (the dynamic programme's bound) where
energy is an objective, and the hypervolume after every generation against the
evaluations; and a comparison's attainment surfaces (attainment.png)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from ato_nodes.core.optimizers.pareto import MEDIAN_ATTAINMENT
from ato_nodes.reports.analysis import pyplot, save_figure
from ato_nodes.core.scoring.catalogue import OBJECTIVE_NAMES

ENERGY = OBJECTIVE_NAMES["energy"]  # the objective the least-energy programme bounds


def plot_pareto(front_file: Path, history_file: Path, path: Path) -> Path:
    front = json.loads(front_file.read_text())
    with history_file.open() as handle:
        history = list(csv.DictReader(handle))
    names = [objective["index"] for objective in front["objectives"]]
    rows, chosen = front["rows"], [row for row in front["rows"] if row["chosen"]]
    plt = pyplot()
    three = len(names) >= 3
    figure = plt.figure(figsize=(14 if three else 10, 4.5))
    panels = 3 if three else 2
    axes = figure.add_subplot(1, panels, 1)
    axes.scatter([row[names[0]] for row in rows], [row[names[1]] for row in rows], s=14,
                 label="front")
    axes.scatter([row[names[0]] for row in chosen], [row[names[1]] for row in chosen],
                 marker="*", s=160, color="C3", label=f"chosen ({front['chosen']['by']})")
    bound = front.get("energy_bound", {}).get(ENERGY)
    if bound is not None and ENERGY in names[:2]:
        line = axes.axvline if names[0] == ENERGY else axes.axhline
        line(bound, color="k", ls="--", lw=1.2, label=f"least energy, nominal train in "
             f"{front['energy_bound']['running_time']:g} s (DP)")
    axes.set(xlabel=names[0], ylabel=names[1], title=f"Front: {len(rows)} candidates")
    axes.grid(alpha=0.3)
    axes.legend()
    if three:
        cube = figure.add_subplot(1, panels, 2, projection="3d")
        cube.scatter(*([row[name] for row in rows] for name in names[:3]), s=10)
        cube.scatter(*([row[name] for row in chosen] for name in names[:3]), marker="*",
                     s=160, color="C3")
        cube.set(xlabel=names[0], ylabel=names[1], zlabel=names[2])
    volume = figure.add_subplot(1, panels, panels)
    volume.plot([int(row["evaluations"]) for row in history],
                [float(row["hypervolume"]) for row in history], marker="o", markersize=3)
    reference = ", ".join(f"{value:.4g}" for value in front["reference_point"])
    volume.set(xlabel="evaluations", ylabel="hypervolume",
               title=f"Hypervolume against ({reference})")
    volume.grid(alpha=0.3)
    return save_figure(figure, path)


def plot_attainment(surfaces: dict, names: tuple[str, ...], path: Path) -> Path:
    """attainment.png: each algorithm's attainment surfaces over its runs in two
    objectives (`surfaces`: algorithm -> percentile -> points, in the objectives' own
    units), the median solid, the best and the worst any and every run reached dotted."""
    plt = pyplot()
    figure, axes = plt.subplots(figsize=(8, 5))
    for colour, (algorithm, levels) in enumerate(surfaces.items()):
        for percentile, points in sorted(levels.items()):
            if not len(points):
                continue
            ordered = points[np.argsort(points[:, 0])]
            median = percentile == MEDIAN_ATTAINMENT
            axes.step(ordered[:, 0], ordered[:, 1], where="post", color=f"C{colour}",
                      lw=1.8 if median else 0.9, ls="-" if median else ":",
                      label=f"{algorithm} {percentile:g} %")
    axes.set(xlabel=names[0], ylabel=names[1],
             title="Attainment over the runs (at least the percentile of them reach it)")
    axes.grid(alpha=0.3)
    axes.legend(fontsize=8)
    return save_figure(figure, path)
