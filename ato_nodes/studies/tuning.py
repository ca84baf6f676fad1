"""Tuning controller parameters with the swarm optimizers.

Every candidate is a set of parameter overrides. In stack mode it is run by
relaunching the whole node graph (ato_nodes.launcher.launch.Stack) in a ROS domain of
its own and scored from its bag; in in-process mode by the same core code in
a worker process. A candidate that crashes, hangs, diverges or is invalid gets
PENALTY and is logged; tuning goes on. Every evaluation is appended to
evaluations.jsonl as it finishes, so an interrupted run loses nothing, and
--resume replays the optimizer (deterministic for a given seed and fitness
values) against the log, running only what the log lacks.
"""

from __future__ import annotations

import csv
import functools
import importlib.util
import json
import math
import os
import shlex
import shutil
import sys
import tempfile
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np
import yaml

from ato_nodes.results import jsontext
from ato_nodes.studies.backend import Backend, ClusterLost, check_cluster, show_progress
from ato_nodes.studies.train_spread import TrainSpread, evaluate_over_trains
from ato_nodes.studies.directory import (check_same_settings, conditions_digest, hold_directory,
                                         name_holder)
from ato_nodes.reports.analysis import plot_convergence
from ato_nodes.core.base import kernels
from ato_nodes.core.run.loop import simulate, warm
from ato_nodes.core.optimizers import ALGORITHMS, Result, create, optimize
from ato_nodes.core.optimizers.pareto import PARETO_ALGORITHMS
from ato_nodes.core.config.components import CONTROLLERS
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.scoring.indices import RunningIndex
from ato_nodes.core.base.paths import config_dir
from ato_nodes.core.base.units import MS_TO_KMH
from ato_nodes.core.config.scenario import (apply_overrides, check_used, load_scenario,
                                            resolve_scenario, ros_parameter_file)
from ato_nodes.core.config.schema import SPEC_BY_NAME
from ato_nodes.core.run.last_stop import planned_steps
from ato_nodes.core.scoring.catalogue import FITNESS, MAXIMISED, Requirement, objective_index
from ato_nodes.results.journeys import score_with_journey

DEFAULT_ALGORITHM = "bas-pso"  # tune.py's, and the league's for every kind
PENALTY = 1e12  # fitness of a candidate that failed, diverged or timed out


@dataclass(frozen=True)
class SearchSpace:
    """The tuned parameters and their bounds."""

    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    # an external node's own parameters (not the schema's): their values as it declares
    # them, the starting region (docs/external-nodes.md)
    node_values: dict[str, float] = field(default_factory=dict)

    @classmethod
    def parse(cls, items: list[str], values: dict[str, Any] | None = None) -> SearchSpace:
        """`name=low:high` items (or comma-separated lists of them); with the run's
        `values`, a parameter of a controller or profile kind the run does not use is
        refused (tuning it would change nothing)."""
        names, lower, upper = [], [], []
        for item in (part.strip() for text in items for part in text.split(",")):
            if not item:
                continue
            name, sep, bounds = item.partition("=")
            low, colon, high = bounds.partition(":")
            spec = SPEC_BY_NAME.get(name.strip())
            if not sep or not colon:
                raise ScenarioError(f"--params expects name=low:high, got {item!r}")
            if spec is None or spec.value_type not in (int, float):
                raise ScenarioError(f"--params: {name.strip()!r} is not a numeric parameter")
            try:
                low_value, high_value = float(low), float(high)
            except ValueError:
                raise ScenarioError(f"--params: bounds of {spec.name} must be numbers") from None
            if not low_value < high_value:
                raise ScenarioError(f"--params: {spec.name} needs low < high")
            for value in (low_value, high_value):
                spec.check(spec.value_type(value), "--params")
            if spec.name in names:
                raise ScenarioError(f"--params: {spec.name} is given twice")
            if values is not None:
                check_used([spec.name], values, "--params")
            names.append(spec.name)
            lower.append(low_value)
            upper.append(high_value)
        if not names:
            raise ScenarioError("--params names no parameter to tune")
        return cls(tuple(names), np.array(lower), np.array(upper))

    @classmethod
    def default(cls, values: dict[str, Any]) -> SearchSpace:
        """The run's controller kind's default search space (its registry entry)."""
        component = CONTROLLERS.chosen(values)
        if not component.search_space:
            raise ScenarioError(f"controller.kind {component.kind} has no default search "
                                f"space; give --params")
        return cls.parse([f"{n}={lo!r}:{hi!r}" for n, lo, hi in component.search_space], values)

    @classmethod
    def of_node(cls, declared: dict[str, tuple[float, float, float]],
                items: list[str] | None = None) -> SearchSpace:
        """An external node's own parameters, `declared` {name: (low, high, value)} from
        its parameter descriptors (FloatingPointRange); `items` (name=low:high) choose some
        and narrow their boxes, inside the declared ranges."""
        if not declared:
            raise ScenarioError("the external node declares no parameter with a "
                                "FloatingPointRange to tune")
        chosen: dict[str, tuple[float, float]] = {}
        for item in (part.strip() for text in items or [] for part in text.split(",")):
            name, _, bounds = item.partition("=")
            low, colon, high = bounds.partition(":")
            if name not in declared or not colon:
                raise ScenarioError(f"--params: {item!r} is not name=low:high of a parameter "
                                    f"the external node declares ({', '.join(declared)})")
            box = (float(low), float(high))
            if not declared[name][0] <= box[0] < box[1] <= declared[name][1]:
                raise ScenarioError(f"--params: {name} needs low < high within its declared "
                                    f"range {declared[name][0]:g}:{declared[name][1]:g}")
            chosen[name] = box
        boxes = chosen or {name: (low, high) for name, (low, high, _) in declared.items()}
        return cls(tuple(boxes), np.array([low for low, _ in boxes.values()]),
                   np.array([high for _, high in boxes.values()]),
                   {name: declared[name][2] for name in boxes})

    def describe(self) -> str:
        return ", ".join(f"{n}={lo:g}:{hi:g}" for n, lo, hi in zip(self.names, self.lower,
                                                                   self.upper, strict=True))

    def overrides(self, x: np.ndarray) -> dict[str, Any]:
        return {name: (int(round(value)) if name in SPEC_BY_NAME and
                       SPEC_BY_NAME[name].value_type is int else float(value))
                for name, value in zip(self.names, x, strict=True)}

    def start(self, values: dict[str, Any]) -> np.ndarray:
        """The scenario's own values (an external node's: its own), clipped into the box:
        the starting region."""
        return np.clip([float(self.node_values.get(name, values.get(name, 0.0)))
                        for name in self.names], self.lower, self.upper)


