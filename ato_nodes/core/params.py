"""Parameter schema shared by the ROS nodes and the in-process simulation.

Every parameter has one global name, a default, a type, a range or a set of
choices, a description (with its unit) and the nodes that declare it.
Scenario files are ROS 2 parameter files (node name -> ros__parameters, with
`/**` for parameters every node shares), so the same file feeds `--params-file`
and the in-process simulation, and a parameter is checked here before any
process starts.
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

NODES = ("profile", "plant", "controller", "supervisor", "recorder")
ALL = NODES


class ScenarioError(ValueError):
    """A scenario or parameter problem, reported to the user as one line."""


@dataclass(frozen=True)
class ParamSpec:
    name: str
    default: Any
    description: str
    nodes: tuple[str, ...]
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] | None = None

    @property
    def kind(self) -> type:
        return type(self.default)

    def check(self, value: Any, where: str = "") -> Any:
        """Return `value` converted to this parameter's type, or raise ScenarioError."""
        prefix = f"{where}: " if where else ""
        kind = self.kind
        if kind is bool:
            if not isinstance(value, bool):
                raise ScenarioError(f"{prefix}{self.name} must be true or false, not {value!r}")
        elif kind is int:
            if isinstance(value, bool) or not isinstance(value, int):
                raise ScenarioError(f"{prefix}{self.name} must be an integer, not {value!r}")
        elif kind is float:
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ScenarioError(f"{prefix}{self.name} must be a number, not {value!r}")
            value = float(value)
            if not math.isfinite(value):
                raise ScenarioError(f"{prefix}{self.name} must be finite, not {value!r}")
        elif not isinstance(value, str):
            raise ScenarioError(f"{prefix}{self.name} must be a string, not {value!r}")
        if self.choices is not None and value not in self.choices:
            raise ScenarioError(f"{prefix}{self.name} must be one of {', '.join(self.choices)}; "
                                f"got {value!r}")
        if self.low is not None and not (self.low <= value <= self.high):
            raise ScenarioError(f"{prefix}{self.name} = {value} is out of range "
                                f"[{self.low:g}, {self.high:g}]")
        return value


def _p(name, default, description, nodes, low=None, high=None, choices=None) -> ParamSpec:
    if isinstance(nodes, str):
        nodes = (nodes,)
    return ParamSpec(name, default, description, tuple(nodes), low, high, choices)


KMH = 1.0 / 3.6

