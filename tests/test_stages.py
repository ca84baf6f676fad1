"""The nodes' three stages, driven one step at a time as the nodes drive them, give the
bits of simulate()'s loop (compiled, and as Python), live gain changes included."""

import numpy as np
import pytest

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.context import RunContext
from ato_nodes.core.config.scenario import apply_overrides, load_scenario
from ato_nodes.core.config.schema import NodeValues, steps
from ato_nodes.core.run.located import ODOMETRY_SERIES
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.run.stages import SERIES, ControllerStage, PlantStage, ProfileStage


def staged_run(values, changes=None):
    """The run as the plant, profile and controller nodes make it: each stage built from
    its node's values, called with what its topics carry, in the order they arrive."""
    profile = ProfileStage(NodeValues("profile", values))
    plant = PlantStage(NodeValues("plant", values))
    controller = ControllerStage(NodeValues("controller", values))
    rows, extras, horizons, located = [], [], [], []
    for k in range(steps(values)):
        out = plant.outputs()  # published: measured speed, position, state
        # the adhesion seen and the located speed, from the odometry topic
        seen, speed = (out.odometry[SEEN], out.odometry[LOCATED_SPEED]) if out.odometry else (
            np.nan, np.nan)
        # with the re-plan, the controller's estimate after the step before (as the node
        # pairs /ato/controller_state with the position)
        mass, mass_sigma = (np.nan, np.nan)
        if values["profile.replan.enabled"] and extras:
            names = controller.output_names
            mass = extras[-1][names.index("mass_factor")]
            mass_sigma = extras[-1][names.index("mass_sigma")]
        controller.horizons.extend(profile.on_position(out.located_position, mass, mass_sigma,
                                                       seen, speed))
        horizon = controller.horizons[0]
        controller.speeds.append(out.measured_speed)
        if controller.efforts is not None:  # controller.slip_hold: /train/drive_effort
            controller.efforts.append(out.drive_effort)
        if changes and k in changes:  # `ros2 param set` between two steps
            controller.pending.update(changes[k])
        (command,) = controller.run_ready_steps()
        plant.apply(command.u)
        rows.append((k * values["run.period"], horizon[0], out.position, out.measured_speed,
                     out.speed, out.acceleration, out.disturbance, out.force, out.resistance,
                     out.line_resistance, profile.speed_limit(out.located_position), command.u))
        extras.append(command.extras)
        located.append(out.odometry)
        horizons.append(horizon)
        if plant.diverged or plant.arrived:
            break
    names = controller.output_names
    series = dict(zip(SERIES, np.array(rows, dtype=float).reshape(-1, len(SERIES)).T,
                      strict=True))
    series.update(zip(names, np.array(extras, dtype=float).reshape(-1, len(names)).T,
                      strict=True))
    series["preview"] = np.array(horizons, dtype=float)
    if values["odometry.enabled"]:
        series.update(zip(ODOMETRY_SERIES, np.array(located, dtype=float).T, strict=True))
    return series


SEEN = ODOMETRY_SERIES.index("adhesion_seen")
LOCATED_SPEED = ODOMETRY_SERIES.index("located_speed")

RUNS = [
    ("seed000", ["run.duration=60"], None),  # time-indexed, Han's ADRC
    ("seed000-realistic", ["run.duration=60"], None),  # lag, envelope, noisy quantised sensor
    ("seed003-maglev", ["run.duration=60"], None),  # the stepped approach, dead time
    ("seed002-hsr-ato", ["run.duration=120", "ladrc.plan_lead=15"], None),  # a line, limits
    ("seed004-metro-line", ["run.duration=150"], None),  # a journey: dwell, departure
    ("seed001-crh380al", ["run.duration=30", "gpc.prediction=mechanistic"], None),
    ("seed000-pid", ["run.duration=60"], {100: {"pid.kp": 80.0}, 300: {"pid.ki": 2.0}}),
    ("seed004-metro-ato", ["run.duration=60"], {0: {"ladrc.omega_c": 3.0},
                                                 250: {"ladrc.omega_o": 9.0}}),
    ("seed000", ["run.duration=60", "profile.approach_step=0.5"], None),  # time-indexed, stairs
    ("seed000", ["run.duration=300", "adrc.b0=0.001"], None),  # diverges
    # the ATO on its sensors' located position, on wet rail (slides; re-planned for them)
    ("seed004-metro-ato", ["run.duration=200", "odometry.enabled=true", "plant.adhesion=wet",
                           "profile.degraded.enabled=true",
                           "odometry.accelerometer=true", "odometry.radar=true",
                           "odometry.balise_spacing=500", "odometry.beacon_distances=20,5",
                           "plant.motored_share=0.667"], None),
    ("seed004-metro-line", ["run.duration=150", "odometry.enabled=true",  # a journey's stops
                            "odometry.balise_spacing=400", "odometry.beacon_distances=5"], None),
]


def same_bits(values, changes=None) -> int:
    """The staged run's bits are the loop's, compiled and as Python; its steps."""
    staged = staged_run(values, changes)
    for compiled in (True, False):
        looped = simulate(values, changes=changes, compiled=compiled)
        assert looped.keys() == staged.keys()
        for name in staged:
            assert np.array_equal(looped[name], staged[name], equal_nan=True), (name, compiled)
    return len(staged["t"])


@pytest.mark.parametrize("scenario,overrides,changes", RUNS)
def test_the_stages_driven_as_the_nodes_drive_them_give_the_loops_bits(scenario, overrides,
                                                                        changes):
    values = apply_overrides(load_scenario(scenario), overrides)
    made = same_bits(values, changes)
    if "adrc.b0=0.001" in overrides:
        assert made < steps(values)  # diverged


def test_a_journey_ended_at_its_last_stop_ends_at_the_same_step():
    """Its last stop moved to the first station (the scenario derives it: set here)."""
    values = {**apply_overrides(load_scenario("seed004-metro-line"), ["run.duration=200"]),
              "run.last_stop_position": 1549.0, "run.last_stop_hold": 5.0}
    assert same_bits(values) < steps(values)


def test_a_live_change_in_the_loop_refuses_what_the_node_refuses():
    values = apply_overrides(load_scenario("seed000"), ["run.duration=20"])
    for compiled in (True, False):
        with pytest.raises(ScenarioError, match="controller.preview cannot change during a run"):
            simulate(values, changes={5: {"controller.preview": 3.0}}, compiled=compiled)


class _Plan:
    """A plug-in plan the profile's step cannot read."""

    shapes_itself = True

    def __init__(self, position_indexed, limits_speed):
        self.position_indexed, self.limits_speed = position_indexed, limits_speed

    def speed(self, t, position=0.0):
        return 10.0

    def table(self):
        return None


@pytest.mark.parametrize("position_indexed,limits_speed,said", [
    (True, False, "gives the table its targets are read from"),
    (False, True, "a time-indexed plan's own speed limits are not read")])
def test_a_plan_the_profile_cannot_read_is_refused_in_one_line(monkeypatch, position_indexed,
                                                               limits_speed, said):
    """Where the Python loop once took it silently: every runner refuses it alike, the
    profile node at start-up."""
    monkeypatch.setattr(RunContext, "plan", property(
        lambda self: _Plan(position_indexed, limits_speed)))
    values = apply_overrides(load_scenario("seed000"), ["run.duration=1"])
    with pytest.raises(ScenarioError, match=said) as refused:
        ProfileStage(NodeValues("profile", values))
    assert "\n" not in str(refused.value)
    for compiled in (True, False):
        with pytest.raises(ScenarioError, match=said):
            simulate(values, compiled=compiled)