@dataclass
class Evaluation:
    index: int
    params: dict[str, Any]
    fitness: float
    status: str                 # ok, infeasible, diverged, failed, timeout, invalid
    wall_time: float
    indices: dict[str, Any] = field(default_factory=dict)
    message: str = ""
    conditions: str = ""        # what makes the fitness mean what it means (see conditions())


INFEASIBLE = 1e9  # base fitness of a run that breaks a requirement (below PENALTY)
PRUNE_MARGIN = 1e-9  # relative: a pruned run's value is above its bound by more than this


@dataclass(frozen=True)
class Objective:
    """The fitness index to minimise and the requirements a candidate must meet.
    Infeasible candidates rank after every feasible one, by how far they miss."""

    fitness: str = "itae"
    requirements: tuple[Requirement, ...] = ()

    @property
    def indices(self) -> tuple[str, ...]:
        """The indices it judges a run by."""
        return (FITNESS[self.fitness],)

    def pruned_by(self, bound: float) -> tuple[str, float] | None:
        """(the running index followed, the value past which the run ends) when a run
        is pruned against `bound` (the optimizer's), else None (prune_limit)."""
        limit = prune_limit(self, bound)
        return None if limit is None else (FITNESS[self.fitness], limit)

    @property
    def prunable(self) -> bool:
        """The fitness only grows along a run (ITAE, IAE, max abs(e)), so a partial run
        bounds it from below."""
        return FITNESS[self.fitness] in RunningIndex.MONOTONE

    def score(self, indices: dict[str, Any]) -> tuple[float, str, str]:
        """(fitness, status, message) of a completed run."""
        value = indices.get(FITNESS[self.fitness], math.nan)
        if not math.isfinite(value):
            return PENALTY, "diverged", f"{self.fitness} is not finite"
        broken = [(r, r.violation(indices)) for r in self.requirements]
        broken = [(r, v) for r, v in broken if v > 0.0]
        if not broken:
            return float(value), "ok", ""
        message = "; ".join(f"{r.name} {indices.get(r.name, math.nan):.4g} > {r.limit:g}"
                            for r, _ in broken)
        miss = min(sum(v for _, v in broken), 1e5)  # stays below PENALTY: still a run
        return INFEASIBLE + 1e6 * miss, "infeasible", message


