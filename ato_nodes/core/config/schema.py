"""The parameter schema shared by the ROS nodes and the in-process simulation.

Every parameter has one global name, a default, a type, a range or a set of
choices, a description (with its unit) and the nodes that declare it. The
run, line, plant and orchestration parameters are listed here; each
controller and profile kind brings its own group through its registry entry
(core/config/components.py). A parameter declared by several nodes is shared: a
scenario gives it under `/**`, so every node sees the same value. A plug-in's kinds
(core/config/plugins.py) join the schema when they are loaded (load_plugins): SPECS and
SPEC_BY_NAME are updated in place.
"""

from __future__ import annotations

from typing import Any

from ..base.errors import ScenarioError
from ..base.spec import MAX_PREVIEW, PLANT_NODES, PROFILE_NODES, ParamSpec, TextForm, param
from ..control.adrc import RETIRED_SWITCHES, retired_switch, switches_as_modes
from ..control.estimation import PARAMETERS as ESTIMATOR_PARAMETERS
from ..control.limiter import LIMITER_PARAMETERS
from ..control.localisation import LOCALISATION_PARAMETERS
from ..train.adhesion import PARAMETERS as ADHESION_PARAMETERS
from ..train.odometry import PARAMETERS as ODOMETRY_PARAMETERS
from ..targets.replan import PARAMETERS as REPLAN_PARAMETERS
from ..scoring.indices import RunningIndex
from . import plugins
from .components import CONTROLLERS, PROFILES, REGISTRIES

NODES = ("profile", "plant", "controller", "supervisor", "recorder")
LOOP_NODES = ("profile", "plant", "controller")
SUPERVISED_NODES = tuple(node for node in NODES if node != "supervisor")  # it waits for them
_UNSIGNED = r"(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_REQUIREMENT = rf"\s*\w+\s*<=\s*[-+]?{_UNSIGNED}\s*"
_BAND = rf"\s*{_UNSIGNED}\s*"
REQUIREMENTS_FORM = TextForm(rf"\s*|{_REQUIREMENT}(?:,{_REQUIREMENT})*",
                             "INDEX<=VALUE items separated by commas, e.g. "
                             "'max_abs_error_kmh<=1, overspeed_time<=0'")
BANDS_FORM = TextForm(rf"\s*|{_BAND}(?:,{_BAND})*",
                      "numbers of km/h separated by commas, e.g. '0.05, 0.4'")

