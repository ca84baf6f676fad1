"""Robustness of a controller (scripts/robustness.py): one scenario over a seeded spread
of real trains, each sample drawn, prepared and run in the worker that runs it, from
the study's seed and the sample's number alone (any worker, any order, any resume
gives the sample the same train and result)."""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import apply_overrides
from ato_nodes.core.targets.timetable import load_timetable
from ato_nodes.results.journeys import (TIMING_MISSED, WORST_ARRIVAL, WORST_STOP,
                                        score_with_journey)
from ato_nodes.studies.samples import NUMBER, SampleFailed

FACTORS = {  # the real train's shares of the nominal values, and the option of each range
    "plant.mass_factor": "mass", "plant.resistance_factor": "resistance",
    "plant.lag_factor": "lag"}
RANGES = {  # the real trains' default spread: each factor's range of shares, low and high
    "plant.mass_factor": (0.85, 1.3), "plant.resistance_factor": (0.8, 1.2),
    "plant.lag_factor": (0.7, 1.3)}
SEEDS = ("plant.noise_seed", "train.load_weighing_seed")
# A train on its sensors (odometry.enabled) draws their errors' seed, and on a rail of
# limited adhesion how wet or dirty within its condition; each from a stream of its own,
# so the trains are those of the same seed before them
SENSOR_SEED = "odometry.seed"
RAIL = "plant.adhesion_scale"
RAIL_RANGE = (0.8, 1.2)  # the adhesion's share of its condition's curve
# On its sensors the ATO knows the limit where it has the train; the scorer judges it
# where the train is (core/run/scoring.limit_where_the_train_is)
OVERSPEED = "max_overspeed_kmh"
INDICES = (  # key, heading; worst is the largest
    ("max_abs_error_kmh", "max abs(e) km/h"),
    ("p95_abs_error_kmh", "p95 abs(e) km/h"),
    ("abs_stopping_error", "abs(stop error) m"),
    ("max_jerk", "max jerk (1 s) m/s^3"),
    ("itae", "ITAE"),
    (OVERSPEED, "max overspeed km/h"),
    (WORST_STOP, "journey: worst stop m"),
    (WORST_ARRIVAL, "journey: worst arrival s"),
    (TIMING_MISSED, "journey: timing points missed"),
)
WITHIN = (  # key, bound, what the count says
    ("max_abs_error_kmh", 1.0, "within 1 km/h"),
    ("abs_stopping_error", 0.1, "stops within 0.1 m"),
    ("abs_running_time_error", 5.0, "arrivals within 5 s"),
    ("abs_stopping_error", 0.3, "stops within 0.3 m"),
    ("overrun", 0.0, "no overrun (past 0.3 m)"),
    (OVERSPEED, 0.0, "no overspeed"),
    (WORST_STOP, 0.1, "every stop of the journey within 0.1 m"),
    (WORST_STOP, 0.3, "every stop of the journey within 0.3 m"),
    (WORST_ARRIVAL, 5.0, "every arrival of the journey within 5 s"),
    (TIMING_MISSED, 0.0, "every timing point of the journey kept"),
)
COLUMNS = {  # a sample's row (after its number): its draw, what the ATO knew, its indices
    **dict.fromkeys(FACTORS, float), **dict.fromkeys(SEEDS, int), "train.mass_reading": float,
    **{key: float for key, _ in INDICES if key not in (TIMING_MISSED, OVERSPEED)},
    "running_time_error": float,
    "abs_running_time_error": float}
SEED_BOUND = 2**31 - 1  # the schema's bound of a noise or weighing seed


def study_columns(base: Mapping[str, Any]) -> dict[str, type]:
    """The samples' columns of a study on `base`: COLUMNS, and the timing points missed
    when its journey has timing points (a TTOBench journey's), the overrun and the
    overspeed on sensors or a rail of limited adhesion: columns only those studies have,
    so that a study recorded without them still resumes."""
    columns = dict(COLUMNS)
    if base["profile.kind"] == "journey" and \
            load_timetable(base["profile.journey.timetable"]).journey:
        columns[TIMING_MISSED] = float
    if base["odometry.enabled"]:
        columns[SENSOR_SEED] = int
    if base["plant.adhesion"] != "unlimited":
        columns[RAIL] = float
    if base["odometry.enabled"] or base["plant.adhesion"] != "unlimited":
        columns["overrun"] = columns[OVERSPEED] = float
    return columns


