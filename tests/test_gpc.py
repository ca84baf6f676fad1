"""Seed 001's generalized predictive controller: prediction, constraints, offset-free
tracking, online correction, the compiled step's bits in every runner, and its one-line
start-up errors."""

from types import SimpleNamespace

import numpy as np
import pytest
from test_stages import same_bits

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.control import gpc_steps
from ato_nodes.core.control.limiter import LimiterSettings
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.run.scoring import score_series
from ato_nodes.core.config.scenario import apply_overrides, load_scenario

C, A, B, DELAY = 0.01, np.array((1.6, -0.62)), np.array((0.004, 0.001)), 2  # an ARX model
SPEEDS = np.array([10.0, 10.1, 10.3, 10.4, 10.6, 10.7, 10.9])
COMMANDS = np.array([5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0])


def simulate_arx(speeds, commands, future):
    """y(k+1..k+P) of the ARX model from the histories under the future commands."""
    speeds, commands = list(speeds), list(commands) + list(future)
    past = len(commands) - len(future)
    out = []
    for j in range(1, len(future) + 1):
        value = C + sum(a * speeds[-i] for i, a in enumerate(A, 1))
        value += sum(b * commands[past + j - DELAY - i] for i, b in enumerate(B, 1))
        speeds.append(value)
        out.append(value)
    return np.array(out)


def responses():
    return gpc_steps.free_and_forced(C, A, B, DELAY, SPEEDS, COMMANDS, 12, 3)


def test_free_and_forced_responses_are_those_of_the_arx_model():
    free, matrix = responses()
    held = [COMMANDS[-1]] * 12
    np.testing.assert_allclose(free, simulate_arx(SPEEDS, COMMANDS, held))
    for i in range(3):  # a unit move at k+i, held after it
        moved = [u + (1.0 if m >= i else 0.0) for m, u in enumerate(held)]
        response = simulate_arx(SPEEDS, COMMANDS, moved) - free
        np.testing.assert_allclose(matrix[:, i], response, atol=1e-12)
    assert np.all(matrix[:DELAY] == 0.0)  # the input delay: no response before it


def test_the_qp_keeps_the_moves_inside_the_jerk_limit_and_the_command_inside_its_bounds():
    free, matrix = responses()
    hessian = matrix.T @ matrix + 1e-4 * np.eye(3)
    settings = SimpleNamespace(constrained=True, moves=3)

    def move(gradient, previous):
        return gpc_steps.first_move(settings, hessian, gradient, previous, -20.0, 12.0, 0.6)

    far_above = matrix.T @ (free - (free + 30.0))  # a target far above: wants full traction
    assert move(far_above, 11.0) == pytest.approx(0.6)  # the jerk limit binds
    unconstrained = float(np.linalg.solve(hessian, -far_above)[0])
    assert unconstrained > 0.6
    near = matrix.T @ (free - (free + 0.01))  # a small move: no constraint active
    assert move(near, 11.0) == pytest.approx(float(np.linalg.solve(hessian, -near)[0]),
                                             rel=1e-12)
    assert move(far_above, 11.9) == pytest.approx(0.1, abs=1e-12)  # stops at u_max
    assert gpc_steps.first_move(SimpleNamespace(constrained=False, moves=3), hessian,
                                far_above, 11.0, -20.0, 12.0, 0.6) == pytest.approx(
        unconstrained, rel=1e-12)


def crh380al(*overrides):
    return apply_overrides(load_scenario("seed001-crh380al"), [
        "line.file=", "profile.kind=step", "profile.step.speed=50", "plant.initial_speed=45",
        "run.duration=240", "plant.speed_noise=0", "plant.speed_quantum=0", *overrides])


def test_the_fed_back_residual_makes_tracking_offset_free_under_a_model_error():
    """The plant's running resistance 30 % above the nominal train's, which the
    mechanistic prediction model uses."""
    errors = {}
    for bias_filter in (3.0, 0.0):
        series = simulate(crh380al("gpc.prediction=mechanistic", "plant.resistance_factor=1.3",
                                   f"gpc.bias_filter={bias_filter}"))
        errors[bias_filter] = np.abs(series["target"] - series["speed"])[-100:].max()
    assert errors[3.0] < 0.01 and errors[0.0] > 3 * errors[3.0]


def test_the_shipped_model_tracks_with_every_prediction_and_is_deterministic():
    for prediction in ("lssvm", "mechanistic", "multimodel"):
        values = crh380al(f"gpc.prediction={prediction}", "run.duration=90")
        series = simulate(values)
        error = np.abs(series["target"] - series["speed"])[100:]
        assert error.max() < 0.5, prediction  # m/s, after the first 30 s
        assert np.all(np.abs(np.diff(series["command"])) <= 40.0 * 0.3 + 1e-9)


