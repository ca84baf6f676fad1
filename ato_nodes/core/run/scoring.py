"""One scorer for recorded and in-process runs: series in, indices out."""

from __future__ import annotations

import base64
import hashlib
import json
import math
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager, nullcontext
from pathlib import Path

import numpy as np
import yaml

from ..base.errors import ScenarioError
from ..base.units import MS_TO_KMH
from ..config.components import CONTROLLERS
from ..config.context import RunContext
from ..config.schema import defaults
from ..scoring.indices import tracking_indices
from ..scoring.operation import STANDSTILL, Regeneration, operation_indices
from ..targets.horizons import plan_speed_limits
from ..train.line import Line
from ..train.lines import for_train, load_line_file, parse_line_file
from ..train.ttobench import is_library_file

# Run-parameter key of the line file's text, kept in the bag. Base64: the parameters
# travel as a ROS parameter (YAML) to the recorder, whose YAML round trips mangle
# backslash escapes in long strings.
LINE_BASE64 = "line.base64"


def encode_line(text: str) -> str:
    return base64.b64encode(text.encode()).decode()


# Other files a run reads, kept in the bag as <name>.sha256 and <name>.base64, so a
# bag re-runs without them (the line is kept as LINE_BASE64, which the scorer reads).
KEPT_FILES = ("profile.table.file", "profile.strategy.file", "gpc.model",
              "profile.journey.timetable", "plant.train")


def kept_files(values: dict) -> dict[str, str]:
    kept = {}
    for name in KEPT_FILES:
        # plant.train names a file only as a TTOBench train (else a preset)
        if values.get(name) and (name != "plant.train" or is_library_file(values[name])):
            content = Path(values[name]).read_bytes()
            kept[f"{name}.sha256"] = hashlib.sha256(content).hexdigest()
            kept[f"{name}.base64"] = base64.b64encode(content).decode()
    return kept


def kept_file(parameters: dict, name: str) -> bytes | None:
    """The content of a file the bag keeps (checked against its digest), None if the
    bag keeps none under `name`."""
    if not parameters.get(f"{name}.base64"):
        return None
    content = base64.b64decode(parameters[f"{name}.base64"])
    if hashlib.sha256(content).hexdigest() != parameters.get(f"{name}.sha256"):
        raise ValueError(f"the copy of {name} kept in the bag does not match its sha256")
    return content


@contextmanager
def files_kept(parameters: dict) -> Iterator[dict]:
    """The run's parameters with the files its bag keeps (the line, tables, model,
    timetable) written out to a temporary folder and named there, for as long as the
    context lasts: a bag's run made again without the files it once read."""
    values = dict(parameters)
    with tempfile.TemporaryDirectory() as folder:
        kept = {"line.file": base64.b64decode(values[LINE_BASE64])
                if values.get(LINE_BASE64) else None}
        kept.update({name: kept_file(values, name) for name in KEPT_FILES})
        for name, content in kept.items():
            if content is not None:  # a folder each: a line and its timetable share a name
                copy = Path(folder) / name / Path(values[name]).name
                copy.parent.mkdir()
                copy.write_bytes(content)
                values[name] = str(copy)
        timetable = "profile.journey.timetable"
        if kept[timetable] is not None and kept["line.file"] is not None:
            _on_kept_line(Path(values[timetable]), values["line.file"])
        yield values


def _on_kept_line(timetable: Path, line_copy: str) -> None:
    """The timetable's copy made to name the line's copy: its `line:` named the line
    where it was then (absolute, or relative to a folder the copy is not in)."""
    text = timetable.read_text(encoding="utf-8")
    try:
        named = next(value for key, value in yaml.compose(text).value
                     if key.value == "line")
    except (yaml.YAMLError, AttributeError, TypeError, ValueError, StopIteration):
        return  # the plan says what is wrong with the copy, in one line
    timetable.write_text(text[:named.start_mark.index] + json.dumps(line_copy)
                         + text[named.end_mark.index:], encoding="utf-8")


