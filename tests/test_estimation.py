"""The on-board estimator of the real train's mass and running resistance
(core/control/estimation.py), run over realistic runs of seed004-metro-ato."""

import functools

import numpy as np
import pytest

from ato_nodes.core.base import kernels
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import prepare
from ato_nodes.core.control import estimation
from ato_nodes.core.control.estimation import (
    PARAMETERS, estimate_series, estimated_force_limits, estimated_mass_factor,
    estimated_resistance, estimator_of, estimator_step, load_weighing)
from ato_nodes.core.control import train_model
from ato_nodes.core.control.train_model import known_resistance, nominal_train
from ato_nodes.core.config.schema import SPEC_BY_NAME
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.train.line import load_line
from ato_nodes.core.train.plant import TrainParameters, force_limits

ERROR = SPEC_BY_NAME["train.load_weighing_error"].default
ESTIMATOR = {**{spec.name: spec.default for spec in PARAMETERS},
             "train.load_weighing_error": ERROR, "estimator.lag_sigma": 0.2}
SETTLED = 1000.0  # m: past the metro's acceleration, where the heavy train saturates


# The curve these tests were written on (seed004-metro-ato's before its on-time curve of
# docs/tracking.md section 5.1): where the nominal train keeps off its envelope.
CURVE = ("profile.ato.acceleration=0.6", "profile.ato.deceleration=0.6",
         "profile.ato.stop_jerk=0.4", "profile.ato.margin=1.3889", "profile.envelope_share=0.9",
         "profile.jerk=0.5", "profile.departure_jerk=0")


# The run these tests estimate from: the speed sensor's white noise (the estimator's
# model) and the controller without an estimate of its own (the ato-on-board preset's off)
ON_THE_SPEED_SENSOR = ("odometry.enabled=false", "estimator.enabled=false",
                       "profile.replan.enabled=false")


@functools.lru_cache(maxsize=None)
def metro_run(*overrides):
    """seed004-metro-ato's values and series (on CURVE) with the real train of
    `overrides`."""
    # the run's own weighing unclipped, as written on: the crush-laden train read 1.305
    # (clipped to 1.3, its plan differs and the estimate is 1.1 % off at SETTLED, 0.06 %
    # at the stop)
    given = {override.split("=")[0] for override in overrides}
    sensor = [kept for kept in ON_THE_SPEED_SENSOR if kept.split("=")[0] not in given]
    values = prepare("seed004-metro-ato", [*CURVE, *sensor, "train.load_weighing_max=0",
                                           *overrides])
    return values, simulate(values)


def estimator(values, mass_reading, line=True):
    return estimator_of(ESTIMATOR, TrainParameters.from_values(values), values["run.period"],
                        mass_reading, load_line(values["line.file"]) if line else None,
                        values["plant.initial_position"])


def estimated_run(mass_factor=1.0, resistance_factor=1.0, weighing_seed=4):
    """(the estimates along the run, its series, the last state), the prior the load
    weighing of the real train with `weighing_seed`."""
    values, series = metro_run(f"plant.mass_factor={mass_factor}",
                               f"plant.resistance_factor={resistance_factor}")
    settings, state = estimator(values, load_weighing(mass_factor, ERROR, weighing_seed))
    rows, last = estimate_series(settings, state, series["command"], series["measured_speed"])
    return rows, series, last


def test_the_load_weighing_error_is_reproducible_from_its_seed_and_of_the_stated_size():
    assert load_weighing(1.3, ERROR, 11) == load_weighing(1.3, ERROR, 11)
    assert load_weighing(1.3, ERROR, 11) != load_weighing(1.3, ERROR, 12)
    assert load_weighing(1.3, 0.0, 11) == 1.3
    errors = np.array([load_weighing(0.85, ERROR, seed) / 0.85 - 1.0 for seed in range(400)])
    assert 0.8 * ERROR < errors.std() < 1.2 * ERROR and abs(errors.mean()) < 0.4 * ERROR


