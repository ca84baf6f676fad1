"""Tuning for several objectives at once (tune.py --objectives): the same candidates, log,
resume and evaluators (in-process, through the stack, on a Dask cluster) as a
single-objective tuning (studies/tuning.py), pymoo's NSGA-II or NSGA-III asking a
generation at a time (core/optimizers/pareto.py), the requirements as hard constraints.

Outputs in OUT beside evaluations.jsonl and tuning.json: front.csv and front.json (every
feasible non-dominated candidate, its row id the evaluation's index, its parameters and
objectives as measured and scaled; front.parquet too where pandas and pyarrow are, the
`tables` extra), hypervolume.csv (after every generation, against
the stated reference point), pareto.png, best.yaml (the chosen member: the knee, or
the one nearest --weights) and summary.json (last: the tuning finished).
"""

from __future__ import annotations

import csv
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import apply_overrides
from ato_nodes.core.optimizers.pareto import (DEFAULT_POPULATION, hypervolume, knee,
                                              minimize_pareto, nondominated,
                                              pseudo_weight_choice, scaled, span)
from ato_nodes.reports.pareto import ENERGY, plot_pareto
from ato_nodes.results import jsontext
from ato_nodes.studies.backend import ClusterLost
from ato_nodes.studies.energy_optimum import least_energy_of_run
from ato_nodes.studies.tuning import Evaluation, Objectives, Tuner, TuningLost

REFERENCE_MARGIN = 0.1  # the default reference point: the front's nadir + this of its span


@dataclass(frozen=True)
class Choice:
    """How the front's member written to best.yaml is chosen: the knee, or the member
    whose pseudo-weights are nearest `weights` (one per objective); and the reference
    point of the hypervolume (None: the front's nadir plus REFERENCE_MARGIN of its
    span), as measured (a maximised objective's too)."""

    weights: tuple[float, ...] | None = None
    reference: tuple[float, ...] | None = None

    @classmethod
    def parse(cls, weights: str | None, reference: str | None, objectives: int) -> Choice:
        return cls(_numbers(weights, "--weights", objectives, positive=True),
                   _numbers(reference, "--reference", objectives))


def _numbers(text: str | None, option: str, count: int, positive: bool = False
             ) -> tuple[float, ...] | None:
    if text is None:
        return None
    try:
        values = tuple(float(item) for item in text.split(","))
    except ValueError:
        raise ScenarioError(f"{option} expects {count} numbers separated by commas, got "
                            f"{text!r}") from None
    if len(values) != count or not all(np.isfinite(values)) or (
            positive and (min(values) < 0.0 or sum(values) <= 0.0)):
        raise ScenarioError(f"{option} expects {count} finite numbers (one per objective"
                            f"{', not negative, not all zero' if positive else ''}), got {text!r}")
    return values


