"""The plug-in seam: registries, run context, preview, named outputs, eager stages."""

import dataclasses

import numpy as np
import pytest

from ato_nodes.core.config.components import CONTROLLERS, PROFILES
from ato_nodes.core.config.context import RunContext
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.base.registry import Controller, Plan
from ato_nodes.core.run.loop import SERIES, simulate
from ato_nodes.core.run.stages import ControllerStage, ProfileStage
from ato_nodes.core.config.scenario import apply_overrides, load_scenario, validate
from ato_nodes.core.config.schema import SPECS, NodeValues, defaults


def values(scenario="seed000", *overrides):
    return apply_overrides(load_scenario(scenario), list(overrides))


# what a kind needs beyond its defaults to build on seed 000 (the GPC's default
# prediction model is a model file identified for another train)
NEEDS = {"gpc": ("gpc.prediction=mechanistic", "gpc.horizon=2")}


def test_every_registered_kind_implements_its_interface():
    """Controllers and plans declare what the loop and the run context read of them
    (core/base/registry.py), instead of being probed for it."""
    for kind in CONTROLLERS.components:
        stage = ControllerStage(NodeValues("controller", values(
            "seed000", f"controller.kind={kind}", "controller.preview=2",
            *NEEDS.get(kind, ()))))
        assert isinstance(stage.controller, Controller), kind
    plans = {"ato": "seed004-metro-ato", "strategy": "seed002-hsr", "table": "seed001-excitation",
             "journey": "seed004-metro-line"}
    for kind in PROFILES.components:
        scenario = plans.get(kind, "seed000")
        plan = RunContext(values(scenario, f"profile.kind={kind}")).plan
        assert isinstance(plan, Plan), kind
        assert isinstance(plan.position_indexed, bool) and isinstance(plan.shapes_itself, bool)
        if not plan.limits_speed:
            with pytest.raises(NotImplementedError):
                plan.limit(0.0)
    ato = RunContext(values("seed004-metro-ato")).plan
    assert ato.limits_speed and ato.limit(100.0) > 0.0


def test_every_registered_kind_builds_and_steps_with_its_declared_outputs():
    for kind, component in CONTROLLERS.components.items():
        stage = ControllerStage(NodeValues("controller", values(
            "seed000", f"controller.kind={kind}", "run.duration=1", "controller.preview=2",
            *NEEDS.get(kind, ()))))
        stage.horizons.append([1.0, 1.1, 1.2])
        stage.speeds.append(0.5)
        (out,) = stage.run_ready_steps()
        assert np.isfinite(out.u) and len(out.extras) == len(component.outputs), kind
        assert not set(component.output_names) & set(SERIES), kind  # no clash with the loop's


def test_a_parameter_default_is_written_once_in_the_schema():
    names = [spec.name for spec in SPECS]
    assert len(names) == len(set(names))
    for registry in (CONTROLLERS, PROFILES):
        owner = {}  # a kind may take another's parameters (a journey drives ato curves)
        for component in registry.components.values():
            for spec in component.parameters:
                owner.setdefault(spec.name, component.kind)
        for component in registry.components.values():
            prefix = {spec.name.rsplit(".", 1)[0] for spec in component.parameters
                      if owner[spec.name] == component.kind}
            assert len(prefix) <= 1, component.kind  # one group of its own per kind


def test_configuration_objects_have_no_defaults_of_their_own():
    from ato_nodes.core.control.adrc import DiscreteADRCGains, HanADRCGains, LinearADRCGains
    from ato_nodes.core.control.gpc import GPCSettings
    from ato_nodes.core.control.pid import PIDGains
    from ato_nodes.core.train.plant import TrainParameters
    from ato_nodes.core.targets.profiles import Seed000Profile
    for cls in (HanADRCGains, DiscreteADRCGains, LinearADRCGains, PIDGains, GPCSettings,
                TrainParameters, Seed000Profile):
        if hasattr(cls, "_fields"):  # a NamedTuple (compiled code reads it)
            assert not cls._field_defaults, cls
        else:
            assert all(f.default is dataclasses.MISSING for f in dataclasses.fields(cls)), cls