BASE: tuple[ParamSpec, ...] = (
    param("run.plugins", "", "the plug-ins the run's nodes import before they read their "
          "other parameters (core/config/plugins.py): modules of controller or profile kinds "
          "from outside the package; a scenario's `plugins:` and --plugin add to it, and the "
          "plug-ins of the kinds the run uses (installed ones too) are added when it is "
          "checked, so a bag names them", NODES, form=plugins.REFERENCES_FORM),
    param("run.period", 0.05, "control period and lockstep step, s", NODES, 1e-4, 10.0),
    param("run.duration", 2400.0, "simulated run length, s", NODES, 1e-3, 1e7),
    param("run.last_stop_hold", 0.0, "a journey's run (profile.kind journey) ends once its "
          "train has stood this long at the timetable's last stop (at or past "
          "run.last_stop_position, at most 0.01 m/s either way: the scorer's standstill), "
          "rounded to whole periods; run.duration is then the longest it may last, s (0 = "
          "the run ends at run.duration)", "plant", 0.0, 3600.0),
    param("run.last_stop_position", 0.0, "where a journey's last stop begins for "
          "run.last_stop_hold: the timetable's last mark less profile.journey.berth, m; "
          "derived from the timetable when run.last_stop_hold > 0 (the launchers pass it to "
          "the plant)", "plant", -1e7, 1e7),
    param("run.real_time", False, "pace /clock at wall speed instead of as fast as possible",
          "plant"),
    param("run.record_lag", 1.0, "the plant runs at most this far (simulated time) ahead of "
          "what the recorder has on disk, so a killed recorder loses at most this much, s "
          "(0 = no limit)", ("plant", "recorder"), 0.0, 1e7),
    param("run.fault", "", "fault injection for testing supervision: NODE:KIND:STEP, KIND one "
          "of crash, hang, kill, diskfull (NODE one of profile, plant, controller, recorder)",
          NODES),
    param("line.file", "", "line file (msg_config/lines/*.yaml): gradients, curves, tunnels, "
          "limits, neutral sections, stations; relative to the scenario file, else to "
          "msg_config/; empty = open track", LOOP_NODES),
    param("line.end", 0.0, "the run's line ends here, m from the file's origin: its sections "
          "and stations beyond dropped, a tunnel across it kept whole (e.g. a track file's "
          "first interstation: its second stop's position); 0 = the file's end", LOOP_NODES,
          0.0, 2.0e6),
    param("line.planned_run_time", 0.0, "the running time the run is planned to and judged "
          "against, standstill to standstill, in place of the line file's planned_run_time: a "
          "service timetabled for another train (0 = the line file's), s", LOOP_NODES,
          0.0, 1e6),
    param("profile.approach_step", 0.0, "seed 003's stepped approach: when the target is more "
          "than this above the speed, approach it in stairs of this size, m/s (0 = off)",
          PROFILE_NODES, 0.0, 100.0),
    param("profile.berth", 0.0, "a train standing still less than this from the line's stop "
          "mark has arrived: its target is zero from then on, so the holding brake holds it "
          "(else a train stopped a few centimetres short creeps to the mark at the eased "
          "stop's last speeds, for seconds), m (0 = off); a position-indexed plan to a stop, "
          "not a journey (profile.journey.berth)", PROFILE_NODES, 0.0, 10.0),
    param("profile.envelope_share", 0.0, "plan traction and braking forces of at most this "
          "share of the nominal train's envelope, against its resistance (and the line's, "
          "for the ato curve), keeping the rest for the controller; the target falls behind "
          "a plan that asks more and catches up as it can (0 = the plan as given, the "
          "papers' setting); time-indexed profiles and the ato curve", PROFILE_NODES,
          0.0, 1.0),
    param("profile.jerk", 0.0, "round the target's acceleration changes to at most this "
          "jerk, m/s^3 (0 = the plan's corners, the papers' setting); time-indexed profiles "
          "and the ato curve", PROFILE_NODES, 0.0, 10.0),
    param("profile.departure_jerk", 0.0, "a position-indexed plan leaves standstill as the "
          "nominal train can follow: its target stays 0 for the train's dead time and "
          "actuator lag after each departure, then rises to the plan's start speed at most at "
          "this jerk, m/s^3, its acceleration zero at both ends (0 = the start speed at once, "
          "a target the standing train cannot follow; the papers' setting); the ato curve, "
          "the strategy and journeys", PROFILE_NODES, 0.0, 10.0),
    param("plant.train", "", "train preset (msg_config/trains/NAME.yaml), or a TTOBench train "
          "file (a .json path: relative to the scenario file, else msg_config/, e.g. "
          "ttobench/trains/CN_Beijing_Subway.json; kept as its absolute path), whose plant.* "
          "values the scenario starts from; the scenario's own plant.* values override it",
          PLANT_NODES),
    param("plant.gamma", 0.11, "rotating-mass coefficient", PLANT_NODES, 0.0, 1.0),
    param("plant.gravity", 9.8, "g, m/s^2 (seed 000's xi = 0.0098 / (1 + gamma))", PLANT_NODES,
          9.0, 10.5),
    param("plant.davis_a", 0.16, "basic resistance a, N/kN", PLANT_NODES, 0.0, 100.0),
    param("plant.davis_b", 0.0053, "basic resistance b, N/kN per m/s", PLANT_NODES, 0.0, 10.0),
    param("plant.davis_c", 0.0018, "basic resistance c, N/kN per (m/s)^2", PLANT_NODES, 0.0, 1.0),
    param("plant.mass", 388.4, "train mass, t (converts kN and kW envelopes to N/kN)", PLANT_NODES,
       1.0, 1e5),
    param("plant.disturbance.amplitude", 1.0 / 3.6, "phi(t) amplitude, m/s^2", PLANT_NODES,
          0.0, 10.0),
    param("plant.disturbance.frequency", 0.77, "phi(t) angular frequency, rad/s", PLANT_NODES,
          0.0, 1e3),
    param("plant.disturbance.phase", 0.0, "phi(t) phase, rad", PLANT_NODES, -10.0, 10.0),
    param("plant.envelope", False, "apply the traction/brake force and power limits", PLANT_NODES),
    param("plant.max_traction_force", 220.0, "traction force limit, kN", PLANT_NODES, 0.0, 1e5),
    param("plant.max_traction_power", 8760.0, "traction power limit, kW", PLANT_NODES, 0.0, 1e6),
    param("plant.max_brake_force", 213.6, "service brake force limit, kN", PLANT_NODES, 0.0, 1e5),
    param("plant.max_brake_power", 12000.0, "brake power limit, kW", PLANT_NODES, 0.0, 1e6),
    param("plant.actuator_lag", 0.0, "first-order traction/brake lag, s (0 = none)", PLANT_NODES,
       0.0, 10.0),
    param("plant.dead_time", 0.0, "traction/brake dead time, s (rounded to whole periods)",
       PLANT_NODES, 0.0, 10.0),
    param("plant.length", 0.0, "train length, m (mass belt over the line's sections; the ATO "
       "curve raises a limit once the tail has passed the change)", PLANT_NODES,
       0.0, 2000.0),
    param("plant.pantograph_offset", 0.0, "pantograph distance behind the head, m (neutral "
       "sections cut traction while it is inside them)", PLANT_NODES, 0.0, 2000.0),
    param("plant.hold_at_standstill", False, "the train cannot roll backwards: speed floors at 0 "
       "(brakes hold a stopped train)", PLANT_NODES),
    param("plant.resistance_factor", 1.0, "the real train's basic running resistance over the "
       "nominal one (plant.davis_*), which the controller and the profile know: a model "
       "error the ATO does not see (1 = the nominal train)", "plant", 0.1, 10.0),
    param("plant.mass_factor", 1.0, "the real train's mass over the nominal plant.mass (its "
       "load: the envelopes in kN and kW then give less specific force), unknown to the ATO",
       "plant", 0.1, 10.0),
    param("plant.davis_absolute", False, "the basic resistance in kN does not grow with the "
          "load: plant.mass_factor (and a weighed train.mass_reading) divide the specific "
          "Davis coefficients (N/kN) by the factor, as a TTOBench train's whole-train r0, r1, "
          "r2 are (its values set true; false = N/kN kept, the resistance in kN grows with "
          "the weight)", PLANT_NODES),
    param("plant.max_running_speed", 0.0, "the train's maximum speed: caps the line's speed "
          "limits for the plan and the scorer's overspeed alike (a TTOBench train's values "
          "set it), m/s (0 = none)", PLANT_NODES, 0.0, 1e3),
    param("plant.lag_factor", 1.0, "the real actuator lag over the nominal "
       "plant.actuator_lag, unknown to the ATO", "plant", 0.0, 10.0),
    param("train.load_weighing", False, "the ATO weighs its train at departure (air-spring "
          "load weighing) and plans and controls with the weighed mass: train.mass_reading is "
          "then plant.mass_factor read with a relative error (false = the ATO knows the mass "
          "train.mass_reading gives, the papers' setting)", "plant"),
    param("train.load_weighing_error", 0.03, "the load weighing's relative error, 1 sigma (a "
          "seeded normal draw; the on-board estimator's mass prior)", ("plant", *PROFILE_NODES),
          0.0, 0.5),
    param("train.load_weighing_bias", 0.0, "the load weighing's systematic error: its reading "
          "is the real mass times (1 + this) before its random error (load cells calibrated "
          "wrong; unknown to the ATO), e.g. -0.1 reads 10 % light", "plant", -0.9, 1.0),
    param("train.load_weighing_seed", 0, "seed of the load weighing's error draw", "plant",
          0, 2**31 - 1),
    param("train.load_weighing_max", 0.0, "the highest reading the load weighing gives, over "
          "the nominal plant.mass: the train's crush load, the top of the range the load "
          "cells are calibrated over (as for load-compensated brakes); a heavier reading, a "
          "heavy train read high, is clipped to it, and no plan is made for a heavier train "
          "(profile.replan) (0 = no ceiling)", ("plant", *PROFILE_NODES), 0.0, 10.0),
    param("train.mass_reading", 1.0, "the mass the ATO knows, over the nominal plant.mass: the "
          "plan's envelope share and the controllers' nominal model are the nominal train's at "
          "this mass, if heavier (the command limits are the nominal's); set from the load "
          "weighing when train.load_weighing (the launchers pass it to the nodes), else as "
          "given (1 = the nominal train)", PROFILE_NODES, 0.1, 10.0),
    param("plant.efficiency", 0.9, "drive efficiency for the energy indices (seed 002); read by "
       "the scorer from the bag's run parameters", PLANT_NODES, 0.01, 1.0),
    param("plant.regenerative_limits", False, "the drive regenerates braking only up to "
          "min(plant.regenerative_force, plant.regenerative_power / v), the rest is pneumatic "
          "and regenerates nothing (false = all braking regenerative); read by the scorer",
          PLANT_NODES),
    param("plant.regenerative_force", 213.6, "regenerative braking force limit, kN (the real "
          "train's, at any load)", PLANT_NODES, 0.0, 1e5),
    param("plant.regenerative_power", 12000.0, "regenerative braking power limit, kW",
          PLANT_NODES, 0.0, 1e6),
    param("plant.regenerative_efficiency", 0.0, "share of the regenerative braking energy "
          "returned to the supply (0 = plant.efficiency, one efficiency both ways); read by "
          "the scorer", PLANT_NODES, 0.0, 1.0),
    param("plant.speed_noise", 0.0, "speed sensor noise, standard deviation, m/s", PLANT_NODES,
       0.0, 10.0),
    param("plant.speed_quantum", 0.0, "speed sensor resolution, m/s (0 = exact)", PLANT_NODES,
       0.0, 10.0),
    param("plant.noise_seed", 0, "seed of the speed sensor noise (same seed, same run)",
          PLANT_NODES,
       0, 2**31 - 1),
    param("plant.substeps", 1, "RK4 sub-steps per control period", PLANT_NODES, 1, 10000),
    param("plant.max_speed", 200.0, "speed beyond which a run counts as diverged and ends, m/s",
       PLANT_NODES, 1.0, 1e4),
    param("plant.initial_speed", 0.0, "speed at t = 0, m/s", PLANT_NODES, 0.0, 300.0),
    param("plant.initial_position", 0.0, "position at t = 0, m", PLANT_NODES, -1e7, 1e7),
    param("controller.preview", 0, "steps of target preview: the profile sends the controller "
          "the horizon r_k .. r_k+N (the planned target; along the planned trajectory for "
          "position-indexed targets); every kind is given r_k as its target and the horizon, "
          "and the shipped kinds track its end r_k+N (0 = r_k, the papers' setting)",
          ("profile", "controller"), 0, MAX_PREVIEW),
    *LIMITER_PARAMETERS,
    *ESTIMATOR_PARAMETERS,
    *ADHESION_PARAMETERS,
    *ODOMETRY_PARAMETERS,
    *LOCALISATION_PARAMETERS,
    *REPLAN_PARAMETERS,
    param("supervisor.ready_timeout", 30.0, "wall seconds to wait for every edge to match",
          "supervisor", 0.1, 3600.0),
    param("supervisor.report", "", "path of the JSON run report the supervisor writes",
          "supervisor"),
    param("supervisor.fitness", "", "running fitness the supervisor computes and publishes on "
          "/ato/running_fitness: itae, iae or max_abs_error ('' = none)", "supervisor",
          choices=("", *RunningIndex.MONOTONE)),
    param("supervisor.prune_above", 0.0, "end the run as pruned once the running fitness "
          "passes this (a tuner's bound; 0 = never)", "supervisor", 0.0, 1e300),
    param("recorder.output", "", "bag directory to create (must not exist)", "recorder"),
    # What the run is judged against (scripts/analyze.py's verdict): declared by the loop's
    # nodes, whose values the bag keeps, so that a bag carries its own targets.
    param("report.require", "", "the run's requirements, each index of the scorer at most "
          "a value in the index's unit (tune.py --require's form): the report's verdict "
          "passes or fails each ('' = none)", LOOP_NODES, form=REQUIREMENTS_FORM),
    param("report.error_bands", "", "reference bands +-X km/h the report draws on the "
          "tracking error ('' = none)", LOOP_NODES, form=BANDS_FORM),
)


