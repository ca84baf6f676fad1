"""The loop's pairing and look-ahead rules (what the nodes and the simulation share)."""

import itertools
from types import SimpleNamespace

import numpy as np
import pytest

from ato_nodes.core.run import fast_loop, loop
from ato_nodes.core.config.components import CONTROLLERS
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.run.stages import ControllerStage, ProfileStage
from ato_nodes.core.config.scenario import apply_overrides, load_scenario


def values(*overrides):
    return apply_overrides(load_scenario("seed000"), ["run.duration=0.2", *overrides])


def test_profile_sends_targets_two_steps_ahead_from_extrapolated_position(tmp_path):
    table = tmp_path / "by_position.csv"
    table.write_text("position,speed\n0,0\n1000,100\n")
    profile = ProfileStage(values("profile.kind=table", f"profile.table.file={table}",
                                  "run.duration=1"))
    # constant 5 m per step: s_k = 5 k, so the target of step j is V(5 j) = 0.5 j.
    # At k = 0 no motion is known yet: r_0..r_2 are taken at s_0 (a standing start).
    sent = [[horizon[0] for horizon in profile.on_position(5.0 * k)] for k in range(4)]
    assert sent[0] == pytest.approx([0.0, 0.0, 0.0])
    assert sent[1] == pytest.approx([1.5]) and sent[3] == pytest.approx([2.5])


def test_profile_stops_at_the_last_step():
    profile = ProfileStage(values())  # 4 steps
    sent = [target for k in range(4) for target in profile.on_position(0.0)]
    assert len(sent) == 4


def test_controller_pairs_each_speed_with_a_horizon_and_tracks_its_preview_entry():
    stage = ControllerStage(values("controller.preview=1"))  # 4 steps
    stage.speeds.append(0.0)
    assert stage.run_ready_steps() == []  # the horizon of step 0 not there yet
    stage.horizons.extend([[1.0, 2.0], [2.0, 3.0]])
    stage.speeds.append(0.0)
    outputs = stage.run_ready_steps()
    assert len(outputs) == 2 and stage.step_index == 2
    v1 = stage.output_names.index("v1")
    assert outputs[0].extras[v1] == pytest.approx(2.0)  # the TD was started on r_1


def test_without_preview_each_step_needs_only_its_own_target():
    stage = ControllerStage(values())
    stage.speeds.append(0.0)
    stage.horizons.append([1.0])
    assert len(stage.run_ready_steps()) == 1


def test_simulation_records_the_target_of_each_step_whatever_the_preview():
    base = simulate(values("run.duration=5"))
    preview = simulate(values("run.duration=5", "controller.preview=1"))
    assert list(base["target"]) == list(preview["target"])
    assert list(base["command"]) != list(preview["command"])


LIVE_GAINS = [("seed000", "adrc.mu1", 7000.0), ("seed003-maglev", "nladrc.kp", 3.0),
              ("seed004-metro", "dadrc.b1", 50.0), ("seed004-metro-ato", "ladrc.omega_c", 3.0),
              ("hsr-neutral-ato", "ladrc.omega_o", 7.0), ("seed000-pid", "pid.kp", 80.0)]


def run_of(scenario, seconds=60):
    return apply_overrides(load_scenario(scenario), [f"run.duration={seconds}"])


@pytest.mark.parametrize("scenario,name,value", LIVE_GAINS)
def test_a_live_gain_set_to_its_own_value_changes_nothing(scenario, name, value):
    """The rebuild carries every bit of state over (observer, filters, model, limiter)."""
    run = run_of(scenario)
    plain = simulate(run)
    retuned = simulate(run, changes={300: {name: run[name]}, 700: {name: run[name]}})
    assert all(np.array_equal(plain[key], retuned[key], equal_nan=True) for key in plain)


@pytest.mark.slow
@pytest.mark.parametrize("scenario,name,value", LIVE_GAINS)
def test_a_live_gain_acts_from_its_step_on(scenario, name, value):
    run = run_of(scenario)
    plain, changed = simulate(run), simulate(run, changes={400: {name: value}})
    assert np.array_equal(plain["command"][:400], changed["command"][:400])
    assert not np.array_equal(plain["command"][400:], changed["command"][400:])
    from_start = simulate(apply_overrides(run, [f"{name}={value}"]))
    assert all(np.array_equal(from_start[key], simulate(run, changes={0: {name: value}})[key],
                              equal_nan=True) for key in from_start)


def test_only_a_kinds_own_float_parameters_are_live():
    han = CONTROLLERS["han_adrc"].live_parameters
    assert "adrc.mu1" in han and "adrc.implicit_nlsef" not in han
    assert "ladrc.feedforward" not in CONTROLLERS["linear_adrc"].live_parameters
    assert CONTROLLERS["gpc"].live_parameters == ()  # no state declared: nothing live
    stage = ControllerStage(values())
    with pytest.raises(ScenarioError, match="controller.preview cannot change during a run"):
        stage.retune({"controller.preview": 3})


def test_the_python_loop_checks_the_deadline_between_its_chunks(monkeypatch):
    """A clock that advances one second per reading, chunks of one step: the run passes
    its deadline at the sixth check, before step 5 (a chunk aims at CHUNK_SECONDS of
    wall time, a step at 10000 RK4 sub-steps takes ~0.03 s as Python)."""
    clock = itertools.count()
    monkeypatch.setattr(loop, "time", SimpleNamespace(monotonic=lambda: next(clock)))
    monkeypatch.setattr(fast_loop, "FIRST_CHUNK", 1)
    monkeypatch.setattr(fast_loop, "CHUNK_SECONDS", 0.0)
    with pytest.raises(TimeoutError, match="deadline at step 5$"):
        simulate(run_of("seed001-crh380al"), deadline=4.5, compiled=False)