@dataclass(frozen=True)
class Objectives(Objective):
    """Several objectives at once (tune.py --objectives), each an index of the catalogue
    minimised, or maximised when more of it is better (catalogue.MAXIMISED), and the
    requirements as hard constraints. A run's fitness in the log is its first objective.
    With `prune`, a run is ended once it has broken for good a requirement on an index a
    run follows step by step (PRUNABLE_REQUIREMENTS): it is infeasible whatever else it
    does, and enters with a lower bound on its violation (vector)."""

    objectives: tuple[str, ...] = ()  # as given: names or catalogue.OBJECTIVE_NAMES' short
    prune: bool = False

    def pruning(self) -> tuple[Requirement, str, float] | None:
        """The requirement a run is pruned on (the first on a running index), the running
        index and its scale (the requirement's units per the running index's)."""
        for requirement in self.requirements if self.prune else ():
            if requirement.name in PRUNABLE_REQUIREMENTS:
                return (requirement, *PRUNABLE_REQUIREMENTS[requirement.name])
        return None

    def pruned_by(self, bound: float) -> tuple[str, float] | None:
        pruning = self.pruning()
        if pruning is None:
            return None
        requirement, running, scale = pruning
        return running, requirement.limit / scale * (1.0 + PRUNE_MARGIN)

    @property
    def indices(self) -> tuple[str, ...]:
        return tuple(objective_index(name) for name in self.objectives)

    @property
    def senses(self) -> np.ndarray:
        """+1 for each objective minimised, -1 for each maximised: the minimised form."""
        return np.array([-1.0 if name in MAXIMISED else 1.0 for name in self.indices])

    @property
    def prunable(self) -> bool:
        return False

    def score(self, indices: dict[str, Any]) -> tuple[float, str, str]:
        missing = [name for name in self.indices if not math.isfinite(
            indices.get(name, math.nan))]
        if missing:
            return PENALTY, "diverged", f"{', '.join(missing)} not finite"
        broken = [r for r in self.requirements if r.violation(indices) > 0.0]
        message = "; ".join(f"{r.name} {indices.get(r.name, math.nan):.4g} > {r.limit:g}"
                            for r in broken)
        return float(indices[self.indices[0]]), "infeasible" if broken else "ok", message

    def vector(self, record: Evaluation) -> tuple[np.ndarray, np.ndarray]:
        """(F, G) of an evaluation for the optimizer: F every objective minimised (a
        maximised one negated), G each requirement's signed violation (relative to
        max(|limit|, 1): <= 0 met) and last whether the run completed (<= 0: it did). A
        run that failed has every G at FAILED_VIOLATION and F at PENALTY."""
        if record.status == "pruned":  # broken for good: its violation so far, the rest 0
            requirement, _, scale = self.pruning()
            reached = requirement.signed_violation({requirement.name: record.fitness * scale})
            return (np.full(len(self.objectives), PENALTY),
                    np.array([reached if r is requirement else 0.0 for r in self.requirements]
                             + [0.0]))
        if record.status not in ("ok", "infeasible"):
            return (np.full(len(self.objectives), PENALTY),
                    np.full(len(self.requirements) + 1, FAILED_VIOLATION))
        F = self.senses * np.array([record.indices[name] for name in self.indices], dtype=float)
        G = [r.signed_violation(record.indices) for r in self.requirements]
        return F, np.array([*G, -1.0])


@dataclass(frozen=True)
class WeightedSum(Objectives):
    """Several objectives as one fitness for a swarm optimizer: sum of weight x objective
    (a maximised one negated); the requirements as for one objective (an infeasible run
    ranks after every feasible one, by how far it misses). Not pruned: a pruned run's
    value would be a requirement's, not the sum's."""

    weights: tuple[float, ...] = ()

    def pruned_by(self, bound: float) -> tuple[str, float] | None:
        return None

    def score(self, indices: dict[str, Any]) -> tuple[float, str, str]:
        first, status, message = super().score(indices)
        if status == "diverged":
            return first, status, message
        total = float(sum(weight * sense * indices[name] for weight, sense, name in zip(
            self.weights, self.senses, self.indices, strict=True)))
        if status == "ok":
            return total, status, message
        miss = min(sum(r.violation(indices) for r in self.requirements), 1e5)
        return INFEASIBLE + 1e6 * miss, status, message


FAILED_VIOLATION = 1e3  # a failed run's every constraint: more than any run that ended
# Requirements a run can be pruned on: index -> (the running index that follows it step by
# step, core/scoring/indices.RunningIndex, and its units per the running index's)
PRUNABLE_REQUIREMENTS = {"itae": ("itae", 1.0), "iae": ("iae", 1.0),
                         "max_abs_error": ("max_abs_error", 1.0),
                         "max_abs_error_kmh": ("max_abs_error", MS_TO_KMH)}


def objective_of(objective: Objective | str) -> Objective:
    return objective if isinstance(objective, Objective) else Objective(objective)


def prune_limit(objective: Objective, bound: float) -> float | None:
    """The running fitness past which a candidate with this bound is pruned, or None: only
    a fitness that only grows, and only below INFEASIBLE (any infeasible run ends above
    it); the margin covers the rounding of a step-by-step sum."""
    if objective.prunable and 0.0 < bound < INFEASIBLE:
        return bound * (1.0 + PRUNE_MARGIN)
    return None


@dataclass(frozen=True)
class Candidate:
    """A candidate ready to run, as both evaluators start it."""

    values: dict[str, Any]  # the base run's values with the candidate's overrides
    objective: Objective
    limit: float | None     # past this the run ends (pruned); None: it is not pruned
    started: float          # time.perf_counter() as its evaluation began
    running: str | None     # the running index followed (RunningIndex)

    def elapsed(self) -> float:
        return time.perf_counter() - self.started


def _candidate(values: dict[str, Any], overrides: dict[str, Any], objective: Objective | str,
               index: int, bound: float) -> Candidate | Evaluation:
    """The candidate to run, or its `invalid` Evaluation when the run refuses the
    overrides."""
    started = time.perf_counter()
    objective = objective_of(objective)
    try:
        run_values = apply_overrides(values, overrides)
    except ScenarioError as exc:
        return Evaluation(index, overrides, PENALTY, "invalid", 0.0, message=str(exc))
    running, limit = objective.pruned_by(bound) or (None, None)
    return Candidate(run_values, objective, limit, started, running)