@pytest.mark.parametrize("mass_factor,weighing_seed", [(0.85, 4), (1.0, 4), (1.3, 3), (1.3, 8)])
def test_it_converges_on_light_nominal_and_heavy_trains(mass_factor, weighing_seed):
    """After 1000 m (~70 s) of the metro run: the resistance scale within 3 %; the heavy
    train's mass (seen at its envelope) within 1 % from a prior 5-6 % off either way;
    a light or nominal train's mass (never at its envelope: unobservable) no further
    from the truth than the load weighing put it, with the load weighing's sigma."""
    rows, series, _ = estimated_run(mass_factor, weighing_seed=weighing_seed)
    settled = np.searchsorted(series["position"], SETTLED)
    prior_error = load_weighing(mass_factor, ERROR, weighing_seed) / mass_factor - 1.0
    mass_error = rows["mass_factor"][settled:] / mass_factor - 1.0
    assert np.all(np.abs(rows["resistance_scale"][settled:] - 1.0) < 0.03)
    if mass_factor > 1.0:
        assert abs(prior_error) > 0.05 and np.all(np.abs(mass_error) < 0.01)
    else:
        assert np.all(np.abs(mass_error) <= abs(prior_error) + 0.005)
        assert rows["mass_sigma"][-1] > 0.9 * ERROR * mass_factor


@pytest.mark.parametrize("resistance_factor", [0.8, 1.2])
def test_it_finds_a_running_resistance_20_percent_off_the_nominal(resistance_factor):
    rows, series, _ = estimated_run(resistance_factor=resistance_factor)
    settled = np.searchsorted(series["position"], SETTLED)
    assert np.all(np.abs(rows["resistance_scale"][settled:] - resistance_factor) < 0.03)
    assert rows["resistance_scale"][0] == 1.0  # it started from the nominal


@pytest.mark.parametrize("lag_factor", [0.7, 1.3])
def test_it_finds_an_actuator_30_percent_quick_or_slow(lag_factor):
    """From the nominal lag (estimator.lag_sigma 0.2), the first acceleration's changes of
    command show the real lag: within 3 % after SETTLED, its sigma under a tenth of the
    prior's."""
    values, series = metro_run(f"plant.lag_factor={lag_factor}")
    settings, state = estimator(values, load_weighing(1.0, ERROR, 4))
    rows, _ = estimate_series(settings, state, series["command"], series["measured_speed"])
    settled = np.searchsorted(series["position"], SETTLED)
    assert rows["lag_factor"][0] == 1.0
    assert np.all(np.abs(rows["lag_factor"][settled:] / lag_factor - 1.0) < 0.03)
    assert np.all(rows["lag_sigma"][settled:] < 0.1 * ESTIMATOR["estimator.lag_sigma"])


def test_with_no_lag_sigma_the_lag_stays_the_nominal_one():
    """estimator.lag_sigma 0: the lag is not estimated, its row and column of the
    covariance stay zero (the three-state filter), the model keeps the nominal lag."""
    values, series = metro_run("plant.lag_factor=1.3")
    settings, state = estimator_of({**ESTIMATOR, "estimator.lag_sigma": 0.0},
                                   TrainParameters.from_values(values), values["run.period"],
                                   1.0, load_line(values["line.file"]))
    assert not settings.lag_estimated
    rows, last = estimate_series(settings, state, series["command"], series["measured_speed"])
    assert np.all(rows["lag_factor"] == 1.0) and np.all(rows["lag_sigma"] == 0.0)
    assert not np.any(last.covariance[estimation.LAG]) and last.updates > 0