SPECS: tuple[ParamSpec, ...] = (
    # Shared by the loop.
    _p("run.period", 0.05, "control period and lockstep step, s", ALL, 1e-4, 10.0),
    _p("run.duration", 2400.0, "simulated run length, s", ALL, 1e-3, 1e7),
    _p("run.real_time", False, "pace /clock at wall speed instead of as fast as possible",
       "plant"),
    _p("run.fault", "", "fault injection for testing supervision: NODE:crash:STEP or "
       "NODE:hang:STEP (NODE one of profile, plant, controller, recorder)", ALL),
    _p("line.file", "", "line file (msg_config/lines/*.yaml): gradients, curves, tunnels, "
       "limits, neutral sections, stations; relative to the scenario file; empty = open track",
       ("profile", "plant")),
    # Target-speed profile.
    _p("profile.kind", "seed000", "target curve: seed000 (eq. 25), step, table (CSV), or ato "
       "(distance-indexed curve from the line's limits, braking and planned run time)",
       "profile", choices=("seed000", "step", "table", "ato")),
    _p("profile.ato.acceleration", 0.8, "ATO curve: planned acceleration, m/s^2", "profile",
       0.01, 5.0),
    _p("profile.ato.power_speed", 0.0, "ATO curve: above this speed the planned acceleration "
       "falls as 1/v (constant power), m/s (0 = constant acceleration)", "profile", 0.0, 300.0),
    _p("profile.ato.deceleration", 0.8, "ATO curve: planned service braking, m/s^2", "profile",
       0.01, 5.0),
    _p("profile.ato.stop_jerk", 0.0, "ATO curve: the braking into the stop mark eases off at "
       "this jerk, m/s^3 (0 = full service braking to the mark)", "profile", 0.0, 10.0),
    _p("profile.ato.margin", 5.0 * KMH, "ATO curve: distance kept below the line limit, m/s",
       "profile", 0.0, 50.0),
    _p("profile.ato.start_speed", 0.3, "ATO curve: target at the departure point (a position-"
       "indexed curve is 0 there and would never start the train), m/s", "profile", 0.01, 10.0),
    _p("profile.approach_step", 0.0, "seed 003's stepped approach: when the target is more "
       "than this above the speed, approach it in stairs of this size, m/s (0 = off)",
       "profile", 0.0, 100.0),
    _p("profile.seed000.cycle", 1200.0, "T of eq. 25, s", "profile", 1.0, 1e6),
    _p("profile.seed000.v_inc", 368.34 * KMH, "Vinc of eq. 25, m/s", "profile", 0.0, 300.0),
    _p("profile.seed000.t1", 125.2841, "t1 of eq. 25, s", "profile", 0.0, 1e6),
    _p("profile.seed000.cruise_high", 350.0 * KMH, "upper cruise speed, m/s", "profile", 0.0, 300.0),
    _p("profile.seed000.cruise_low", 200.0 * KMH, "lower cruise speed, m/s", "profile", 0.0, 300.0),
    _p("profile.step.speed", 10.0 * KMH, "step height, m/s", "profile", 0.0, 300.0),
    _p("profile.step.time", 0.0, "step instant, s", "profile", 0.0, 1e7),
    _p("profile.table.file", "", "CSV table (time|position,speed); relative to the scenario file",
       "profile"),
    # Train plant.
    _p("plant.train", "", "train preset (msg_config/trains/NAME.yaml) whose plant.* values "
       "the scenario starts from; the scenario's own plant.* values override it", "plant"),
    _p("plant.gamma", 0.11, "rotating-mass coefficient", "plant", 0.0, 1.0),
    _p("plant.gravity", 9.8, "g, m/s^2 (seed 000's xi = 0.0098 / (1 + gamma))", "plant", 9.0, 10.5),
    _p("plant.davis_a", 0.16, "basic resistance a, N/kN", "plant", 0.0, 100.0),
    _p("plant.davis_b", 0.0053, "basic resistance b, N/kN per m/s", "plant", 0.0, 10.0),
    _p("plant.davis_c", 0.0018, "basic resistance c, N/kN per (m/s)^2", "plant", 0.0, 1.0),
    _p("plant.mass", 388.4, "train mass, t (converts kN and kW envelopes to N/kN)", "plant",
       1.0, 1e5),
    _p("plant.disturbance.amplitude", 1.0 / 3.6, "phi(t) amplitude, m/s^2", "plant", 0.0, 10.0),
    _p("plant.disturbance.frequency", 0.77, "phi(t) angular frequency, rad/s", "plant", 0.0, 1e3),
    _p("plant.disturbance.phase", 0.0, "phi(t) phase, rad", "plant", -10.0, 10.0),
    _p("plant.envelope", False, "apply the traction/brake force and power limits", "plant"),
    _p("plant.max_traction_force", 220.0, "traction force limit, kN", "plant", 0.0, 1e5),
    _p("plant.max_traction_power", 8760.0, "traction power limit, kW", "plant", 0.0, 1e6),
    _p("plant.max_brake_force", 213.6, "service brake force limit, kN", "plant", 0.0, 1e5),
    _p("plant.max_brake_power", 12000.0, "brake power limit, kW", "plant", 0.0, 1e6),
    _p("plant.actuator_lag", 0.0, "first-order traction/brake lag, s (0 = none)", "plant",
       0.0, 10.0),
    _p("plant.dead_time", 0.0, "traction/brake dead time, s (rounded to whole periods)",
       "plant", 0.0, 10.0),
    _p("plant.length", 0.0, "train length, m (mass belt over the line's sections; the ATO "
       "curve raises a limit once the tail has passed the change)", ("plant", "profile"),
       0.0, 2000.0),
    _p("plant.pantograph_offset", 0.0, "pantograph distance behind the head, m (neutral "
       "sections cut traction while it is inside them)", "plant", 0.0, 2000.0),
    _p("plant.hold_at_standstill", False, "the train cannot roll backwards: speed floors at 0 "
       "(brakes hold a stopped train)", "plant"),
    _p("plant.efficiency", 0.9, "drive efficiency for the energy indices (seed 002); read by "
       "the scorer from the bag's run parameters, no node uses it", (), 0.01, 1.0),
    _p("plant.speed_noise", 0.0, "speed sensor noise, standard deviation, m/s", "plant",
       0.0, 10.0),
    _p("plant.speed_quantum", 0.0, "speed sensor resolution, m/s (0 = exact)", "plant",
       0.0, 10.0),
    _p("plant.noise_seed", 0, "seed of the speed sensor noise (same seed, same run)", "plant",
       0, 2**31 - 1),
    _p("plant.substeps", 1, "RK4 sub-steps per control period", "plant", 1, 10000),
    _p("plant.max_speed", 200.0, "speed beyond which a run counts as diverged and ends, m/s",
       "plant", 1.0, 1e4),
    _p("plant.initial_speed", 0.0, "speed at t = 0, m/s", "plant", 0.0, 300.0),
    _p("plant.initial_position", 0.0, "position at t = 0, m", "plant", -1e7, 1e7),
    # Controller.
    _p("controller.kind", "han_adrc", "han_adrc (seed 000), nladrc (seed 003), discrete_adrc "
       "(seed 004) or linear_adrc", "controller",
       choices=("han_adrc", "nladrc", "discrete_adrc", "linear_adrc")),
    _p("controller.preview", 0, "steps of target preview: 0 = the TD tracks r_k (paper), "
       "1 = r_k+1, the target at the end of the interval the command acts over",
       "controller", 0, 1),
    _p("controller.u_min", -1e6, "lowest command (braking), N/kN", "controller", -1e9, 0.0),
    _p("controller.u_max", 1e6, "highest command (traction), N/kN", "controller", 0.0, 1e9),
    _p("controller.max_rate", 0.0, "jerk limit: largest change of the command per second, "
       "N/kN/s (0 = none)", "controller", 0.0, 1e9),
    _p("controller.mode_band", 0.0, "speed-limit module (seed 003): no traction while the speed "
       "is more than this above the target, no braking while more than this below, m/s "
       "(0 = off)", "controller", 0.0, 100.0),
    _p("controller.holding_brake", 0.0, "braking held with a zero target once the train is "
       "stopped (station berth), N/kN (0 = none)", "controller", 0.0, 1e6),
    _p("adrc.mu1", 6000.0, "NLSEF gain on e1", "controller", 0.0, 1e9),
    _p("adrc.mu2", 5500.0, "NLSEF gain on e2", "controller", 0.0, 1e9),
    _p("adrc.alpha1", 0.75, "NLSEF exponent on e1", "controller", 0.0, 3.0),
    _p("adrc.alpha2", 1.5, "NLSEF exponent on e2", "controller", 0.0, 3.0),
    _p("adrc.r0", 5.0, "TD speed factor, m/s^2", "controller", 1e-6, 1e6),
    _p("adrc.h0", 0.001, "TD filter factor, s", "controller", 1e-6, 10.0),
    _p("adrc.beta1", 1200.0, "ESO gain beta1", "controller", 0.0, 1e9),
    _p("adrc.beta2", 1700.0, "ESO gain beta2", "controller", 0.0, 1e9),
    _p("adrc.beta3", 4500.0, "ESO gain beta3", "controller", 0.0, 1e9),
    _p("adrc.b0", 0.1766, "compensation factor b0 (not in the paper; ~xi / 50 ms, see README)",
       "controller", 1e-9, 1e9),
    _p("adrc.delta", 0.01, "fal linear-zone half width", "controller", 1e-9, 100.0),
    _p("adrc.implicit_nlsef", True, "implicit NLSEF discretisation (false: literal law)",
       "controller"),
    _p("ladrc.omega_o", 20.0, "linear ADRC observer bandwidth, rad/s", "controller", 1e-6, 1e6),
    _p("ladrc.omega_c", 2.0, "linear ADRC controller bandwidth, rad/s", "controller", 1e-6, 1e6),
    _p("ladrc.b0", 0.0098 / 1.11, "linear ADRC input gain, m/s^2 per N/kN", "controller",
       1e-9, 1e9),
    _p("nladrc.kp", 2.0, "seed 003 NLADRC: proportional gain of the nonlinear PD", "controller",
       0.0, 1e6),
    _p("nladrc.kd", 1.0, "seed 003 NLADRC: derivative gain of the nonlinear PD", "controller",
       0.0, 1e6),
    _p("nladrc.omega", 10.0, "seed 003 NLADRC: observer bandwidth w (b01 = 3w, b02 = 3w^2, "
       "b03 = w^3), rad/s", "controller", 1e-3, 1e4),
    _p("nladrc.b", 0.5, "seed 003 NLADRC: compensation factor b", "controller", 1e-9, 1e9),
    _p("nladrc.alpha1", 0.75, "seed 003 NLADRC: fal exponent on e1", "controller", 0.0, 3.0),
    _p("nladrc.alpha2", 1.25, "seed 003 NLADRC: fal exponent on e2", "controller", 0.0, 3.0),
    _p("nladrc.delta", 0.01, "seed 003 NLADRC: fal linear zone", "controller", 1e-9, 100.0),
    _p("nladrc.r0", 15.0, "seed 003 NLADRC: TD speed factor r", "controller", 1e-6, 1e6),
    _p("nladrc.h0", 0.01, "seed 003 NLADRC: TD filter factor h0, s", "controller", 1e-6, 10.0),
    _p("dadrc.b01", 0.9, "seed 004 discrete ESO gain b01 (per step)", "controller", 0.0, 3.0),
    _p("dadrc.b02", 0.03, "seed 004 discrete ESO gain b02 (per step)", "controller", 0.0, 3.0),
    _p("dadrc.b03", 0.001, "seed 004 discrete ESO gain b03 (per step)", "controller", 0.0, 3.0),
    _p("dadrc.b1", 40.0, "seed 004 NLSEF gain on e1, N/kN per (m/s)^a1", "controller", 0.0, 1e6),
    _p("dadrc.b2", 100.0, "seed 004 NLSEF gain on e2, N/kN per (m/s per step)^a2",
       "controller", 0.0, 1e6),
    _p("dadrc.alpha1", 0.75, "seed 004 NLSEF exponent a1 in (0, 1)", "controller", 0.01, 1.0),
    _p("dadrc.alpha2", 0.5, "seed 004 NLSEF exponent a2 in (0, 1)", "controller", 0.01, 1.0),
    _p("dadrc.b0", 1e-4, "seed 004 input gain b0 per step^2 (xi h^2 / lag)", "controller",
       1e-12, 1e3),
    _p("dadrc.delta", 0.01, "seed 004 fal linear zone (below 0.0025 chatters)", "controller",
       1e-6, 10.0),
    _p("dadrc.r0", 2.0, "seed 004 TD speed factor, m/s^2", "controller", 1e-6, 1e6),
    _p("dadrc.h0", 0.1, "seed 004 TD filter factor, s", "controller", 1e-6, 10.0),
    # Orchestration.
    _p("supervisor.ready_timeout", 30.0, "wall seconds to wait for every edge to match",
       "supervisor", 0.1, 3600.0),
    _p("supervisor.report", "", "path of the JSON run report the supervisor writes",
       "supervisor"),
    _p("recorder.output", "", "bag directory to create (must not exist)", "recorder"),
    _p("recorder.run_parameters", "", "JSON of the whole run's parameters, kept in the bag's "
       "metadata (custom_data) so a bag explains itself", "recorder"),
)