def evaluate_in_process(values: dict[str, Any], overrides: dict[str, Any],
                        objective: Objective | str, index: int, bound: float = math.inf,
                        timeout: float | None = None) -> Evaluation:
    """One candidate with the core code in this process (a worker of the pool); past
    `timeout` wall seconds it ends as a timeout, as a stack candidate does. With a
    finite `bound` (pruning: the optimizer does not care by how much a candidate
    misses it) a run whose fitness, which only grows, has passed the bound ends
    there as `pruned`, its fitness the value reached (a lower bound)."""
    candidate = _candidate(values, overrides, objective, index, bound)
    if isinstance(candidate, Evaluation):
        return candidate
    run_values, limit = candidate.values, candidate.limit
    running = RunningIndex(candidate.running) if limit is not None else None
    try:
        series = simulate(run_values, None if timeout is None else time.monotonic() + timeout,
                          (running, limit) if running is not None else None)
    except TimeoutError as exc:
        return Evaluation(index, overrides, PENALTY, "timeout", candidate.elapsed(),
                          message=f"{exc} ({timeout:g} s)")
    if limit is not None and running.value > limit:
        return Evaluation(index, overrides, running.value, "pruned", candidate.elapsed(),
                          message=f"{candidate.running} passed {limit:.9g} at t = "
                                  f"{series['t'][-1]:g} s")
    indices = tuning_indices(series, run_values)
    elapsed = candidate.elapsed()
    # ended before the step it was to end at (run.duration's, or a journey's at its last
    # stop): it diverged
    diverged = len(series["t"]) < planned_steps(run_values, series["position"],
                                                series["speed"])
    if diverged or not indices["finite"]:
        return Evaluation(index, overrides, PENALTY, "diverged", elapsed, indices)
    value, status, message = candidate.objective.score(indices)
    return Evaluation(index, overrides, value, status, elapsed, indices, message)


def evaluate_in_stack(values: dict[str, Any], overrides: dict[str, Any],
                      objective: Objective | str, index: int, bag: Path,
                      timeout: float, cancel: threading.Event | None = None,
                      bound: float = math.inf, external: tuple[str, ...] = ()) -> Evaluation:
    """One candidate through the real node graph, scored from its bag. With a finite
    `bound` (see evaluate_in_process) the supervisor follows the running fitness and
    ends a run that passes it: `pruned`, with the value it reached. With an `external`
    controller's command, the overrides are that node's own parameters (SearchSpace.of_node:
    none the run's controller declares), given to it as `--ros-args -p NAME:=VALUE`."""
    from ato_nodes.bags.bagio import BagError, read_parameters, read_series
    from ato_nodes.launcher.launch import Stack

    candidate = _candidate(values, {} if external else overrides, objective, index, bound)
    if isinstance(candidate, Evaluation):
        candidate.params = overrides
        return candidate
    run_values = candidate.values
    if candidate.limit is not None:
        run_values = {**run_values, "supervisor.fitness": candidate.running,
                      "supervisor.prune_above": candidate.limit}
    nodes = {"controller": node_command(external, overrides)} if external else None
    outcome = Stack(run_values, bag, quiet=True, timeout=timeout, cancel=cancel,
                    external=nodes).run()
    if outcome.status == "pruned":
        return Evaluation(index, overrides, outcome.report["fitness"], "pruned",
                          candidate.elapsed(), message=outcome.message)
    indices = {}
    if bag.exists():
        try:
            indices = tuning_indices(read_series(bag), read_parameters(bag))
        except BagError as exc:
            outcome.message += f"; {exc}"
    elapsed = candidate.elapsed()
    if outcome.status != "completed" or not indices:
        status = outcome.status if outcome.status != "completed" else "failed"
        return Evaluation(index, overrides, PENALTY, status, elapsed, indices, outcome.message)
    value, status, message = candidate.objective.score(indices)
    return Evaluation(index, overrides, value, status, elapsed, indices, message)


def tuning_indices(series: dict[str, np.ndarray], values: dict[str, Any]) -> dict[str, Any]:
    """A candidate's indices: the run's, and a journey's worst station
    (catalogue.JOURNEY_INDICES), without its per-station record (a line of the log a
    candidate)."""
    indices = score_with_journey(values, series)
    indices.pop("journey", None)
    return indices


def node_command(external: tuple[str, ...], overrides: dict[str, Any]) -> list[str]:
    """An external node's command with its own parameters' values (a candidate's
    overrides: SearchSpace.of_node's) as ROS arguments."""
    own = [item for name, value in overrides.items()
           for item in ("-p", f"{name}:={float(value)!r}")]
    return [*external, "--ros-args", *own] if own else list(external)


def evaluate_in_stack_anywhere(values: dict[str, Any], overrides: dict[str, Any],
                               objective: Objective | str, index: int, bound: float = math.inf,
                               timeout: float = 300.0) -> Evaluation:
    """evaluate_in_stack for a worker on any host (a Dask cluster): the bag goes to a
    temporary directory of that host and is deleted once scored; the launcher takes
    a free ROS domain of that host, with localhost discovery."""
    workdir = Path(tempfile.mkdtemp(prefix="ato-candidate-"))
    try:
        return evaluate_in_stack(values, overrides, objective, index, workdir / "bag", timeout,
                                 bound=bound)
    finally:
        shutil.rmtree(workdir, ignore_errors=True)