def score_series(series: dict[str, np.ndarray], parameters: dict | None = None
                 ) -> dict[str, float]:
    """Indices of a run. Series of unequal length (an interrupted run) are cut to
    the steps every one of them holds. Which indices apply follows from what the
    run has: the observer's accuracy for a controller with a third-order observer,
    the overshoot for a step target, stopping and punctuality for a line with a stop."""
    series = common_steps(series)
    command = series.get("command")
    if command is not None and parameters:
        command = notch_level(command, parameters)
    indices = tracking_indices(series["t"], series["target"], series["speed"], command)
    b0 = observer_b0(parameters or {})
    if b0 is not None and {"z1", "z2", "z3", "acceleration"} <= set(series):
        indices.update(observer_accuracy(series, b0))
    if is_step(series["target"]):
        indices["overshoot_percent"] = step_overshoot(series["speed"], series["target"])
    if {"position", "acceleration", "force"} <= set(series):
        indices.update(operation(series, parameters or {}))
    return indices


def common_steps(series: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The series cut to the steps every one of them holds (an interrupted run)."""
    length = min(len(values) for values in series.values())
    return {name: values[:length] for name, values in series.items()}


def energy_terms(parameters: dict) -> dict:
    """operation_indices' mass (the real train's: the nominal times its load factor),
    gravity, efficiency and regeneration, from the run's parameters."""
    mass = parameters.get("plant.mass", math.nan) * parameters.get("plant.mass_factor", 1.0)
    return {"mass": mass, "gravity": parameters.get("plant.gravity", 9.8),
            "efficiency": parameters.get("plant.efficiency", 0.9),
            "regeneration": Regeneration.of(parameters)}


LIMITED = 1e5  # N/kN: a controller limit below this is a real one (defaults are 1e6)


def notch_level(command: np.ndarray, parameters: dict) -> np.ndarray:
    """The command as seed 004's notch level in [-1, 1] (u / u_max in traction,
    u / |u_min| in braking) when the controller has real limits, so that J's u^2
    term weighs the command against the tracking error on a fixed scale; the raw
    command (N/kN) otherwise, as for seed 000."""
    high, low = parameters.get("controller.u_max", 1e6), parameters.get("controller.u_min", -1e6)
    if high >= LIMITED or -low >= LIMITED:
        return command
    return np.where(command > 0, command / high, command / -low)


def run_line(parameters: dict) -> Line | None:
    """The run's line: the copy the bag carries (LINE_BASE64; its format by line.file's
    name, which the bag keeps), else the file it names; as the run's train ran it
    (core/train/lines.for_train: capped at its maximum speed, planned to the run's
    line.planned_run_time where it gave one)."""
    if parameters.get(LINE_BASE64):
        return for_train(parse_line_file(base64.b64decode(parameters[LINE_BASE64]).decode(),
                                         parameters.get("line.file") or "<bag>"), parameters)
    if parameters.get("line.file") and Path(parameters["line.file"]).is_file():
        return for_train(load_line_file(parameters["line.file"]), parameters)
    return None


def stop_not_reached(series: dict[str, np.ndarray], parameters: dict | None) -> str | None:
    """Why the run's STOP_INDICES judge nothing (None when they do): it ended with the
    train still moving short of its stop, a run cut shorter than its trip (--duration,
    an interrupt). A train standing short of the stop at the end is judged."""
    line = run_line(parameters) if parameters else None
    if line is None or line.stop_position <= 0.0 or "position" not in series:
        return None
    short = line.stop_position - float(series["position"][-1])
    speed = float(series["speed"][-1])
    if short <= 0.0 or speed <= STANDSTILL:
        return None
    return (f"the run ended at t = {float(series['t'][-1]):.1f} s, {short:.0f} m before its "
            f"stop, still moving at {speed * MS_TO_KMH:.0f} km/h")


def is_step(target: np.ndarray) -> bool:
    """A step target: at most two distinct values, the last held from its first step on."""
    values = np.unique(target)
    return len(values) <= 2 and len(target) > 1 and not np.any(np.diff(
        (target == target[-1]).astype(int)) < 0)


def operation(series: dict[str, np.ndarray], parameters: dict) -> dict[str, float]:
    """Energy (needs the train's mass), comfort, switches, limits; stopping and
    punctuality for runs on a line with a stop beyond the departure point."""
    line = run_line(parameters)
    to_station = line is not None and line.stop_position > 0.0
    if "speed_limit" in series and not np.any(np.isfinite(series["speed_limit"])):
        series = {name: values for name, values in series.items() if name != "speed_limit"}
    if "speed_limit" in series and "located_position" in series:
        series = {**series, "speed_limit": limit_where_the_train_is(series, parameters, line)}
    indices = operation_indices(
        series, **energy_terms(parameters),
        stop_position=line.stop_position if to_station else None,
        planned_run_time=line.planned_run_time if to_station else None,
        neutral=pantograph_in_neutral(series, parameters, line))
    if parameters.get("profile.approach_step", 0.0) > 0.0:
        steps = stepped_approach(series, parameters, line)
        error = np.abs(series["target"] - series["speed"])[~steps]
        indices["max_abs_error_outside_steps_kmh"] = float(error.max()) * MS_TO_KMH \
            if error.size else 0.0
        indices["stepped_time"] = float(np.count_nonzero(steps) * parameters["run.period"])
    return indices