SPEC_BY_NAME = {spec.name: spec for spec in SPECS}


def defaults() -> dict[str, Any]:
    return {spec.name: spec.default for spec in SPECS}


def for_node(node: str) -> list[ParamSpec]:
    return [spec for spec in SPECS if node in spec.nodes]


def _unknown(name: str, where: str) -> ScenarioError:
    close = difflib.get_close_matches(name, SPEC_BY_NAME, n=1)
    hint = f" (did you mean {close[0]}?)" if close else ""
    return ScenarioError(f"{where}: unknown parameter {name!r}{hint}")


def config_dir() -> Path:
    """msg_config/ of the source tree, or of the installed ament package."""
    source = Path(__file__).resolve().parents[2] / "msg_config"
    if source.is_dir():
        return source
    try:
        from ament_index_python.packages import get_package_share_directory
        return Path(get_package_share_directory("ato_nodes")) / "msg_config"
    except (ImportError, LookupError):
        return source


def scenario_names() -> list[str]:
    return sorted(p.stem for p in (config_dir() / "scenarios").glob("*.yaml"))


def resolve_scenario(name_or_file: str) -> Path:
    path = Path(name_or_file)
    if path.suffix in (".yaml", ".yml") or path.exists():
        if not path.is_file():
            raise ScenarioError(f"scenario file {name_or_file} does not exist")
        return path
    candidate = config_dir() / "scenarios" / f"{name_or_file}.yaml"
    if candidate.is_file():
        return candidate
    raise ScenarioError(f"unknown scenario {name_or_file!r}; known: {', '.join(scenario_names())}")