def test_the_covariance_shrinks_with_excitation_only():
    """Moving, the resistance's sigma falls from the prior's 0.2; the mass's only where the
    train reached its envelope (the heavy one), not for the light one; the covariance
    stays symmetric and positive definite."""
    light, series, light_state = estimated_run(0.85)
    heavy, _, heavy_state = estimated_run(1.3, weighing_seed=3)
    settled = np.searchsorted(series["position"], SETTLED)
    prior = ESTIMATOR["estimator.resistance_sigma"]
    assert light["resistance_sigma"][0] == prior
    assert np.all(light["resistance_sigma"][settled:] < prior / 4)
    assert heavy["mass_sigma"][-1] < 0.3 * heavy["mass_sigma"][0]
    assert light["mass_sigma"][-1] > 0.95 * light["mass_sigma"][0]
    for state in (light_state, heavy_state):
        assert np.array_equal(state.covariance, state.covariance.T)
        assert np.all(np.linalg.eigvalsh(state.covariance) > 0.0)


def test_standstill_and_the_holding_brake_freeze_the_estimates():
    """Stopped (held by the brakes, whatever the command), the estimates, their covariance
    and the update count stay as they were, to the bit: no information, no drift."""
    _, _, stopped = estimated_run(1.3, weighing_seed=3)
    values, _ = metro_run("plant.mass_factor=1.3", "plant.resistance_factor=1.0")
    settings, _ = estimator(values, 1.3)
    state = stopped
    for k in range(600):
        command = -30.0 if k < 300 else 80.0  # the holding brake, then traction held back
        state = estimator_step(settings, state, command, 0.0)
    assert (state.inverse_mass, state.resistance_scale, state.updates) == (
        stopped.inverse_mass, stopped.resistance_scale, stopped.updates)
    assert np.array_equal(state.covariance[1:, 1:], stopped.covariance[1:, 1:])
    moving = estimator_step(settings, state, 80.0, 2.0)
    moving = estimator_step(settings, moving, 80.0, 2.05)
    assert moving.updates == stopped.updates + 1


def test_a_period_beyond_the_gate_is_not_learned_from_and_its_speed_is_taken():
    """Wheels slipping give the train less than it asked: a speed 0.3 m/s short of the
    prediction (some 20 sigmas) moves no estimate through the gate, and moves them without."""
    values, series = metro_run("plant.mass_factor=1.0", "plant.resistance_factor=1.0")
    moving = np.flatnonzero(series["measured_speed"] > 10.0)[0]
    states = {}
    for gate in (0.0, 4.0):
        settings, state = estimator_of({**ESTIMATOR, "estimator.gate": gate},
                                       TrainParameters.from_values(values),
                                       values["run.period"], 1.0,
                                       load_line(values["line.file"]),
                                       values["plant.initial_position"])
        for command, speed in zip(series["command"][:moving], series["measured_speed"][:moving],
                                  strict=True):
            state = estimator_step(settings, state, command, speed)
        states[gate] = (state, estimator_step(settings, state, series["command"][moving],
                                              series["measured_speed"][moving] - 0.3))
    before, gated = states[4.0]
    assert (gated.inverse_mass, gated.resistance_scale, gated.lag_factor, gated.updates) == (
        before.inverse_mass, before.resistance_scale, before.lag_factor, before.updates)
    assert gated.speed == series["measured_speed"][moving] - 0.3
    before, learned = states[0.0]
    assert learned.updates == before.updates + 1
    assert learned.resistance_scale != before.resistance_scale


def test_the_updates_stop_below_the_minimum_speed_along_a_run():
    rows, series, last = estimated_run()
    values, _ = metro_run("plant.mass_factor=1.0", "plant.resistance_factor=1.0")
    settings, state = estimator(values, 1.0)
    counts = []
    for command, speed in zip(series["command"], series["measured_speed"], strict=True):
        state = estimator_step(settings, state, command, speed)
        counts.append(state.updates)
    increments = np.diff(counts, prepend=0) > 0
    slow = series["measured_speed"] < ESTIMATOR["estimator.min_speed"]
    assert not np.any(increments & slow) and increments.sum() == last.updates > 1000


