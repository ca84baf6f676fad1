"""The sliding-mode law's pure functions (ato_smc/law.py) and the kind's registration."""

import math

import pytest

from ato_nodes.plugin import LimiterSettings, TrainConstants
from ato_smc import SMC
from ato_smc.law import PARAMETERS, SMC_STEPS, SMCState, smc_settings

TRAIN = TrainConstants(xi=0.009, davis_a=1.0, davis_b=0.01, davis_c=0.001,
                       disturbance_amplitude=0.0, disturbance_frequency=0.0,
                       disturbance_phase=0.0, limited=False, actuator_lag=0.0,
                       hold_at_standstill=False, envelope=None, length=100.0)
OPEN = LimiterSettings(u_min=-1e6, u_max=1e6, max_change=0.0, mode_band=0.0,
                       holding_brake=0.0, holding_target=0.0)
DEFAULTS = {spec.name: spec.default for spec in PARAMETERS}
START = SMCState(0.0)


def settings(**gains):
    return smc_settings({**DEFAULTS, **{f"smc.{k}": v for k, v in gains.items()}}, 0.1, TRAIN)


def step(settings_, speed, horizon, state=START, limits=OPEN):
    return SMC_STEPS.step(settings_, state, horizon[0], speed, horizon, 0.0, limits)


def test_the_switching_term_is_linear_inside_the_boundary_layer_and_saturated_outside():
    s = settings(integral_weight=0.0, gain=20.0, boundary=0.5, feedforward=0.0)
    _, inside, _ = step(s, 9.9, [10.0])
    _, outside, _ = step(s, 8.0, [10.0])
    _, below, _ = step(s, 12.0, [10.0])
    assert inside[3] == pytest.approx(20.0 * 0.1 / 0.5)
    assert outside[3] == 20.0 and below[3] == -20.0


def test_the_feedforward_is_the_nominal_trains_for_the_horizons_end():
    s = settings(integral_weight=0.0, gain=0.0)
    u, outputs, _ = step(s, 10.5, [10.0, 10.5])  # tracks r_k+1, where the train is
    planned = 0.5 / 0.1 / TRAIN.xi
    resistance = 1.0 + 0.01 * 10.5 + 0.001 * 10.5 ** 2
    assert outputs[1] == pytest.approx(planned + resistance) and u == outputs[1]


def test_the_integral_grows_only_inside_the_boundary_layer_and_while_the_command_passes():
    s = settings(boundary=1.0)
    _, _, free = step(s, 9.5, [10.0])
    _, _, reaching = step(s, 8.0, [10.0])  # |s| = 2 > phi
    cut = LimiterSettings(-1.0, 1.0, 0.0, 0.0, 0.0, 0.0)
    u, _, held = step(s, 9.5, [10.0], limits=cut)
    assert free.integral == pytest.approx(0.05) and reaching.integral == 0.0
    assert u == 1.0 and held.integral == 0.0


def test_the_sliding_surface_weighs_the_integral():
    s = settings(integral_weight=0.5)
    _, outputs, _ = step(s, 9.0, [10.0], state=SMCState(2.0))
    assert outputs[0] == 1.0 + 0.5 * 2.0 and math.isfinite(outputs[2])


def test_the_kind_is_registered_by_its_entry_point():
    """This process imported ato_smc before ato_nodes (whose schema found the entry point
    while ato_smc was starting): the kind joins at the first load, as at a run's check."""
    from ato_nodes.core.config.components import CONTROLLERS
    from ato_nodes.core.config.schema import SPEC_BY_NAME
    from ato_nodes.plugin import load
    load()
    assert CONTROLLERS["smc"] is SMC
    assert SPEC_BY_NAME["smc.gain"].default == DEFAULTS["smc.gain"]
