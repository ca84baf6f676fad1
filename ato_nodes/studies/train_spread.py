"""A candidate judged over many trains (tune.py --trains N): the same N real trains for
every candidate, drawn as robustness.py draws them (its default ranges of mass,
resistance and lag, the sensors' and the rail's draws where the run has them; the
study's seed and the train's number alone), each objective the trains' mean, a
quantile or the worst, each requirement the worst train's: it must hold for every
train."""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import apply_overrides
from ato_nodes.core.scoring.catalogue import MAXIMISED
from ato_nodes.studies.robustness import RAIL, RAIL_RANGE, RANGES, draw_train


@dataclass(frozen=True)
class TrainSpread:
    """N trains of the seed `seed`, each objective's `statistic` over them: mean, worst,
    or qP (the P quantile, 0 < P < 1, e.g. q0.9); one for every objective, or one per
    objective in their order, comma-separated (e.g. mean,worst,q0.95)."""

    trains: int
    seed: int = 1
    statistic: str = "mean"

    def __post_init__(self):
        if self.trains < 1:
            raise ScenarioError("--trains must be at least 1")
        for statistic in self.statistics:  # checked before any run
            _reduce(statistic, np.zeros(1), maximised=False)

    @property
    def statistics(self) -> tuple[str, ...]:
        return tuple(item.strip() for item in self.statistic.split(","))

    def check(self, objectives: int) -> None:
        if len(self.statistics) not in (1, objectives):
            raise ScenarioError(f"--statistic: one for every objective or one per objective "
                                f"({objectives}), not {len(self.statistics)}")

    def reduce(self, values: np.ndarray, maximised: bool, objective: int = 0) -> float:
        """The statistic of the `objective`-th objective over the trains' values."""
        statistics = self.statistics
        return _reduce(statistics[objective if len(statistics) > 1 else 0], values, maximised)

    def describe(self) -> dict[str, Any]:
        return {"trains": self.trains, "train_seed": self.seed, "statistic": self.statistic}


def _reduce(statistic: str, values: np.ndarray, maximised: bool) -> float:
    """mean; worst: the largest of an objective minimised, the smallest of one maximised;
    qP: a quantile on the worse side."""
    if statistic == "mean":
        return float(np.mean(values))
    if statistic == "worst":
        return float(np.min(values) if maximised else np.max(values))
    share = _quantile(statistic)
    return float(np.quantile(values, 1.0 - share if maximised else share))


def _quantile(statistic: str) -> float:
    try:
        share = float(statistic[1:]) if statistic.startswith("q") else math.nan
    except ValueError:
        share = math.nan
    if not 0.0 < share < 1.0:
        raise ScenarioError(f"--statistic: mean, worst or qP (0 < P < 1, e.g. q0.9), not "
                            f"{statistic!r}")
    return share


def evaluate_over_trains(values: dict[str, Any], overrides: dict[str, Any], objective,
                         index: int, bound: float = math.inf, timeout: float | None = None, *,
                         spread: TrainSpread, evaluate: Callable):
    """One candidate (a tuning's Objective) over the spread's trains in this process (a
    worker), each run by `evaluate` (the tuner's evaluate_in_process); the first train
    that fails fails the candidate. Its indices: each objective's statistic and each
    requirement's worst train, beside `trains`."""
    started = time.perf_counter()
    ranges = dict(RANGES, **({RAIL: RAIL_RANGE} if values["plant.adhesion"] != "unlimited"
                             else {}))
    records = []
    for number in range(spread.trains):
        draw = draw_train(ranges, spread.seed, number, values["odometry.enabled"])
        record = evaluate(apply_overrides(values, draw), overrides, objective, index,
                          timeout=timeout)
        if record.status not in ("ok", "infeasible"):
            record.message = f"train {number}: {record.status} {record.message}".strip()
            record.wall_time = time.perf_counter() - started
            return record
        records.append(record)
    indices: dict[str, Any] = {name: spread.reduce(np.array([r.indices[name] for r in records]),
                                                   name in MAXIMISED, number)
                               for number, name in enumerate(objective.indices)}
    for requirement in objective.requirements:  # it must hold for every train
        worst = max(records, key=lambda record: requirement.signed_violation(record.indices))
        indices[requirement.name] = worst.indices.get(requirement.name, math.nan)
    indices["trains"] = spread.trains
    value, status, message = objective.score(indices)
    return dataclasses.replace(records[0], fitness=value, status=status, indices=indices,
                               message=message, wall_time=time.perf_counter() - started)