def test_a_neutral_section_edge_freezes_the_update():
    values = prepare("hsr-neutral-ato", [])
    train = TrainParameters.from_values(values)
    start = 8410.0 + train.pantograph_offset  # the head where the pantograph enters
    for head, informative in ((start - 200.0, True), (start - 4.0, False),
                              (start + 100.0, True), (start + 298.0, False)):
        settings, state = estimator(values, 1.0)
        state = state._replace(actuator=state.actuator._replace(position=head))
        assert estimator_step(settings, state, 0.0, 20.0).informative == informative


def test_the_estimated_model_is_the_nominal_one_at_the_prior_of_a_nominal_train():
    values, _ = metro_run("plant.mass_factor=1.0", "plant.resistance_factor=1.0")
    train, line = TrainParameters.from_values(values), load_line(values["line.file"])
    settings, state = estimator(values, 1.0)
    model, _ = nominal_train(train, values["run.period"], 0.0, line)
    heavy = state._replace(inverse_mass=1.0 / 1.3)
    for speed, position in ((5.0, 400.0), (20.0, 1500.0)):
        assert estimated_resistance(settings, state, speed, position) == known_resistance(
            model, speed, position, 1.0)
        assert estimated_force_limits(settings, state, speed) == force_limits(
            speed, train.envelope)
        assert estimated_force_limits(settings, heavy, speed)[1] == pytest.approx(
            force_limits(speed, train.envelope)[1] / 1.3)
    assert estimated_mass_factor(heavy)[0] == pytest.approx(1.3)


@pytest.mark.slow
@pytest.mark.skipif(not kernels.AVAILABLE, reason="numba is not installed")
def test_the_compiled_estimator_gives_the_python_bits():
    values, series = metro_run("plant.mass_factor=1.3", "plant.resistance_factor=1.0")
    settings, state = estimator(values, 1.25)
    python, python_state = estimate_series(settings, state, series["command"],
                                           series["measured_speed"])
    fast, fast_state = estimate_series(settings, state, series["command"],
                                       series["measured_speed"], fast=True)
    assert estimation.compiled_estimate_rows is not None
    for name in python:
        assert np.array_equal(python[name], fast[name]), name
    assert np.array_equal(python_state.covariance, fast_state.covariance)


def test_off_a_controller_reports_the_departure_estimates_throughout():
    values, series = metro_run("plant.mass_factor=1.2", "plant.resistance_factor=1.2")
    assert not values["estimator.enabled"]
    assert np.all(series["mass_factor"] == values["train.mass_reading"])
    assert np.all(series["resistance_scale"] == 1.0)


@pytest.mark.slow
def test_on_the_linear_adrc_learns_the_resistance_and_its_observer_explains_less():
    """A 20 % heavier running resistance: with the estimate in its model, the linear
    ADRC's observer is left less unexplained acceleration (z2) to estimate."""
    runs = [metro_run("plant.resistance_factor=1.2", f"estimator.enabled={on}")[1]
            for on in ("false", "true")]
    moving = (runs[0]["speed"] > 5.0) & (runs[0]["t"] > 60.0)
    unexplained = [np.mean(np.abs(series["z2"][moving])) for series in runs]
    assert runs[1]["resistance_scale"][-1] == pytest.approx(1.2, rel=0.02)
    assert unexplained[1] < 0.75 * unexplained[0]


def test_a_controller_kind_without_the_estimator_refuses_it_in_one_line():
    with pytest.raises(ScenarioError, match="does not use the on-board estimator") as caught:
        prepare("seed000", ["estimator.enabled=true"])
    assert "\n" not in str(caught.value)


