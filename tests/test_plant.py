"""The seed-000 train against closed forms."""

import math

import pytest

from dataclasses import replace

from ato_nodes.core.train.plant import PointMassTrain, TrainState
from ato_nodes.core.config.schema import defaults

QUIET = dict(disturbance_amplitude=0.0)


def TrainParameters(**changes):  # noqa: N802 -- the schema's defaults, changed
    from ato_nodes.core.train.plant import TrainParameters as parameters
    return replace(parameters.from_values(defaults()), **changes)


def run(train, command, seconds):
    for _ in range(int(round(seconds / train.period))):
        train.step(command)
    return train.state


def test_xi_is_the_papers():
    assert TrainParameters().xi == pytest.approx(0.0098 / 1.11)


def test_resistance_is_davis_in_m_per_s():
    p = TrainParameters()
    v = 350 / 3.6
    assert p.resistance(v) == pytest.approx(0.16 + 0.0053 * v + 0.0018 * v * v)
    # docs/papers.md: 17.7 N/kN at 350 km/h
    assert p.resistance(v) == pytest.approx(17.68, abs=0.01)
    assert p.resistance(-v) == -p.resistance(v)


def test_steady_state_where_traction_equals_resistance():
    p = TrainParameters(**QUIET)
    v_star = 80.0
    train = PointMassTrain(p, 0.05, state=TrainState(speed=v_star))
    state = run(train, p.resistance(v_star), 100.0)
    assert state.speed == pytest.approx(v_star, abs=1e-10)
    assert state.position == pytest.approx(v_star * 100.0, rel=1e-12)


def test_converges_to_the_balance_speed():
    p = TrainParameters(**QUIET)
    force = 10.0  # N/kN: a + b v + c v^2 = 10 -> v*
    v_star = (-p.davis_b + math.sqrt(p.davis_b ** 2 - 4 * p.davis_c * (p.davis_a - force))) / (
        2 * p.davis_c)
    # slowest time constant near v*: 1 / (xi (b + 2 c v*)) ~ 425 s
    state = run(PointMassTrain(p, 1.0), force, 20000.0)
    assert state.speed == pytest.approx(v_star, rel=1e-6)


def test_linear_resistance_matches_the_exponential_solution():
    # c = 0: dv/dt = xi (F - a - b v) -> v(t) = v* + (v0 - v*) exp(-xi b t)
    p = TrainParameters(davis_a=0.5, davis_b=0.2, davis_c=0.0, **QUIET)
    force, t = 4.5, 30.0
    v_star = (force - p.davis_a) / p.davis_b
    state = run(PointMassTrain(p, 0.05, state=TrainState(speed=1.0)), force, t)
    assert state.speed == pytest.approx(v_star + (1.0 - v_star) * math.exp(-p.xi * p.davis_b * t),
                                        rel=1e-9)


def test_disturbance_alone_integrates_to_the_closed_form():
    # No force, no resistance: v(t) = A / w (1 - cos w t)
    p = TrainParameters(davis_a=0.0, davis_b=0.0, davis_c=0.0)
    t = 7.3
    state = run(PointMassTrain(p, 0.05), 0.0, t)
    amplitude, omega = p.disturbance_amplitude, p.disturbance_frequency
    assert state.speed == pytest.approx(amplitude / omega * (1 - math.cos(omega * t)), rel=1e-7)
    assert state.time == pytest.approx(t)


def test_actuator_lag_is_first_order():
    p = TrainParameters(davis_a=0.0, davis_b=0.0, davis_c=0.0, actuator_lag=0.5, **QUIET)
    train = PointMassTrain(p, 0.05, substeps=4)
    state = run(train, 20.0, 1.0)
    assert state.force == pytest.approx(20.0 * (1 - math.exp(-1.0 / 0.5)), rel=1e-6)


def test_traction_never_exceeds_the_envelope():
    p = TrainParameters(mass=388.4, max_traction_force=220.0, max_traction_power=8760.0,
                        max_brake_force=213.6, max_brake_power=12000.0, **QUIET)
    weight = p.mass * p.gravity
    train = PointMassTrain(p, 0.05)
    for _ in range(20000):
        v = train.state.speed
        train.step(1e6)
        allowed = min(220.0, 8760.0 / max(train.state.speed, 1e-6)) * 1000 / weight
        assert train.state.force <= allowed * (1 + 1e-12)
        power_kw = train.state.force * weight / 1000 * train.state.speed
        assert power_kw <= 8760.0 * (1 + 1e-9)
    assert v > 50.0  # it got well into the constant-power region
    low, _ = p.force_limits(train.state.speed)
    assert low == pytest.approx(-min(213.6, 12000.0 / train.state.speed) * 1000 / weight)