def load_scenario(name_or_file: str) -> dict[str, Any]:
    """All parameters of a scenario: defaults overlaid with the file's values, checked."""
    path = resolve_scenario(name_or_file)
    try:
        document = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f" line {mark.line + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or "not valid YAML"
        raise ScenarioError(f"{path}{at}: malformed YAML ({problem})") from None
    except OSError as exc:
        raise ScenarioError(f"cannot read scenario {path}: {exc.strerror}") from None
    if not isinstance(document, dict):
        raise ScenarioError(f"{path}: expected a ROS 2 parameter file (node: ros__parameters: ...)")
    given = {}
    for node, section in document.items():
        if node != "/**" and node not in NODES:
            raise ScenarioError(f"{path}: unknown node {node!r}; nodes are /**, {', '.join(NODES)}")
        if not isinstance(section, dict) or not isinstance(section.get("ros__parameters"), dict):
            raise ScenarioError(f"{path}: {node} needs a 'ros__parameters:' mapping")
        for name, value in _flatten(section["ros__parameters"]).items():
            spec = SPEC_BY_NAME.get(name)
            if spec is None:
                raise _unknown(name, str(path))
            if node != "/**" and node not in spec.nodes:
                owners = ", ".join(spec.nodes) or "/** (no node uses it; the scorer reads it)"
                raise ScenarioError(f"{path}: {name} belongs to {owners}, not {node}")
            value = spec.check(value, str(path))
            if name in given and given[name] != value:
                raise ScenarioError(f"{path}: {name} is given twice, as {given[name]!r} and "
                                    f"{value!r}")
            given[name] = value
    for name in FILE_PARAMETERS:
        if given.get(name) and not Path(given[name]).is_absolute():
            local = path.parent / given[name]
            given[name] = str((local if local.exists() else config_dir() / given[name]).resolve())
    values = defaults()
    if given.get("plant.train"):
        values.update(train_preset(given["plant.train"]))
    values.update(given)
    return check_consistency(values, str(path))