def conditions(values: dict[str, Any], settings: TuningSettings) -> str:
    """A digest of everything that makes a logged fitness mean what it means: every
    parameter of the base run, the text of its line and table files, the fitness,
    requirements, search space, algorithm and how candidates are run."""
    return conditions_digest(values, settings.describe())


class TuningLost(ClusterLost):
    """A tuning that cannot go on through no fault of its input (its Dask scheduler
    stopped answering); its log keeps every finished evaluation for --resume."""


class EvaluationLog:
    """evaluations.jsonl: one line per finished evaluation, flushed at once. On resume
    every line must have been evaluated under the same conditions; a last line cut
    short (the process was killed while writing it) is dropped and evaluated again.
    Reading checks and changes nothing; start() writes."""

    def __init__(self, path: Path, resume: bool, expected_conditions: str):
        self.path = path
        self.resume = resume
        self.done: dict[int, Evaluation] = {}
        if resume and path.exists():
            lines = path.read_text().splitlines()
            for number, line in enumerate(lines, 1):
                if not line.strip():
                    continue
                try:
                    record = Evaluation(**json.loads(line))
                    if not isinstance(record.fitness, (int, float)):
                        raise TypeError("no fitness")
                except (json.JSONDecodeError, TypeError) as exc:
                    if number == len(lines):  # cut short: evaluate it again
                        print(f"warning: {path} line {number} is incomplete; it is evaluated "
                              "again", file=sys.stderr)
                        break
                    raise ScenarioError(f"{path} line {number} is not an evaluation record "
                                        f"({exc.__class__.__name__}); remove that line or tune "
                                        "into a new --out") from None
                if record.conditions != expected_conditions:
                    raise ScenarioError(
                        f"{path} line {number} was evaluated under other conditions (the "
                        "scenario, its line or table file, --set, the fitness, requirements or "
                        "search space changed); tune into a new --out")
                self.done[record.index] = record
        self.lock = threading.Lock()

    def start(self) -> None:
        """The log as this tuning appends to it: what was read (without a cut-short
        last line) on resume, else empty."""
        if self.resume and self.path.exists():
            temporary = self.path.with_suffix(".jsonl.tmp")
            temporary.write_text("".join(self.line(record) for record in self.done.values()))
            temporary.replace(self.path)
        elif self.path.exists():
            self.path.unlink()

    @staticmethod
    def line(record: Evaluation) -> str:
        return jsontext.dumps(asdict(record)) + "\n"

    def cached(self, index: int, overrides: dict[str, Any]) -> Evaluation | None:
        record = self.done.get(index)
        if record is None:
            return None
        if record.params.keys() != overrides.keys() or not np.allclose(
                list(record.params.values()), list(overrides.values()), rtol=1e-12, atol=0.0):
            raise ScenarioError(f"{self.path}: evaluation {index} was made with other settings; "
                                "resume with the same algorithm, seed and --params")
        return record

    def append(self, record: Evaluation) -> None:
        with self.lock, self.path.open("a") as handle:
            handle.write(self.line(record))
            handle.flush()
        self.done[record.index] = record


@dataclass
class TuningSettings:
    algorithm: str
    scenario: str
    space: SearchSpace
    evaluations: int
    seed: int
    workers: int = 1
    in_process: bool = False
    fitness: str = "itae"
    timeout: float = 300.0     # s of wall time per stack candidate
    options: dict[str, Any] = field(default_factory=dict)
    requirements: tuple[Requirement, ...] = ()
    keep_bags: bool = False    # stack candidates' bags (runs/), else deleted once scored
    prune: bool = True         # in-process: end candidates that cannot matter (see Tuner)
    cluster: str = ""          # "" = local worker processes; local:N or tcp://HOST:PORT = Dask
    external: tuple[str, ...] = ()  # an external controller's command (its own parameters)
    objectives: tuple[str, ...] = ()  # several at once (ParetoTuner); else the fitness
    spread: TrainSpread | None = None  # each candidate over many trains
    weights: tuple[float, ...] = ()  # a swarm optimizer's weighted sum of the objectives

    @property
    def objective(self) -> Objective:
        if self.objectives and self.algorithm in ALGORITHMS:
            return WeightedSum(self.fitness, self.requirements, self.objectives,
                               weights=self.weights)
        if self.objectives:
            return Objectives(self.fitness, self.requirements, self.objectives, self.prune)
        return Objective(self.fitness, self.requirements)

    def describe(self) -> dict[str, Any]:
        return {"algorithm": self.algorithm, "scenario": self.scenario,
                "params": {n: [lo, hi] for n, lo, hi in zip(self.space.names, self.space.lower,
                                                            self.space.upper, strict=True)},
                "evaluations": self.evaluations, "seed": self.seed, "fitness": self.fitness,
                "in_process": self.in_process, "options": self.options,
                "prune": self.prune,
                "requirements": [f"{r.name}<={r.limit:g}" for r in self.requirements],
                **({"external": list(self.external)} if self.external else {}),
                **({"objectives": list(self.objectives)} if self.objectives else {}),
                **(self.spread.describe() if self.spread else {}),
                **({"weights": list(self.weights)} if self.weights else {})}