def limit_where_the_train_is(series: dict[str, np.ndarray], parameters: dict,
                             line: Line | None) -> np.ndarray:
    """The limit at each sample's true position, m/s (inf: none). A run on its sensors
    records the limit where the ATO has the train (its located position): overspeed is
    judged where the train is. The plan's limits as it started (a re-plan keeps them),
    made from the files the run names, else from the copies its bag keeps (a bag moved
    to another machine, its timetable gone or changed); the recorded limit when neither
    makes it."""
    for made_again in (nullcontext(parameters), files_kept(parameters)):
        try:
            with made_again as values:
                context = RunContext({**defaults(), **values}, line)
                settings, journey = context.profile_settings, getattr(context.plan,
                                                                      "journey", None)
        except (ScenarioError, ValueError):
            continue
        return plan_speed_limits(settings, journey, line, series["position"])
    return np.asarray(series["speed_limit"], dtype=float)


def pantograph_in_neutral(series: dict[str, np.ndarray], parameters: dict, line: Line | None
                          ) -> np.ndarray | None:
    """The samples with the pantograph (plant.pantograph_offset behind the head, as the
    plant cuts traction) inside a neutral section; None on a line without any."""
    if line is None or not line.neutral_sections:
        return None
    return line.in_neutral_sections(np.asarray(series["position"], dtype=float)
                                    - parameters.get("plant.pantograph_offset", 0.0))


def stepped_approach(series: dict[str, np.ndarray], parameters: dict, line: Line | None
                     ) -> np.ndarray:
    """Steps where seed 003's stepped approach held the target below the plan (the run
    context's, rebuilt from the run's parameters and line): the stairs sit at least a
    step below it, the extrapolated targets within centimetres per second of it."""
    context = RunContext({**defaults(), **parameters}, line)
    planned = np.array([context.target(t, s)
                        for t, s in zip(series["t"], series["position"], strict=True)])
    return series["target"] < planned - 0.2 * parameters["profile.approach_step"]


def observer_b0(parameters: dict) -> float | None:
    """The input gain of the run's third-order observer, per s^2 (None: no such observer,
    or a bag without parameters)."""
    if CONTROLLERS.kind_parameter.name not in parameters:
        return None
    values = {**defaults(), **parameters}
    try:
        gain = CONTROLLERS.chosen(values).observer_gain
    except ScenarioError:  # a kind this version does not know
        return None
    return gain(values) if gain is not None else None


def total_disturbance(series: dict[str, np.ndarray], b0: float) -> np.ndarray:
    """What z3 estimates in the second-order model dv/dt = a, da/dt = f + b0 u:
    f_k = (a_k - a_k-1) / h - b0 u_k-1 from the true acceleration (NaN at k = 0)."""
    t, a, u = series["t"], series["acceleration"], series["command"]
    f = np.full_like(a, np.nan)
    f[1:] = np.diff(a) / np.diff(t) - b0 * u[:-1]
    return f


def observer_accuracy(series: dict[str, np.ndarray], b0: float) -> dict[str, float]:
    """Largest deviations of the ESO's z1, z2, z3 from true speed, acceleration and
    total disturbance."""
    f = total_disturbance(series, b0)
    disturbance = np.abs(series["z3"] - f)
    known = ~np.isnan(disturbance)  # f needs two samples: none from a one-step run
    return {
        "eso_speed_max_dev": float(np.max(np.abs(series["z1"] - series["speed"]))),
        "eso_acceleration_max_dev": float(np.max(np.abs(series["z2"] - series["acceleration"]))),
        "eso_disturbance_max_dev": float(np.max(disturbance[known])) if known.any() else np.nan,
    }


def step_overshoot(speed: np.ndarray, target: np.ndarray) -> float:
    """Peak beyond the final target, in percent of the step height."""
    height = target[-1] - speed[0]
    if height == 0:
        return 0.0
    return float(max(0.0, np.max((speed - target[-1]) * np.sign(height))) / abs(height) * 100.0)