def test_a_node_reads_only_what_it_declares():
    controller = NodeValues("controller", defaults())
    assert controller["plant.mass"] == 388.4  # the nominal train is in its context
    with pytest.raises(ScenarioError, match="'recorder.output' is not declared by the "
                                            "controller node"):
        controller["recorder.output"]


def test_a_missing_parameter_fails_at_start_up_the_same_way_in_simulate():
    bad = {**values("seed000"), "profile.kind": "table"}
    with pytest.raises(ScenarioError, match="profile.table.file is empty") as checked:
        validate(bad, "here")
    with pytest.raises(ScenarioError) as simulated:
        simulate(bad)
    assert str(checked.value) == f"here: {simulated.value}"


@pytest.mark.parametrize("scenario", ["seed000", "seed004-metro"])
def test_the_controller_receives_a_preview_of_20_steps_of_the_plan(scenario):
    run = values(scenario, "run.duration=20", "controller.preview=20")
    series = simulate(run)
    preview, context = series["preview"], RunContext(run)
    assert preview.shape == (len(series["t"]), 21)
    np.testing.assert_array_equal(preview[:, 0], series["target"])
    position = series["position"]
    for k in range(3, len(position)):
        predicted = position[k - 2] + 2 * (position[k - 2] - position[k - 3])
        assert list(preview[k]) == context.horizon(k, predicted, 20), k
    if not context.plan.position_indexed:  # time-indexed: exactly r(t_k) .. r(t_k+20)
        h = run["run.period"]
        expected = [[context.plan.speed((k + i) * h) for i in range(21)]
                    for k in range(len(position))]
        np.testing.assert_array_equal(preview, expected)


def test_a_position_indexed_horizon_follows_the_planned_trajectory():
    context = RunContext(values("seed004-metro"))
    horizon = context.horizon(100, 500.0, 50)
    h, position = context.period, 500.0
    for i in range(1, 51):  # ds/dt = v(s), Heun: the positions the planned train passes
        v = horizon[i - 1]
        position += 0.5 * h * (v + context.plan.speed(0.0, position + h * v))
        assert horizon[i] == context.plan.speed(0.0, position)
    assert horizon[0] == context.plan.speed(0.0, 500.0)


def test_the_profile_sends_each_step_its_horizon_and_stairs_only_the_first_entry():
    stage = ProfileStage(NodeValues("profile", values(
        "seed003-maglev", "controller.preview=3")))
    assert [len(horizon) for horizon in stage.on_position(100.0)] == [4, 4, 4]
    later = stage.on_position(100.0)[0]  # standing 100 m in: a stair one step above 0
    planned = stage.context.horizon(3, 100.0, 3)
    assert later[0] == stage.settings.approach_step < planned[0] and later[1:] == planned[1:]


class _Recording:
    """A controller that notes what the loop gives it and steps the kind it wraps."""

    def __init__(self, controller, seen):
        self.controller, self.seen = controller, seen

    def start(self, target, measured, horizon):
        self.seen.append(("start", target, list(horizon)))
        self.controller.start(target, measured, horizon)

    def step(self, target, measured, horizon):
        self.seen.append(("step", target, list(horizon)))
        return self.controller.step(target, measured, horizon)


@pytest.mark.parametrize("compiled", [True, False])
def test_a_controller_is_given_r_k_as_its_target_and_the_horizon_whatever_the_preview(
        monkeypatch, compiled):
    """`target` is the plan's speed now (what the run records as its target), not the
    preview's end: a kind that ignores the horizon tracks r_k even where a scenario
    previews 9 steps (the -ato scenarios); the horizon is r_k .. r_k+N."""
    seen = []
    pid = CONTROLLERS.components["pid"]
    monkeypatch.setitem(CONTROLLERS.components, "pid", dataclasses.replace(
        pid, steps=None, factory=lambda *arguments: _Recording(pid.factory(*arguments), seen)))
    run = values("seed004-metro-ato", "controller.kind=pid", "run.duration=20")
    assert run["controller.preview"] == 9
    series = simulate(run, compiled=compiled)
    assert [what for what, _, _ in seen] == ["start"] + ["step"] * len(series["t"])
    targets = np.array([target for _, target, _ in seen[1:]])
    np.testing.assert_array_equal(targets, series["target"])
    assert {len(horizon) for _, _, horizon in seen} == {10}
    assert all(target == horizon[0] for _, target, horizon in seen)