FILE_PARAMETERS = ("profile.table.file", "line.file")  # relative to the scenario file, else
#                                                        to msg_config/


def train_names() -> list[str]:
    return sorted(p.stem for p in (config_dir() / "trains").glob("*.yaml"))


def train_preset(name: str) -> dict[str, Any]:
    """The plant.* values of msg_config/trains/NAME.yaml (a flat mapping), checked."""
    path = config_dir() / "trains" / f"{name}.yaml"
    if not path.is_file():
        raise ScenarioError(f"unknown train {name!r}; known: {', '.join(train_names())}")
    try:
        document = yaml.safe_load(path.read_text())
    except yaml.YAMLError:
        raise ScenarioError(f"{path}: malformed YAML") from None
    if not isinstance(document, dict):
        raise ScenarioError(f"{path}: a train preset is a mapping of plant.* values")
    values = {}
    for key, value in document.items():
        spec = SPEC_BY_NAME.get(key)
        if spec is None or "plant" not in spec.nodes or key == "plant.train":
            raise ScenarioError(f"{path}: {key!r} is not a plant parameter")
        values[key] = spec.check(value, str(path))
    return {**values, "plant.train": name}


def _flatten(mapping: dict, prefix: str = "") -> dict[str, Any]:
    """ROS parameter files may nest dotted names; flatten them back."""
    flat = {}
    for key, value in mapping.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(_flatten(value, name + "."))
        else:
            flat[name] = value
    return flat