def _all_specs() -> list[ParamSpec]:
    return [*BASE, *PROFILES.parameters(), *CONTROLLERS.parameters()]


# Lists and a dict updated in place when a plug-in's kinds join (load_plugins), so that
# every module that imported them sees the plug-ins' parameters.
SPECS: list[ParamSpec] = _all_specs()
SPEC_BY_NAME = {spec.name: spec for spec in SPECS}
if len(SPEC_BY_NAME) != len(SPECS):
    raise ValueError("a parameter name is defined twice in the schema")


def load_plugins(named: str | tuple[str, ...] = ()) -> None:
    """Import the installed plug-ins (those not imported yet) and those `named` (run.plugins's
    text, or references), and add their kinds' parameters to the schema.
    ScenarioError (one line) for a plug-in refused."""
    if isinstance(named, str):
        named = plugins.references(named)
    if plugins.load(named, SPEC_BY_NAME):
        SPECS[:] = _all_specs()
        SPEC_BY_NAME.clear()
        SPEC_BY_NAME.update({spec.name: spec for spec in SPECS})


try:  # the installed plug-ins' kinds join as the schema is built: every process has them
    load_plugins()
except ScenarioError:
    pass  # said again, in one line, by the first run this process checks (load_plugins)


def run_plugins(values) -> str:
    """run.plugins's text for a run: the plug-ins it names, and those whose kinds it
    uses."""
    used = (plugins.provider(role, values[registry.kind_parameter.name])
            for role, registry in REGISTRIES.items())
    return plugins.joined((*plugins.references(values["run.plugins"]),
                           *(reference for reference in used if reference)))