def draw_train(ranges: Mapping[str, tuple[float, float]], seed: int, number: int,
               sensed: bool = False) -> dict:
    """Sample `number`'s real train: a share of each nominal value, uniform in its range,
    a speed-sensor noise seed and a load-weighing seed (from a stream of its own, so
    the trains are those of the same seed before the load weighing); `sensed`, its
    sensors' seed, and with a range for RAIL its rail's adhesion (each its own stream)."""
    rng = np.random.default_rng([seed, number, 0])
    weighing = np.random.default_rng([seed, number, 1])
    draw = {**{name: float(rng.uniform(low, high)) for name, (low, high) in ranges.items()
               if name != RAIL},
            "plant.noise_seed": int(rng.integers(0, SEED_BOUND)),
            "train.load_weighing_seed": int(weighing.integers(0, SEED_BOUND))}
    if sensed:
        draw[SENSOR_SEED] = int(np.random.default_rng([seed, number, 2]).integers(0, SEED_BOUND))
    if RAIL in ranges:
        draw[RAIL] = float(np.random.default_rng([seed, number, 3]).uniform(*ranges[RAIL]))
    return draw


def run_sample(base: dict[str, Any], ranges: Mapping[str, tuple[float, float]], seed: int,
               number: int, extra: tuple[str, ...] = ()) -> dict[str, Any]:
    """Sample `number` of the study on `base` (the scenario's checked values with the
    study's --set): drawn, prepared and run here (a worker), its row of COLUMNS and of
    the indices named in `extra` that the run has."""
    draw = draw_train(ranges, seed, number, base["odometry.enabled"])
    try:
        values = apply_overrides(base, draw)
    except ScenarioError as exc:
        raise SampleFailed(f"sample {number}: {exc}") from None
    indices = score_with_journey(values)
    return {NUMBER: number, **sample_result(draw, indices),
            **{key: float(indices[key]) for key in extra if key in indices},
            "train.mass_reading": values["train.mass_reading"]}  # what the ATO knew


def run_sample_in_stack(base: dict[str, Any], ranges: Mapping[str, tuple[float, float]],
                        seed: int, number: int, external: dict[str, list[str]]
                        ) -> dict[str, Any]:
    """run_sample through the stack, with a node of the user's (`external`,
    docs/external-nodes.md: its law runs only there) in its run: the bag in a temporary
    directory, scored, then deleted."""
    from ato_nodes.bags.bagio import read_series
    from ato_nodes.launcher.launch import Stack
    draw = draw_train(ranges, seed, number, base["odometry.enabled"])
    try:
        values = apply_overrides(base, draw)
    except ScenarioError as exc:
        raise SampleFailed(f"sample {number}: {exc}") from None
    folder = Path(tempfile.mkdtemp(prefix="ato-sample-"))
    try:
        outcome = Stack(values, folder / "bag", quiet=True, external=external).run()
        if not outcome.ok:
            raise SampleFailed(f"sample {number}: {outcome.message}")
        indices = score_with_journey(values, read_series(folder / "bag"))
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    return {NUMBER: number, **sample_result(draw, indices),
            "train.mass_reading": values["train.mass_reading"]}


def sample_result(draw: dict, indices: dict) -> dict:
    """The sample's draw and the indices of INDICES it has."""
    result = {**draw, **{key: float(indices[key]) for key, _ in INDICES if key in indices}}
    if "stopping_error" in indices:  # abs_stopping_error is among INDICES
        result["overrun"] = float(indices["overrun"])
    if "running_time_error" in indices:
        result["running_time_error"] = float(indices["running_time_error"])
        result["abs_running_time_error"] = float(indices["abs_running_time_error"])
    return result


def summarise(values: np.ndarray, present: np.ndarray, columns: list[str]
              ) -> tuple[dict[str, dict[str, float]], dict[str, int]]:
    """(median and worst of each index of INDICES the samples have, how many samples
    keep each bound of WITHIN of those that have its index) of the samples' table
    (SampleFile.table(), its `columns`)."""
    summary, within = {}, {}
    for key, _ in INDICES:
        if key not in columns:
            continue
        has = present[:, columns.index(key)]
        if has.any():
            column = values[has, columns.index(key)]
            summary[key] = {"median": float(np.median(column)), "worst": float(np.max(column))}
    for key, bound, text in WITHIN:
        if key not in columns:
            continue
        has = present[:, columns.index(key)]
        if has.any():
            within[text] = int(np.count_nonzero(values[has, columns.index(key)] <= bound))
    return summary, within