class Tuner:
    """Runs one tuning and writes its output directory. Everything that can refuse it
    (settings, the directory's lock, a resumed log's conditions) is checked before
    anything in the directory is written."""

    def __init__(self, values: dict[str, Any], settings: TuningSettings, out: Path,
                 resume: bool = False, evaluate: Callable[..., Evaluation] | None = None,
                 progress: bool = True):
        _check_settings(settings)
        self.values, self.settings, self.out = values, settings, out
        self.progress = progress
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ScenarioError(f"cannot create {out}: {exc.strerror or exc}") from None
        self.directory_lock = hold_directory(out, "tuning")
        self.conditions = conditions(values, settings)
        settings_file = out / "tuning.json"
        described = jsontext.dumps({**settings.describe(), "conditions": self.conditions},
                                   indent=2)
        if resume and settings_file.exists():
            check_same_settings(out, settings_file, described, "tuning",
                                "scenario, files, --set", "tune into a new --out")
        self.log = EvaluationLog(out / "evaluations.jsonl", resume, self.conditions)
        self.summary = _finished_summary(out, self.conditions, len(self.log.done)) \
            if resume else None
        if self.summary is None:  # accepted, with work to do: the directory is this tuning's
            name_holder(self.directory_lock)
            settings_file.write_text(described)
            self.log.start()
        self.in_process_pool = evaluate is None and settings.in_process
        self.evaluate = evaluate if evaluate is not None else self._evaluator()
        self._plan(evaluate is None)
        self.cancel = threading.Event()  # stops the stack candidates under way
        self.next_index = 0
        self.fresh = 0  # evaluations run by this process (not replayed from the log)
        self.pruned = 0  # of them, ended early by pruning
        self.started = time.monotonic()
        self.best = math.inf

    def _plan(self, own_evaluator: bool) -> None:
        """The algorithm's pace (for the progress line) and whether it prunes: a fitness
        that only grows, an algorithm that bounds its candidates (optimizers/base.py),
        in-process or by the supervisor; the result is the same."""
        algorithm = create(self.settings.algorithm, **self.settings.options)
        self.prune = (self.settings.prune and own_evaluator and self.settings.objective.prunable
                      and getattr(algorithm, "own_best_bound", False) and not self.settings.spread)
        self.initial_evaluations = algorithm.initial_evaluations()
        self.evaluations_per_iteration = algorithm.evaluations_per_iteration()

    @property
    def finished(self) -> bool:
        """Resumed, and the tuning had finished: nothing to run (summary.json says how
        it ended)."""
        return self.summary is not None

    def _evaluator(self) -> Callable[..., Evaluation]:
        """How the settings run a candidate: in a worker process, through the stack on
        any host of a Dask cluster, or through the stack here with its bag in OUT/runs."""
        if self.settings.spread:
            return functools.partial(evaluate_over_trains, timeout=self.settings.timeout,
                                     spread=self.settings.spread, evaluate=evaluate_in_process)
        if self.settings.in_process:
            return functools.partial(evaluate_in_process, timeout=self.settings.timeout)
        if self.settings.cluster:  # a remote worker cannot reach this tuner's OUT/runs
            return functools.partial(evaluate_in_stack_anywhere, timeout=self.settings.timeout)
        return self._evaluate_in_stack

    def _stamped(self, record: Evaluation) -> Evaluation:
        record.conditions = self.conditions
        if not math.isfinite(record.fitness):  # the log's fitness is always a number
            record.fitness, record.status = PENALTY, "failed"
            record.message = record.message or "fitness not finite"
        return record

    def _evaluate_in_stack(self, values, overrides, objective, index,
                           bound: float = math.inf) -> Evaluation:
        bag = self.out / "runs" / f"candidate-{index:05d}"
        if bag.exists():  # a candidate interrupted before it was logged: run it again
            shutil.rmtree(bag)
        bag.parent.mkdir(parents=True, exist_ok=True)
        record = evaluate_in_stack(values, overrides, objective, index, bag,
                                   self.settings.timeout, self.cancel, bound,
                                   self.settings.external)
        if not self.settings.keep_bags:  # scored; best.yaml reruns the best one
            shutil.rmtree(bag, ignore_errors=True)
        return record

    def _backend(self) -> Backend:
        """Where candidates run: local worker processes (in-process evaluations),
        threads (stack runs are processes already), or a Dask cluster's workers; all
        give the same fitness for the same candidate."""
        return Backend(self.settings.workers, self.settings.cluster,
                       threads=not self.in_process_pool, cancel=self.cancel)

    def _warm_kernels(self) -> None:
        """Compile the in-process loop here, once, before the workers start: they then
        load it (forked, or from the cache beside the source) instead of compiling it
        each."""
        if self.progress:
            with kernels.announced():
                warm(self.values)
        else:
            warm(self.values)

    def _batch_fitness(self, backend: Backend, population: np.ndarray,
                       bounds: np.ndarray | None = None) -> np.ndarray:
        return np.array([record.fitness for record in self._batch(backend, population,
                                                                    bounds)])

    def _batch(self, backend: Backend, population: np.ndarray,
               bounds: np.ndarray | None = None) -> list[Evaluation]:
        """The population's evaluations in its order: from the log where it has them
        (a resume), the rest run on the backend and logged as they finish."""
        requests = []
        for x in population:
            overrides = self.settings.space.overrides(x)
            requests.append((self.next_index, overrides))
            self.next_index += 1
        results: dict[int, Evaluation] = {}
        pending = {}
        for index, overrides in requests:
            record = self.log.cached(index, overrides)
            if record is not None:
                results[index] = record
                self.best = min(self.best, record.fitness)
            else:
                extra = (float(bounds[index - requests[0][0]]),) if bounds is not None else ()
                pending[backend.submit(self.evaluate, self.values, overrides,
                                       self.settings.objective, index, *extra)] = index
        waiting = set(pending)
        while waiting:
            finished = backend.finished(waiting)
            waiting -= finished
            for future in sorted(finished, key=pending.get):
                record = self._stamped(future.result())
                self.fresh += 1
                self.log.append(record)
                results[record.index] = record
                self._report(record)
        return [results[index] for index, _ in requests]

    def _report(self, record: Evaluation) -> None:
        self.best = min(self.best, record.fitness)
        self.pruned += record.status == "pruned"
        if not self.progress:
            return
        done = len(self.log.done)
        total = self.settings.evaluations
        eta = (time.monotonic() - self.paced) / max(self.fresh, 1) * (total - done)
        iteration = max(0, done - self.initial_evaluations) // self.evaluations_per_iteration
        pruned = f"  pruned {self.pruned / max(self.fresh, 1):4.0%}" if self.prune else ""
        line = (f"iteration {iteration:4d}  evaluations {done:5d}/{total}  {self._standing()}"
                f"{pruned}  ETA {eta:6.0f} s")
        notable = record.status not in ("ok", "pruned")
        show_progress(done, total, line, f"candidate {record.index}: {record.status}"
                      if notable else "")

    def _standing(self) -> str:
        """Where the tuning stands, for the progress line."""
        return f"best {self.best:.6g}"

    def run(self) -> Result:
        """The tuning. Ctrl-C stops the candidates under way at once (their runs are
        not logged; --resume evaluates them again) and re-raises."""
        s = self.settings
        if self.in_process_pool:
            self._warm_kernels()
        self.paced = time.monotonic()  # the ETA's pace is the candidates', not a compilation's
        try:
            with self._backend() as backend:
                result = optimize(s.algorithm,
                                  lambda population, bounds=None: self._batch_fitness(
                                      backend, population, bounds),
                                  s.space.lower, s.space.upper, s.evaluations, s.seed,
                                  x0=s.space.start(self.values), bounded=self.prune,
                                  **s.options)
        except ClusterLost as exc:
            raise TuningLost(f"{exc} mid-tuning; every finished evaluation is in "
                             f"{self.log.path}; continue with --resume") from None
        self._write_outputs(result)
        return result

    def _write_outputs(self, result: Result) -> None:
        best_overrides = self.settings.space.overrides(result.best_x)
        if result.best_f < PENALTY:  # else every candidate failed: there is no best to run
            best_values = apply_overrides(self.values, {} if self.settings.external  # its own
                                          else best_overrides)  # on the command line
            (self.out / "best.yaml").write_text(self.best_scenario(result, best_values))
        with (self.out / "history.csv").open("w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(["iteration", "evaluations", "best_fitness", "mean_fitness",
                             *self.settings.space.names])
            for record in result.history:  # plain decimal text, full precision
                writer.writerow([record.iteration, record.evaluations, repr(float(record.best_f)),
                                 repr(float(record.mean_f)),
                                 *(repr(float(v)) for v in record.best_x)])
        failures, pruned = {}, 0
        for record in self.log.done.values():
            if record.status == "pruned":
                pruned += 1
            elif record.status != "ok":
                failures[record.status] = failures.get(record.status, 0) + 1
        summary = {**self.settings.describe(), "best_fitness": result.best_f,
                   "best_params": best_overrides, "evaluations_used": result.evaluations,
                   "iterations": result.iterations, "stop_reason": str(result.stop_reason.value),
                   "failed_evaluations": failures, "pruned_evaluations": pruned,
                   "best_is_feasible": result.best_f < INFEASIBLE,
                   "best_at_bounds": at_bounds(self.settings.space, result.best_x),
                   "best_indices": _best_indices(self.log, best_overrides),
                   "wall_time": time.monotonic() - self.started, "conditions": self.conditions}
        plot_convergence([self.out], self.out / "convergence.png")
        # last: a summary.json under these conditions means the tuning finished
        (self.out / "summary.json").write_text(jsontext.dumps(summary, indent=2))


    def best_scenario(self, result: Result, best_values: dict[str, Any]) -> str:
        """best.yaml: the base scenario by name (or by path relative to OUT) and what the
        best run changes in it, the tuned parameters and any --set; commented."""
        s = self.settings
        feasible = "feasible" if result.best_f < INFEASIBLE else "INFEASIBLE"
        return self.scenario_text(
            f"Best of a {s.algorithm} tuning (seed {s.seed}, {result.evaluations} evaluations) "
            f"on {s.scenario}, {time.strftime('%Y-%m-%d')}: fitness {fitness_name(s.describe())} = "
            f"{result.best_f:.9g} ({feasible}"
            + "".join(f", {r.name}<={r.limit:g}" for r in s.requirements) + ").",
            s.space.overrides(result.best_x), best_values)

    def scenario_text(self, header: str, overrides: dict[str, Any],
                      best_values: dict[str, Any], target: Path | None = None) -> str:
        """The scenario file `target` (default OUT/best.yaml) run_stack.py accepts: the
        base scenario by name (or by path relative to the file) and what `best_values`
        change in it, the tuned parameters and any --set, under `header` and the command
        that runs it."""
        s = self.settings
        target = target or self.out / "best.yaml"
        base_path = resolve_scenario(s.scenario)
        base = (s.scenario if base_path.parent == config_dir() / "scenarios"
                else os.path.relpath(base_path.resolve(), target.parent.resolve()))
        base_values = load_scenario(s.scenario)
        changed = [name for name in SPEC_BY_NAME if best_values[name] != base_values[name]
                   and name not in ("recorder.output", "supervisor.report")]
        run_best = best_command(self.out, s.external, overrides, target)
        document = {"base": base, **ros_parameter_file(best_values, set(changed))}
        return (f"# {header}\n# Run it: {run_best}\n"
                + yaml.safe_dump(document, sort_keys=False))