# resolved to absolute paths
FILE_PARAMETERS = ("profile.table.file", "profile.strategy.file", "line.file", "gpc.model",
                   "profile.journey.timetable")


def retired(name: str, value: Any) -> str | None:
    """The line for a parameter retired from the schema given as `value` (the linear ADRC's
    old switches, now modes): what to give instead; None for anything else."""
    return retired_switch(name, value)


RETIRED_NAMES = frozenset(RETIRED_SWITCHES) - set(SPEC_BY_NAME)  # gone from the schema


def upgraded(values: dict[str, Any]) -> dict[str, Any]:
    """A run's values as an older version recorded them (a bag's), with what took the
    place of the parameters retired since (the linear ADRC's switches: its modes)."""
    return switches_as_modes(values)


def defaults() -> dict[str, Any]:
    return {spec.name: spec.default for spec in SPECS}


def unused(values) -> dict[str, str]:
    """The parameters of the controller and profile kinds a run's `values` do not choose,
    each with the line that says so (core.registry.Registry.unused)."""
    return {**PROFILES.unused(values), **CONTROLLERS.unused(values)}


def for_node(node: str, values=None) -> list[ParamSpec]:
    """The parameters `node` may declare; given a run's `values`, those it declares: none
    of the kinds the run does not use."""
    skipped = unused(values) if values is not None else {}
    return [spec for spec in SPECS if node in spec.nodes and spec.name not in skipped]