def test_online_correction_adds_samples_deterministically():
    values = apply_overrides(load_scenario("seed001-crh380al"), [
        "run.duration=120", "gpc.correction_threshold=0.03"])
    first, second = simulate(values), simulate(values)
    assert first["samples_added"][-1] > 0
    assert np.all(np.diff(first["samples_added"]) >= 0)
    for name in first:
        np.testing.assert_array_equal(first[name], second[name], err_msg=name)
    off = simulate(apply_overrides(values, ["gpc.correction=false"]))
    assert off["samples_added"][-1] == 0


@pytest.mark.parametrize("overrides, message", [
    (["gpc.model=models/absent.npz"], "cannot read model file"),
    (["run.period=0.2"], "identified at a 0.3 s period"),
    (["plant.train=crh380a"], "identified on train 'crh380al'"),
    (["gpc.horizon=20", "controller.preview=10"], "needs controller.preview >= 20"),
    (["gpc.prediction=mechanistic", "gpc.horizon=1", "controller.preview=1"],
     "does not reach past the model's input delay"),
    (["gpc.model="], "needs gpc.model"),
])
def test_bad_gpc_input_is_one_line_before_anything_starts(overrides, message):
    with pytest.raises(ScenarioError, match=message) as caught:
        apply_overrides(load_scenario("seed001-crh380al"), overrides)
    assert "\n" not in str(caught.value)


def approach(*overrides):
    """seed001-crh380al-ato's last 50 m from standstill: a short run up and a berth."""
    return apply_overrides(load_scenario("seed001-crh380al-ato"), [
        "plant.initial_position=59950", "run.duration=60", *overrides])


def test_the_berthing_mode_stops_at_the_mark_and_the_holding_target_holds():
    values = approach()
    series = simulate(values)
    stop = score_series(series, values)["stopping_error"]
    assert abs(stop) <= 0.1
    without = approach("gpc.berthing_speed=0")
    assert abs(score_series(simulate(without), without)["stopping_error"]) > 2 * abs(stop)
    moving = int(np.argmax(series["speed"]))
    stopped = moving + np.flatnonzero(series["speed"][moving:] == 0.0)[0]  # held from here on
    assert np.all(series["speed"][stopped:] == 0.0)
    assert np.all(series["command"][stopped + 5:] <= -values["controller.holding_brake"])
    # nothing learnt while held: the residual fed back and the samples stay as they were
    assert np.all(series["bias"][stopped + 5:] == series["bias"][stopped + 5])
    assert np.all(series["model_error"][stopped + 5:] == 0.0)


def test_the_additions_at_their_defaults_leave_the_paper_configuration_untouched():
    """berthing_speed 0: the cost counts the whole horizon, a stop in it or not; hold
    false: a held train's one-step error is learnt."""
    values = load_scenario("seed001-crh380al")
    assert values["gpc.berthing_speed"] == 0.0 and values["gpc.hold"] is False
    stopping = np.concatenate((np.linspace(2.0, 0.0, 8), np.zeros(13)))
    for berthing_speed, counted in ((0.0, 16), (0.05, 7)):  # horizon[0]: the current target
        settings = SimpleNamespace(berthing_speed=berthing_speed, horizon=16, delay=1)
        assert gpc_steps._predictions(settings, stopping) == counted
    limits = LimiterSettings(-50.0, 50.0, 12.0, 0.0, 30.0, 0.0)
    state = SimpleNamespace(expecting=True, expected=0.02, bias=0.0, added=0, model=None,
                            speeds=np.zeros(5), commands=np.zeros(5))
    learning = SimpleNamespace(hold=False, bias_gain=0.5, prediction=gpc_steps.MECHANISTIC)
    error, bias, _, _ = gpc_steps._learn(learning, state, 0.0, 0.0, limits)  # held
    assert error == -0.02 and bias == -0.01
    holding = SimpleNamespace(hold=True, bias_gain=0.5, prediction=gpc_steps.MECHANISTIC)
    assert gpc_steps._learn(holding, state, 0.0, 0.0, limits)[:2] == (0.0, 0.0)


@pytest.mark.parametrize("scenario, overrides", [
    ("seed001-crh380al", ["run.duration=60", "gpc.correction_threshold=0.03"]),
    ("seed001-crh380al-ato", ["plant.initial_position=59950", "run.duration=60",
                              "estimator.enabled=true", "gpc.correction_threshold=0.03"]),
    ("seed001-crh380al", ["run.duration=30", "gpc.prediction=multimodel"]),
    ("seed001-crh380al", ["run.duration=30", "gpc.constrained=false", "gpc.window=2",
                          "gpc.correction_threshold=0.01"]),
])
def test_the_gpc_driven_as_the_nodes_drive_it_gives_the_loops_bits(scenario, overrides):
    """The node's compiled step and the loop's: the same bits, online corrections (and a
    full window forgetting), the estimator and the berth included."""
    values = apply_overrides(load_scenario(scenario), overrides)
    same_bits(values)
    series = simulate(values)
    if "gpc.correction_threshold=0.01" in overrides:
        assert series["samples_added"][-1] > 2  # the window of 2 forgot some