class ParetoTuner(Tuner):
    """A Tuner whose settings name several objectives; run() returns the ParetoResult and
    writes the front."""

    def __init__(self, values: dict[str, Any], settings, out: Path, choice: Choice = Choice(),
                 **options):
        self.choice = choice
        super().__init__(values, settings, out, **options)

    @property
    def objectives(self) -> Objectives:
        return self.settings.objective

    def _plan(self, own_evaluator: bool) -> None:
        self.population = self.settings.options.get("population_size", DEFAULT_POPULATION)
        # a front has no one bound to prune against; a requirement broken for good has
        self.prune = own_evaluator and self.objectives.pruning() is not None
        self.initial_evaluations = self.evaluations_per_iteration = self.population

    def _standing(self) -> str:
        return f"feasible {sum(r.status == 'ok' for r in self.log.done.values())}"

    def run(self):
        s = self.settings
        objectives = self.objectives
        if self.in_process_pool:
            self._warm_kernels()
        self.paced = time.monotonic()

        def evaluate(population: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            vectors = [objectives.vector(record)
                       for record in self._batch(backend, population)]
            return np.array([f for f, _ in vectors]), np.array([g for _, g in vectors])

        try:
            with self._backend() as backend:
                result = minimize_pareto(
                    s.algorithm, evaluate, s.space.lower, s.space.upper, s.evaluations,
                    s.seed, objectives=len(objectives.objectives),
                    constraints=len(objectives.requirements) + 1,
                    x0=s.space.start(self.values), population_size=self.population)
        except ClusterLost as exc:
            raise TuningLost(f"{exc} mid-tuning; every finished evaluation is in "
                             f"{self.log.path}; continue with --resume") from None
        self._write_front(result)
        return result

    def _write_front(self, result) -> None:
        s, objectives = self.settings, self.objectives
        indices = objectives.indices
        sense = objectives.senses
        records = [self.log.done[index] for index in range(len(result.X))]
        feasible = np.flatnonzero(result.feasible)
        on_front = feasible[nondominated(result.F[feasible])]
        front = result.F[on_front]
        summary: dict[str, Any] = {**s.describe(), "evaluations_used": len(result.X),
                                   "generations": int(result.generation[-1]) + 1,
                                   "feasible_evaluations": len(feasible),
                                   "front_size": len(on_front)}
        rows: list[dict[str, Any]] = []
        if len(on_front):
            ideal, nadir = span(front)
            reference = (np.array(self.choice.reference) * sense if self.choice.reference
                         else nadir + REFERENCE_MARGIN * np.where(nadir > ideal, nadir - ideal,
                                                                  np.abs(nadir) + 1.0))
            chosen = (pseudo_weight_choice(front, np.array(self.choice.weights))
                      if self.choice.weights else knee(front))
            unit = scaled(front, ideal, nadir)
            order = np.lexsort(front.T[::-1])
            rows = [self._row(records[on_front[k]], result.generation[on_front[k]], indices,
                              unit[k], k == chosen) for k in order]
            best = records[on_front[chosen]]
            summary.update(self._front_summary(front, reference, best))
            if ENERGY in indices:
                summary["energy_bound"] = self._energy_bound()
            history = self._hypervolume_history(result, reference)
        else:
            history, best = [], None
        self._write_members([records[k] for k in on_front], best, len(result.X))
        self._write_tables(rows, history, summary)
        if rows:
            plot_pareto(self.out / "front.json", self.out / "hypervolume.csv",
                        self.out / "pareto.png")
        summary["wall_time"] = time.monotonic() - self.started
        summary["conditions"] = self.conditions
        (self.out / "summary.json").write_text(jsontext.dumps(summary, indent=2))

    def _write_members(self, members: list[Evaluation], best: Evaluation | None,
                       evaluations: int) -> None:
        """Each member of the front as a scenario run_stack.py accepts, front/row-N.yaml
        (N its row id), and the chosen one as best.yaml; none of them without a front."""
        s = self.settings
        folder = self.out / "front"
        shutil.rmtree(folder, ignore_errors=True)
        (self.out / "best.yaml").unlink(missing_ok=True)
        if best is not None:
            folder.mkdir()
        how = "pseudo-weights" if self.choice.weights else "knee"
        for member in members:
            chosen = member is best
            text = (f"Row {member.index} of the front{f' (chosen: {how})' if chosen else ''} "
                    f"of a {s.algorithm} tuning (seed {s.seed}, {evaluations} evaluations) on "
                    f"{s.scenario}, {time.strftime('%Y-%m-%d')}: "
                    + ", ".join(f"{index} = {member.indices[index]:.6g}"
                                for index in self.objectives.indices)
                    + "".join(f", {r.name}<={r.limit:g}" for r in s.requirements) + ".")
            values = apply_overrides(self.values, member.params)
            target = folder / f"row-{member.index:05d}.yaml"
            target.write_text(self.scenario_text(text, member.params, values, target))
            if chosen:
                (self.out / "best.yaml").write_text(self.scenario_text(
                    text, member.params, values, self.out / "best.yaml"))

    def _energy_bound(self) -> dict[str, Any]:
        """The least traction energy of the scenario's run on its nominal train in its
        planned time (studies/energy_optimum.py's programme): no candidate can beat it on
        that train; or why there is none (no stop, no planned time)."""
        try:
            energy, running_time = least_energy_of_run(self.values)
        except (ScenarioError, ValueError) as exc:
            return {"error": str(exc)}
        return {ENERGY: energy, "running_time": running_time, "train": "nominal"}

    def _front_summary(self, front: np.ndarray, reference: np.ndarray, best: Evaluation
                       ) -> dict[str, Any]:
        """The objectives with their sense and span on the front, the reference point and
        hypervolume, and the chosen member, each objective as measured."""
        objectives = self.objectives
        sense = objectives.senses
        ideal, nadir = span(front)
        return {
            "objectives": [{"name": name, "index": index, "sense": "max" if sign < 0
                            else "min", "ideal": float(low * sign), "nadir": float(high * sign)}
                           for name, index, sign, low, high in zip(
                               objectives.objectives, objectives.indices, sense, ideal, nadir,
                               strict=True)],
            "reference_point": (reference * sense).tolist(),
            "hypervolume": hypervolume(front, reference),
            "chosen": {"row": best.index, "by": "pseudo-weights" if self.choice.weights
                       else "knee", "weights": list(self.choice.weights or ()),
                       "params": best.params,
                       "objectives": {index: best.indices[index] for index in
                                      objectives.indices}}}

    def _row(self, record: Evaluation, generation: int, indices: tuple[str, ...],
             unit: np.ndarray, chosen: bool) -> dict[str, Any]:
        return {"row": record.index, "generation": int(generation), **record.params,
                **{index: record.indices[index] for index in indices},
                **{f"scaled_{index}": float(value) for index, value in zip(indices, unit,
                                                                              strict=True)},
                "chosen": chosen, "scenario": f"front/row-{record.index:05d}.yaml"}

    def _hypervolume_history(self, result, reference: np.ndarray) -> list[dict[str, Any]]:
        """After every generation, the hypervolume of the feasible front found so far."""
        history = []
        for generation in range(int(result.generation[-1]) + 1):
            seen = result.generation <= generation
            F = result.F[seen & result.feasible]
            front = F[nondominated(F)]
            history.append({"generation": generation, "evaluations": int(np.sum(seen)),
                            "front_size": len(front),
                            "hypervolume": hypervolume(front, reference)})
        return history

    def _write_tables(self, rows, history, summary) -> None:
        for name, table in (("front.csv", rows), ("hypervolume.csv", history)):
            with (self.out / name).open("w", newline="") as handle:
                if table:
                    writer = csv.DictWriter(handle, fieldnames=list(table[0]))
                    writer.writeheader()
                    writer.writerows({key: repr(value) if isinstance(value, float) else value
                                      for key, value in row.items()} for row in table)
        write_parquet(rows, self.out / "front.parquet")
        (self.out / "front.json").write_text(jsontext.dumps(
            {key: summary[key] for key in ("objectives", "reference_point", "hypervolume",
                                           "chosen", "energy_bound") if key in summary}
            | {"rows": rows, "hypervolume_history": history}, indent=2))


def write_parquet(rows: list[dict], path: Path) -> None:
    """`rows` as a Parquet table at `path` where pandas and pyarrow are installed (the
    `tables` extra); nothing where they are not."""
    try:
        import pandas
        import pyarrow  # noqa: F401  (pandas' Parquet engine: its absence is the answer)
    except ImportError:
        return
    pandas.DataFrame(rows).to_parquet(path, index=False)