def shared(spec: ParamSpec) -> bool:
    """Declared by several nodes: it must reach them all alike (under /** in a file)."""
    return len(spec.nodes) > 1


class NodeValues(dict):
    """A node's parameter values: exactly what the node declares for the run (no
    parameter of a kind the run does not use). Reading anything else is a start-up
    error, in the node and in simulate() alike."""

    def __init__(self, node: str, values: dict[str, Any]):
        # a process that builds a stage from a run's values imports its plug-ins first
        # (a study's worker, a resimulation): its kinds are known wherever it runs
        load_plugins(values.get("run.plugins", ""))
        for name in RETIRED_NAMES & values.keys():  # values written for an older schema
            raise ScenarioError(f"{node}: {retired(name, values[name])}")
        super().__init__({spec.name: values[spec.name] for spec in for_node(node, values)})
        self.node = node
        self.unused = unused(values)

    def __missing__(self, name: str):
        if name in self.unused:
            raise ScenarioError(f"{self.node}: {self.unused[name]}")
        raise ScenarioError(f"{self.node}: parameter {name!r} is not declared by the {self.node} "
                            f"node")


def recording_steps(values) -> tuple[int, int | None]:
    """(steps per flushed block of the bag, steps the plant may run ahead of the last
    flushed block, None = no limit): blocks of half run.record_lag (0.5 s without a
    limit), so the plant always has a block of room and never waits for ever."""
    lag, period = values["run.record_lag"], values["run.period"]
    block = max(1, round((lag if lag > 0 else 1.0) / 2 / period))
    return block, (max(round(lag / period), 2 * block) if lag > 0 else None)


def steps(values) -> int:
    """Number of lockstep steps of a run."""
    return int(round(values["run.duration"] / values["run.period"]))