def parse_override(text: str) -> tuple[str, Any]:
    """`name=value` with the value read as YAML (numbers, true/false, strings)."""
    name, sep, raw = text.partition("=")
    name = name.strip()
    if not sep or not name:
        raise ScenarioError(f"--set expects name=value, got {text!r}")
    spec = SPEC_BY_NAME.get(name)
    if spec is None:
        raise _unknown(name, "--set")
    try:
        value = yaml.safe_load(raw) if raw.strip() else ""
    except yaml.YAMLError:
        value = raw
    if spec.kind is str and value is not None and not isinstance(value, str):
        value = raw.strip()
    return name, spec.check(value, "--set")


def apply_overrides(values: dict[str, Any], overrides: list[str] | dict[str, Any]) -> dict[str, Any]:
    if isinstance(overrides, dict):
        checked = {}
        for name, value in overrides.items():
            spec = SPEC_BY_NAME.get(name)
            if spec is None:
                raise _unknown(name, "override")
            checked[name] = spec.check(value, "override")
        overrides = checked
    else:
        overrides = dict(parse_override(text) for text in overrides)
    for name in FILE_PARAMETERS:  # relative: from the working directory, else msg_config/
        given = overrides.get(name)
        if given and not Path(given).is_absolute():  # the nodes run elsewhere: absolute
            local = Path(given)
            overrides[name] = str((local if local.exists() else config_dir() / given).resolve())
    merged = {**values, **overrides}
    if overrides.get("plant.train"):  # a new train: its preset, then the other overrides
        merged.update(train_preset(overrides["plant.train"]))
        merged.update(overrides)
    return check_consistency(merged, "parameters")


def check_consistency(values: dict[str, Any], where: str) -> dict[str, Any]:
    if values["run.duration"] < values["run.period"]:
        raise ScenarioError(f"{where}: run.duration must be at least one run.period")
    if values["profile.kind"] == "table" and not values["profile.table.file"]:
        raise ScenarioError(f"{where}: profile.kind is table but profile.table.file is empty")
    if values["profile.kind"] == "ato" and not values["line.file"]:
        raise ScenarioError(f"{where}: profile.kind is ato but line.file is empty")
    if values["line.file"]:
        from .line import load_line  # validated before any node starts; errors name file:line
        line = load_line(values["line.file"])
        if values["profile.kind"] == "ato" and line.stop_position <= 0.0:
            raise ScenarioError(f"{where}: the ato profile needs a stop beyond the departure "
                                f"point; {values['line.file']} stops at 0 m")
    try:
        parse_fault(values["run.fault"])
    except ScenarioError as exc:
        raise ScenarioError(f"{where}: {exc}") from None
    return values


FAULT_NODES = ("profile", "plant", "controller", "recorder")


def parse_fault(text: str) -> tuple[str, str, int] | None:
    """run.fault as (node, 'crash' | 'hang', step), or None when empty."""
    if not text:
        return None
    parts = text.split(":")
    if (len(parts) != 3 or parts[0] not in FAULT_NODES or parts[1] not in ("crash", "hang")
            or not parts[2].isdigit()):
        raise ScenarioError(f"run.fault must be NODE:crash|hang:STEP with NODE one of "
                            f"{', '.join(FAULT_NODES)}; got {text!r}")
    return parts[0], parts[1], int(parts[2])


def steps(values: dict[str, Any]) -> int:
    """Number of lockstep steps of a run."""
    return int(round(values["run.duration"] / values["run.period"]))


def ros_parameter_file(values: dict[str, Any]) -> dict[str, Any]:
    """The values as a ROS 2 parameter file, each node given only what it declares."""
    return {node: {"ros__parameters": {spec.name: values[spec.name] for spec in for_node(node)}}
            for node in NODES}
