"""A league of controller kinds (scripts/league.py): every kind on the same scenario and
target, tuned with the same budget, algorithm, seed and objective (or with its given or
shipped gains), then run over the same real trains (robustness.py's draw: a train is its
study seed's and number's alone), set in one table and one figure.

Its output directory holds settings.json (the league's settings and a digest of the
conditions they were prepared under), each kind's tuning (tune-KIND, the tuner's own
directory) and trains (trains-KIND, robustness.py's samples.csv), each resumable, and
the table (league.md, league.json) and figure (league.png) made from them at the end.
Started again with the same settings it runs only what they lack; with others, or on a
directory that holds something else, it is refused before anything is written.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.components import CONTROLLERS
from ato_nodes.core.config.scenario import (apply_overrides, check_given_once, parse_override,
                                            prepare)
from ato_nodes.core.config.schema import SPEC_BY_NAME
from ato_nodes.core.scoring.catalogue import Requirement
from ato_nodes.results import jsontext
from ato_nodes.results.journeys import WORST_ARRIVAL, WORST_STOP
from ato_nodes.studies.backend import Backend, Progress
from ato_nodes.studies.directory import (check_same_settings, conditions_digest,
                                         create_and_hold, name_holder)
from ato_nodes.studies.robustness import COLUMNS, INDICES, RANGES, WITHIN, run_sample, summarise
from ato_nodes.studies.runner import short_value
from ato_nodes.studies.samples import SampleStudy
from ato_nodes.studies.tuning import (DEFAULT_ALGORITHM, PENALTY, Objective, SearchSpace, Tuner,
                                      TuningSettings)

ENERGY = "net_energy_kwh"  # a train's row holds it besides robustness.py's columns
TRAIN_COLUMNS = {**COLUMNS, ENERGY: float}
SETTINGS = "settings.json"
CELLS = (  # the table's index columns: (key, statistic) of a kind's trains
    ("max_abs_error_kmh", "median"), ("max_abs_error_kmh", "worst"),
    ("p95_abs_error_kmh", "median"), ("abs_stopping_error", "median"),
    ("abs_stopping_error", "worst"), ("max_jerk", "worst"), (WORST_STOP, "worst"),
    (WORST_ARRIVAL, "worst"), (ENERGY, "median"))
HEADINGS = {**dict(INDICES), ENERGY: "net energy kWh"}


def registered_kinds() -> tuple[str, ...]:
    """Every controller kind registered now (a plug-in's included): the default league."""
    return tuple(CONTROLLERS.components)


@dataclass(frozen=True)
class LeagueSettings:
    """What a league is: its scenario, kinds, budget, trains and objective (`describe()`,
    which its results depend on), and where its runs go (workers, cluster: not)."""
    scenario: str
    kinds: tuple[str, ...]
    tune: int = 0  # evaluations per kind; 0: each kind's given or shipped gains
    trains: int = 50
    seed: int = 1
    sets: tuple[str, ...] = ()
    algorithm: str = DEFAULT_ALGORITHM
    fitness: str = Objective.fitness
    requirements: tuple[str, ...] = ()  # INDEX<=VALUE texts
    workers: int = 1
    cluster: str = ""

    def describe(self) -> dict[str, Any]:
        return {"scenario": self.scenario, "kinds": list(self.kinds), "tune": self.tune,
                "trains": self.trains, "seed": self.seed, "set": list(self.sets),
                "ranges": RANGES, "algorithm": self.algorithm, "fitness": self.fitness,
                "requirements": list(self.requirements)}

    def objective(self) -> tuple[Requirement, ...]:
        return tuple(Requirement.parse(text) for text in self.requirements)


@dataclass
class Entry:
    """A kind's row: how its gains were chosen, its run's values, or why it cannot run."""
    kind: str
    gains: str  # "tuned N", "scenario's gains" or "shipped gains", then any given: "; NAME=VALUE"
    values: dict[str, Any] | None = None
    reason: str = ""  # one line, when values is None
    tuning: dict[str, Any] = field(default_factory=dict)  # the tuning's best, when tuned

    @property
    def label(self) -> str:
        return f"{self.kind} ({self.gains})"

    def cannot_run(self, reason: str) -> None:
        self.values, self.reason = None, " ".join(reason.split())


def check_kinds(kinds: Sequence[str]) -> None:
    """ScenarioError (one line) for a kind not registered, or named twice."""
    for kind in kinds:
        CONTROLLERS[kind]  # noqa: B018 (its error names the known kinds)
    twice = sorted({kind for kind in kinds if list(kinds).count(kind) > 1})
    if twice:
        raise ScenarioError(f"--kinds names {', '.join(twice)} more than once")


def split_sets(sets: Sequence[str], kinds: Sequence[str]) -> tuple[list[str], dict[str, dict]]:
    """(the --set texts every kind takes, kind -> the values of its own parameters given):
    a controller kind's parameter goes to the kinds of the league that have it, and is
    refused when none has it."""
    check_given_once(list(sets))
    owners: dict[str, list[str]] = {}
    for kind, component in CONTROLLERS.components.items():
        for spec in component.parameters:
            owners.setdefault(spec.name, []).append(kind)
    common, own = [], {kind: {} for kind in kinds}
    for text in sets:
        name, value = parse_override(text)
        if name == CONTROLLERS.kind_parameter.name:
            raise ScenarioError(f"--set {name}: the league's kinds are --kinds")
        if name not in owners:
            common.append(text)
            continue
        takers = [kind for kind in kinds if kind in owners[name]]
        if not takers:
            raise ScenarioError(f"--set {name} belongs to controller kind "
                                f"{', '.join(owners[name])}, not one of --kinds")
        for kind in takers:
            own[kind][name] = value
    return common, own


def prepare_entries(settings: LeagueSettings) -> tuple[dict[str, Any], list[Entry]]:
    """(the scenario's values with the common --set, each kind's entry): a kind the
    scenario refuses (a combination it cannot run) gets its reason; bad input raises
    ScenarioError."""
    check_kinds(settings.kinds)
    common, own = split_sets(settings.sets, settings.kinds)
    base = prepare(settings.scenario, common)
    return base, [kind_entry(base, kind, own[kind], settings.tune) for kind in settings.kinds]


def kind_entry(base: dict[str, Any], kind: str, given: dict[str, Any], tune: int) -> Entry:
    """The kind on the scenario with its given gains. To be tuned, the gains it tunes
    start at the shipped ones unless given (the scenario's own kind would otherwise
    start at gains tuned on this very scenario)."""
    ours = kind == base[CONTROLLERS.kind_parameter.name]
    gains = f"tuned {tune}" if tune else "scenario's gains" if ours else "shipped gains"
    if given:
        gains += "; " + ", ".join(f"{name}={short_value(name, value)}"
                                  for name, value in given.items())
    entry = Entry(kind, gains)
    overrides = {CONTROLLERS.kind_parameter.name: kind, **given}
    if tune:
        overrides.update({name: SPEC_BY_NAME[name].default
                          for name, _, _ in CONTROLLERS[kind].search_space if name not in given})
    try:
        entry.values = apply_overrides(base, overrides)
    except ScenarioError as exc:
        entry.cannot_run(str(exc).removeprefix("parameters: "))
    return entry


def empty_directory(path: Path) -> bool:
    try:
        return not any(path.iterdir())
    except OSError:  # a file, or a directory this process cannot read
        return False


class League:
    """A league's output directory, opened before anything runs: a new one, or one that
    holds a league of the same settings under the same conditions (continued); anything
    else is refused before anything is written. Held by this process while it lasts."""

    def __init__(self, out: Path, settings: LeagueSettings, base: dict[str, Any]):
        self.out, self.settings, self.started = out, settings, False
        described = settings.describe()
        self.described = jsontext.dumps(
            {**described, "conditions": conditions_digest(base, described)}, indent=2)
        settings_file = out / SETTINGS
        if out.exists() and not settings_file.exists() and not empty_directory(out):
            raise ScenarioError(f"{out} holds something other than a league; use a new --out")
        if settings_file.exists():
            check_same_settings(out, settings_file, self.described, "league",
                                "scenario, its files, --kinds, --tune, --trains, --seed, --set, "
                                "--algorithm, --fitness or --require", "use a new --out")
        self.lock = None

    def begin(self) -> None:
        """OUT made this league's: created if new, held, its settings written."""
        self.lock = create_and_hold(self.out, "league")
        name_holder(self.lock)
        (self.out / SETTINGS).write_text(self.described)
        self.started = True

    def tune(self, entry: Entry, show: bool) -> None:
        """The kind tuned in OUT/tune-KIND (continued there if begun), its values then
        the best candidate's; a kind with no default search space, or whose every
        candidate failed, cannot run."""
        if not CONTROLLERS[entry.kind].search_space:
            entry.cannot_run("it has no default search space (search_space) to tune")
            return
        s = self.settings
        tuning = TuningSettings(s.algorithm, s.scenario, SearchSpace.default(entry.values),
                                s.tune, s.seed, s.workers, True, s.fitness,
                                requirements=s.objective(), cluster=s.cluster)
        out = self.out / f"tune-{entry.kind}"
        tuner = Tuner(entry.values, tuning, out, resume=True, progress=show)
        if not tuner.finished:
            tuner.run()
        summary = json.loads((out / "summary.json").read_text())
        if summary["best_fitness"] >= PENALTY:
            entry.cannot_run(f"every one of its {summary['evaluations_used']} candidates "
                             f"failed ({summary['failed_evaluations']})")
            return
        entry.values = apply_overrides(entry.values, summary["best_params"])
        entry.tuning = {key: summary[key] for key in ("fitness", "best_fitness",
                        "best_is_feasible", "best_params", "best_at_bounds")}

    def run_trains(self, entries: Sequence[Entry]) -> dict[str, SampleStudy]:
        """Every kind that can run over the league's trains, each kind's rows streamed
        to OUT/trains-KIND/samples.csv; kind -> its study, every train in it."""
        s, runnable = self.settings, [entry for entry in entries if entry.values is not None]
        studies: dict[str, SampleStudy] = {}
        try:
            for entry in runnable:
                studies[entry.kind] = SampleStudy(
                    self.out / f"trains-{entry.kind}",
                    {**self.settings.describe(), "kind": entry.kind}, entry.values,
                    TRAIN_COLUMNS, s.trains, resume=True)
            with Backend(s.workers, s.cluster) as backend:
                for study in studies.values():
                    study.begin()
                progress = Progress(s.trains * len(studies),
                                    sum(len(study.file.done) for study in studies.values()),
                                    "trains")
                tasks = (((entry.kind, number), (entry.values, RANGES, s.seed, number, (ENERGY,)))
                         for entry in runnable for number in studies[entry.kind].missing())
                try:
                    for (kind, _), row in backend.stream(run_sample, tasks):
                        studies[kind].file.append(row)
                        progress.advance()
                finally:
                    progress.end()
        finally:
            for study in studies.values():
                study.close()
        return studies


def table(entries: Sequence[Entry], studies: dict[str, SampleStudy]) -> list[dict[str, Any]]:
    """Each kind's row: its trains' counts within robustness.py's bounds, the median and
    worst of its indices, its tuning's best; or why it cannot run."""
    rows = []
    for entry in entries:
        row = {"label": entry.label, "kind": entry.kind, "gains": entry.gains}
        if entry.values is None:
            rows.append({**row, "cannot_run": entry.reason})
            continue
        values, present = studies[entry.kind].file.table()
        columns = list(studies[entry.kind].file.columns)
        summary, within = summarise(values, present, columns)
        energy = values[present[:, columns.index(ENERGY)], columns.index(ENERGY)]
        if energy.size:
            summary[ENERGY] = {"median": float(np.median(energy)), "worst": float(energy.max())}
        rows.append({**row, "trains": len(values), "within": within, "summary": summary,
                     **({"tuning": entry.tuning} if entry.tuning else {})})
    return rows


def markdown(rows: Sequence[dict[str, Any]]) -> str:
    """The league as a Markdown table: a row per kind, a kind that cannot run saying why
    in its first cell; a tuned kind's best fitness (on the scenario's own train) last."""
    ran = [row for row in rows if "summary" in row]
    counts = [text for _, _, text in WITHIN if any(text in row["within"] for row in ran)]
    cells = [(key, stat) for key, stat in CELLS if any(key in row["summary"] for row in ran)]
    tuned = next((row["tuning"]["fitness"] for row in ran if "tuning" in row), None)
    headings = ["controller", *counts, *(f"{HEADINGS[key]} {stat}" for key, stat in cells),
                *([f"tuning's best {tuned}"] if tuned else [])]
    lines = ["| " + " | ".join(headings) + " |", "|---" * len(headings) + "|"]
    for row in rows:
        if "summary" not in row:
            texts = [f"cannot run: {row['cannot_run']}"] + [""] * (len(headings) - 2)
        else:
            texts = [f"{row['within'][text]} of {row['trains']}" if text in row["within"]
                     else "-" for text in counts]
            texts += [f"{row['summary'][key][stat]:.4g}" if key in row["summary"] else "-"
                      for key, stat in cells]
            texts += [tuning_text(row.get("tuning"))] if tuned else []
        lines.append("| " + " | ".join([row["label"], *texts]).replace("\n", " ") + " |")
    return "\n".join(lines)


def tuning_text(tuning: dict[str, Any] | None) -> str:
    """A tuned kind's best fitness on the scenario's own train, or that it missed the
    requirements."""
    if tuning is None:
        return "-"
    return f"{tuning['best_fitness']:.4g}" if tuning["best_is_feasible"] else "infeasible"


def plot(entries: Sequence[Entry], studies: dict[str, SampleStudy], path: Path,
         scenario: str) -> None:
    """league.png: each kind's trains, one point a train, max abs(e) and the stop error
    (a journey's worst stop) against robustness.py's bounds, beside the table."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    ran = [entry for entry in entries if entry.kind in studies]
    figure, axes = plt.subplots(1, 2, figsize=(12, 0.5 * max(len(ran), 4) + 1.5), sharey=True)
    for axis, (keys, bound) in zip(axes, ((("max_abs_error_kmh",), 1.0),
                                          ((WORST_STOP, "abs_stopping_error"), 0.1)), strict=True):
        axis.axvline(bound, color="0.5", ls="--", lw=1)  # robustness.py's bound (WITHIN)
        for place, entry in enumerate(ran):
            values, present = studies[entry.kind].file.table()
            columns = list(studies[entry.kind].file.columns)
            key = next((key for key in keys if present[:, columns.index(key)].any()), None)
            if key is None:
                continue
            column = values[present[:, columns.index(key)], columns.index(key)]
            axis.plot(column, place + np.linspace(-0.2, 0.2, column.size), "o", ms=3)
            axis.set_xlabel(HEADINGS[key])
        axis.set_xscale("log")  # the kinds' errors differ by orders of magnitude
        axis.grid(alpha=0.3)
    axes[0].set_yticks(range(len(ran)), [entry.label for entry in ran])
    axes[0].invert_yaxis()  # the table's order, top down
    figure.suptitle(f"{scenario}: each kind over the same real trains")
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def write_report(out: Path, settings: LeagueSettings, entries: Sequence[Entry],
                 studies: dict[str, SampleStudy]) -> str:
    """league.md, league.json and league.png in OUT; the table's Markdown."""
    rows = table(entries, studies)
    text = markdown(rows)
    (out / "league.md").write_text(text + "\n")
    (out / "league.json").write_text(jsontext.dumps(
        {**settings.describe(), "rows": rows}, indent=2))
    plot(entries, studies, out / "league.png", settings.scenario)
    return text
