"""Seed 001's generalized predictive controller: prediction, constraints, offset-free
tracking, online correction, and its one-line start-up errors."""

import numpy as np
import pytest

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.control import gpc as gpc_module
from ato_nodes.core.control.estimation import on_board_estimator
from ato_nodes.core.control.gpc import GPC, Arx, GPCSettings
from ato_nodes.core.control.limiter import CommandLimiter
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.run.scoring import score_series
from ato_nodes.core.config.scenario import apply_overrides, load_scenario
from ato_nodes.core.config.schema import defaults


class FixedModel:
    """A prediction model that always linearises to the same ARX model."""

    def __init__(self, arx, history=6):
        self.arx, self.delay, self.history = arx, arx.delay, history

    def linearise(self, speeds, commands):
        return self.arx

    def observe(self, speeds, commands, error):
        return False


ARX = Arx(0.01, np.array((1.6, -0.62)), np.array((0.004, 0.001)), 2)


def controller(arx=ARX, horizon=12, nu=3, constrained=True, rate=0.0, low=-1e6, high=1e6):
    settings = GPCSettings(horizon, nu, 1.0, 1e-4, constrained, 0.0, 0.0, False)
    limiter = CommandLimiter(low, high, 0.3, rate)
    gpc = GPC(settings, FixedModel(arx), 0.3, limiter, train=None, envelope=False,
              estimator=on_board_estimator(defaults(), 0.3))
    gpc.start(10.0, 10.0)
    gpc.speeds = np.array([10.0, 10.1, 10.3, 10.4, 10.6, 10.7, 10.9])
    gpc.commands = np.array([5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0])
    return gpc


def simulate_arx(arx, speeds, commands, future):
    """y(k+1..k+P) of the ARX model from the histories under the future commands."""
    speeds, commands = list(speeds), list(commands) + list(future)
    past = len(commands) - len(future)
    out = []
    for j in range(1, len(future) + 1):
        value = arx.c + sum(a * speeds[-i] for i, a in enumerate(arx.a, 1))
        value += sum(b * commands[past + j - arx.delay - i] for i, b in enumerate(arx.b, 1))
        speeds.append(value)
        out.append(value)
    return np.array(out)


def test_free_and_forced_responses_are_those_of_the_arx_model():
    gpc = controller()
    free, matrix = gpc._responses(ARX, 0.0)
    held = [gpc.commands[-1]] * 12
    np.testing.assert_allclose(free, simulate_arx(ARX, gpc.speeds, gpc.commands, held))
    for i in range(3):  # a unit move at k+i, held after it
        moved = [u + (1.0 if m >= i else 0.0) for m, u in enumerate(held)]
        response = simulate_arx(ARX, gpc.speeds, gpc.commands, moved) - free
        np.testing.assert_allclose(matrix[:, i], response, atol=1e-12)
    assert np.all(matrix[:ARX.delay] == 0.0)  # the input delay: no response before it


@pytest.mark.skipif(gpc_module.free_and_forced is gpc_module._free_and_forced,
                    reason="numba is not installed")
def test_the_compiled_responses_give_the_bits_of_the_python_ones():
    rng = np.random.default_rng(7)
    for na, nb, delay, horizon, moves in [(1, 1, 0, 1, 1), (2, 2, 1, 16, 3), (3, 1, 2, 20, 5),
                                          (2, 3, 0, 12, 12), (1, 2, 3, 8, 2)]:
        arx = Arx(rng.normal(0.0, 0.1), rng.normal(0.5, 0.3, na), rng.normal(0.0, 0.01, nb),
                  delay)
        history = max(na, delay + nb + 1) + 1
        speeds, commands = rng.uniform(0, 90, history), rng.uniform(-50, 50, history)
        arguments = (arx.c, arx.a, arx.b, arx.delay, speeds, commands, horizon, moves)
        for compiled, python in zip(gpc_module.free_and_forced(*arguments),
                                    gpc_module._free_and_forced(*arguments), strict=True):
            np.testing.assert_array_equal(compiled, python)


def test_the_qp_keeps_the_moves_inside_the_jerk_limit_and_the_command_inside_its_bounds():
    gpc = controller(rate=2.0, low=-20.0, high=12.0)
    free, matrix = gpc._responses(ARX, 0.0)
    hessian = matrix.T @ matrix + 1e-4 * np.eye(3)
    far_above = matrix.T @ (free - (free + 30.0))  # a target far above: wants full traction
    move = gpc._solve(hessian, far_above, gpc.commands[-1], -20.0, 12.0)
    assert move == pytest.approx(2.0 * 0.3)  # the jerk limit binds
    unconstrained = float(np.linalg.solve(hessian, -far_above)[0])
    assert unconstrained > 0.6
    near = matrix.T @ (free - (free + 0.01))  # a small move: no constraint active
    assert gpc._solve(hessian, near, gpc.commands[-1], -20.0, 12.0) == pytest.approx(
        float(np.linalg.solve(hessian, -near)[0]), rel=1e-6)
    gpc.commands[-1] = 11.9  # next to u_max: the QP stops at it
    assert gpc._solve(hessian, far_above, 11.9, -20.0, 12.0) == pytest.approx(0.1, abs=1e-6)


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


def test_the_additions_at_their_defaults_leave_the_paper_configuration_untouched(monkeypatch):
    values = apply_overrides(load_scenario("seed001-crh380al"), ["run.duration=60"])
    assert values["gpc.berthing_speed"] == 0.0 and values["gpc.hold"] is False
    before = simulate(values)

    def entered(*arguments):
        raise AssertionError("a berthing or holding path ran with the additions off")

    monkeypatch.setattr(GPC, "_berthing", entered)
    monkeypatch.setattr(gpc_module, "holds", entered)
    after = simulate(values)
    for name in before:
        np.testing.assert_array_equal(before[name], after[name], err_msg=name)