def test_the_recorded_estimates_are_the_estimators_over_the_recorded_run():
    """What the controller carries in its loop is what estimate_series gives offline
    over the commands and measured speeds it recorded (scripts/estimator_accuracy.py)."""
    values, series = metro_run("plant.mass_factor=1.3", "plant.resistance_factor=1.2",
                               "estimator.enabled=true")
    on_board, state = estimation.on_board_estimator(values, values["run.period"],
                                                    load_line(values["line.file"]))
    offline, _ = estimate_series(on_board.settings, state, series["command"],
                                 series["measured_speed"])
    for name, values_offline in offline.items():
        assert np.array_equal(values_offline, series[name]), name


def test_the_controllers_model_acts_on_the_estimated_envelope():
    """The linear ADRC's nominal model (its delay-aware prediction and observer input)
    clamps the force at the envelope as estimated on board: the model's mass over the
    estimated one; 1 with the estimator off (the model's own envelope, to the bit)."""
    values = prepare("seed004-metro-ato", ["estimator.enabled=true", "train.load_weighing=false",
                                           "train.mass_reading=1.1"])
    model, state = nominal_train(TrainParameters.from_values(values), values["run.period"])
    on_board, estimated = estimation.on_board_estimator(values, values["run.period"])
    def envelope(state):
        return estimation.on_board_actuator(on_board, state, model).envelope_scale
    assert envelope(None) == 1.0
    assert envelope(estimated) == pytest.approx(1.0)  # the prior
    assert envelope(estimated._replace(inverse_mass=1.0 / 1.43)) == pytest.approx(1.1 / 1.43)
    low, high = force_limits(10.0, model.train.envelope)
    for scale in (1.0, 0.5):
        lag_state = high * 2.0  # the lag's output well above the envelope
        actuator = train_model.Actuator(scale, model.decay, model.spread)
        _, mean = train_model.nominal_act(model, lag_state, 2.0 * high, 10.0, 0.0, actuator)
        assert mean == high * scale


def test_the_controllers_model_lags_as_estimated():
    """The linear ADRC's nominal model's actuator (on_board_actuator) takes the lag as
    estimated on board; off, or with the lag not estimated, the model's own lag (its
    bits kept)."""
    values = prepare("seed004-metro-ato", ["estimator.enabled=true", "estimator.lag_sigma=0.2"])
    model, _ = nominal_train(TrainParameters.from_values(values), values["run.period"])
    on_board, estimated = estimation.on_board_estimator(values, values["run.period"])
    assert estimation.on_board_actuator(on_board, None, model) == train_model.model_actuator(
        model) == (1.0, model.decay, model.spread)
    slower = estimation.on_board_actuator(on_board, estimated._replace(lag_factor=1.3), model)
    lag = 1.3 * values["plant.actuator_lag"]
    assert slower.decay == pytest.approx(np.exp(-values["run.period"] / lag))
    assert slower.spread == pytest.approx(lag * (1.0 - slower.decay) / values["run.period"])
    assert slower.decay > model.decay
    fixed = on_board._replace(settings=on_board.settings._replace(lag_estimated=False))
    kept = estimation.on_board_actuator(fixed, estimated._replace(lag_factor=1.3), model)
    assert (kept.decay, kept.spread) == (model.decay, model.spread)


@pytest.mark.slow
def test_the_estimated_lag_helps_the_linear_adrc_track_a_slow_actuator():
    """seed004-metro-line's linear ADRC driving an actuator 40 % slower than it knows:
    with the lag estimated its delay-aware prediction lags as the train does, and the
    worst tracking error falls by a fifth or more against the nominal lag kept."""
    errors = {}
    for lag_sigma in (0.0, 0.2):
        values = prepare("seed004-metro-line", ["estimator.enabled=true", "plant.lag_factor=1.4",
                                                f"estimator.lag_sigma={lag_sigma}"])
        series = simulate(values)
        errors[lag_sigma] = np.max(np.abs(series["target"] - series["speed"]))
        if lag_sigma:
            assert series["lag_factor"][-1] == pytest.approx(1.4, rel=0.03)
    assert errors[0.2] < 0.8 * errors[0.0]