def fitness_name(described: dict[str, Any]) -> str:
    """What a tuning (its TuningSettings.describe(), or its summary.json) minimised."""
    if described.get("weights"):
        return "the weighted sum " + " + ".join(
            f"{weight:g} {name}" for weight, name in zip(described["weights"],
                                                        described["objectives"], strict=True))
    return described["fitness"]


def best_command(out: Path, external: tuple[str, ...], best: dict[str, Any],
                 scenario: Path | None = None) -> str:
    """The command that runs the best candidate, its `scenario` file (default
    OUT/best.yaml; with an external node: its best own parameters on its command line)."""
    command = f"python scripts/run_stack.py --scenario {scenario or out / 'best.yaml'}"
    if not external:
        return command
    return " ".join([command, "--external", "controller", "--",
                     *map(shlex.quote, node_command(external, best))])


def check_external(external: tuple[str, ...], in_process: bool, cluster: str) -> None:
    """An external node's law runs only in its node, through the stack on this host."""
    if external and (in_process or cluster):
        raise ScenarioError("an external node's law runs only in its node: --external "
                            "tunes through the stack on this host, not with --in-process "
                            "or --cluster")


def _check_settings(settings: TuningSettings) -> None:
    """A ScenarioError for an unknown algorithm or fitness, bags kept from a cluster, or
    an external node not run through the stack here."""
    check_external(settings.external, settings.in_process, settings.cluster)
    known = (*PARETO_ALGORITHMS, *ALGORITHMS) if settings.objectives else tuple(ALGORITHMS)
    if settings.algorithm not in known:
        raise ScenarioError(f"unknown algorithm {settings.algorithm!r}; known: "
                            f"{', '.join(known)}")
    if settings.objectives and settings.algorithm in ALGORITHMS and \
            len(settings.weights) != len(settings.objectives):
        raise ScenarioError(f"{settings.algorithm} minimises one number: give --weights, one "
                            "per objective (their weighted sum), or a multi-objective "
                            f"algorithm ({', '.join(PARETO_ALGORITHMS)})")
    for name in settings.objectives:
        objective_index(name)
    if settings.algorithm in PARETO_ALGORITHMS and not all(
            importlib.util.find_spec(name) for name in ("pymoo", "moocore")):
        raise ScenarioError("--objectives needs pymoo and moocore: pip install pymoo moocore "
                            "(requirements.txt pins them)")
    if len(settings.objectives) == 1:
        raise ScenarioError("--objectives needs two or more (one is --fitness)")
    if settings.fitness not in FITNESS:
        raise ScenarioError(f"unknown fitness {settings.fitness!r}; known: "
                            f"{', '.join(FITNESS)}")
    if settings.spread:
        settings.spread.check(len(settings.objective.indices))
    if settings.spread and not settings.in_process:
        raise ScenarioError("--trains runs each candidate's trains in-process: give "
                            "--in-process")
    if settings.cluster:
        check_cluster(settings.cluster)
    if settings.cluster and settings.keep_bags:
        raise ScenarioError("--keep-bags keeps bags on this host; not with --cluster")


def at_bounds(space: SearchSpace, x: np.ndarray) -> list[str]:
    """The tuned parameters whose best value sits on its box's bound (a wider box may
    do better)."""
    width = space.upper - space.lower
    return [name for name, value, low, high, span in zip(space.names, x, space.lower,
                                                         space.upper, width, strict=True)
            if min(value - low, high - value) <= 1e-6 * span]


def _finished_summary(out: Path, expected_conditions: str, logged: int) -> dict[str, Any] | None:
    """The summary.json of a tuning in OUT that finished under these conditions, its
    `logged` evaluations all still in the log, or None."""
    try:
        summary = json.loads((out / "summary.json").read_text())
    except (OSError, ValueError):
        return None
    finished = (isinstance(summary, dict) and summary.get("conditions") == expected_conditions
                and summary.get("evaluations_used") == logged)
    return summary if finished else None


def _best_indices(log: EvaluationLog, best: dict[str, Any]) -> dict[str, Any]:
    for record in log.done.values():
        if record.params == best:
            return record.indices
    return {}
