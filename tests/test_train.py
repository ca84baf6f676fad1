"""Trains on lines: presets, grades, envelopes, neutral sections, dead time, the speed
sensor, the ATO curve and the seed-003/004 controllers (ROS-free)."""

import math
from dataclasses import replace

import numpy as np
import pytest

from ato_nodes.core.control.adrc import (DISCRETE_ADRC_STEPS, DiscreteADRCGains,
                                         DiscreteADRCSettings, fal, nladrc_gains)
from ato_nodes.core.control.stepped import SteppedController
from ato_nodes.core.control.limiter import CommandLimiter
from ato_nodes.core.train.line import parse_line
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.run.stages import PlantStage
from ato_nodes.core.targets.horizons import approach
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import apply_overrides, load_scenario, train_names, train_preset
from ato_nodes.core.config.schema import defaults
from ato_nodes.core.base.spec import settings
from ato_nodes.core.train.plant import PointMassTrain, TrainParameters, TrainState
from ato_nodes.core.targets.profiles import AtoCurve


def line(body: str, length: float = 100000.0, limit: float = 100.0):
    return parse_line(f"name: t\nlength: {length}\nspeed_limits:\n"
                      f"  - {{start: 0, end: {length}, limit: {limit}}}\n{body}")


def metro(**changes) -> TrainParameters:
    values = {**defaults(), **train_preset("metro-b"), "plant.envelope": True,
              "plant.disturbance.amplitude": 0.0}
    return replace(TrainParameters.from_values(values), **changes)


def test_every_preset_loads_and_a_scenario_overrides_its_preset(tmp_path):
    assert {"crh380al", "crh380a", "crh5", "metro-b", "maglev"} <= set(train_names())
    for name in train_names():
        assert train_preset(name)["plant.mass"] > 0
    scenario = tmp_path / "s.yaml"
    scenario.write_text("/**:\n  ros__parameters:\n    plant.train: metro-b\n"
                        "    plant.actuator_lag: 1.25\n")
    values = load_scenario(str(scenario))
    assert values["plant.mass"] == 194.3 and values["plant.actuator_lag"] == 1.25
    with pytest.raises(ScenarioError, match="unknown train 'tgv'"):
        apply_overrides(values, ["plant.train=tgv"])
    scenario.write_text("profile:\n  ros__parameters:\n    line.file: a.yaml\n"
                        "plant:\n  ros__parameters:\n    line.file: b.yaml\n")
    with pytest.raises(ScenarioError, match="line.file is shared by profile, plant, controller: "
                       "give it under /"):
        load_scenario(str(scenario))


def test_coasting_on_a_constant_grade_settles_where_grade_and_resistance_balance():
    params = metro(actuator_lag=0.0, dead_time=0.0, max_traction_force=math.inf)
    grade = -6.0  # per mille, downhill: the grade pulls with 6 N/kN
    train = PointMassTrain(params, 0.5, 1, TrainState(position=1000.0, speed=5.0),
                           line(f"gradients:\n  - {{start: 0, end: 100000, grade: {grade}}}"))
    for _ in range(12000):  # 6000 s, ~27 time constants of the approach
        train.step(0.0)
    a, b, c = params.davis_a, params.davis_b, params.davis_c
    balance = (-b + math.sqrt(b * b - 4 * c * (a + grade))) / (2 * c)  # w0(v) = -grade
    assert train.state.speed == pytest.approx(balance, rel=1e-6)


def test_plant_acceleration_uses_the_belt_resistance_of_the_line():
    track = line("gradients:\n  - {start: 0, end: 500, grade: 10}\n"
                 "  - {start: 500, end: 100000, grade: -5}")
    params = metro(actuator_lag=0.0, dead_time=0.0, max_traction_force=math.inf)
    for head in (300.0, 550.0, 700.0):  # on +10, straddling, on -5
        train = PointMassTrain(params, 0.1, 1, TrainState(position=head, speed=10.0), track)
        expected = params.xi * (20.0 - params.resistance(10.0)
                                - track.additional_resistance(head, params.length))
        train.motion = train.motion._replace(acting=20.0)
        assert train.acceleration() == pytest.approx(expected)
    assert track.additional_resistance(550.0, 118.0) == pytest.approx(
        (10.0 * 68.0 - 5.0 * 50.0) / 118.0)


def test_traction_and_braking_never_exceed_the_envelope_force_or_power():
    params = metro()
    weight = params.mass * params.gravity  # kN
    train = PointMassTrain(params, 0.1, 2, TrainState())
    forces, speeds = [], []
    for command in [1e3] * 600 + [-1e3] * 400:  # flat out, then full brake
        state = train.step(command)
        forces.append(state.force * weight / 1000.0)
        speeds.append(state.speed)
    forces, speeds = np.array(forces), np.array(speeds)
    assert speeds.max() > 60 / 3.6  # well into the constant-power region
    assert forces.max() <= params.max_traction_force + 1e-9
    assert -forces.min() <= params.max_brake_force + 1e-9
    assert np.max(forces * speeds) <= params.max_traction_power * (1 + 1e-9)
    assert np.max(-forces * speeds) <= params.max_brake_power * (1 + 1e-9)
    assert forces.max() == pytest.approx(params.max_traction_force, rel=1e-3)  # reached


def test_a_neutral_section_cuts_traction_exactly_while_the_pantograph_is_inside():
    period, start, end, offset = 0.01, 400.0, 650.0, 30.0
    track = line(f"neutral_sections:\n  - {{start: {start}, end: {end}}}")
    params = metro(actuator_lag=0.0, dead_time=0.0, pantograph_offset=offset)
    train = PointMassTrain(params, period, 1, TrainState(speed=15.0), track)
    cut, inside = 0.0, 0.0
    while train.state.position < end + offset + 100.0:
        was_inside = start <= train.state.position - offset < end
        speed = train.state.speed
        state = train.step(20.0)
        pantograph = state.position - offset
        assert (state.speed < speed) == was_inside  # the step's traction: where it starts
        cut += period if state.force == 0.0 else 0.0
        assert (state.force == 0.0) == (start <= pantograph < end)  # the force: where it ends
        inside += period if start <= pantograph < end else 0.0
    speed = 15.0  # at the start, and it gains: the time inside is (end - start) / v
    assert cut == pytest.approx(inside) and cut > 0.8 * (end - start) / (speed * 1.5)


def test_dead_time_delays_the_command_by_whole_periods():
    params = metro(actuator_lag=0.0, dead_time=0.3, max_traction_force=math.inf)
    train = PointMassTrain(params, 0.1, 1, TrainState(speed=10.0))
    forces = [train.step(50.0).force for _ in range(5)]
    assert forces == [0.0, 0.0, 0.0, 50.0, 50.0]


def test_a_held_train_does_not_roll_back_under_braking_or_on_an_up_grade():
    track = line("gradients:\n  - {start: 0, end: 100000, grade: 20}")
    params = metro(actuator_lag=0.0, dead_time=0.0, hold_at_standstill=True)
    train = PointMassTrain(params, 0.1, 2, TrainState(position=100.0, speed=1.0), track)
    for _ in range(100):
        train.step(-30.0)
    assert train.state.speed == 0.0 and train.state.position > 100.0


def test_the_speed_sensor_is_seeded_noisy_and_quantised():
    values = load_scenario("seed004-metro")

    def readings(**changes):
        stage = PlantStage({**values, **changes})
        return np.array([stage.outputs().measured_speed for _ in range(2000)])

    first, again = readings(), readings()
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first, readings(**{"plant.noise_seed": 5}))
    noisy = readings(**{"plant.speed_quantum": 0.0, "plant.speed_noise": 0.05})
    assert np.std(noisy) == pytest.approx(0.05, rel=0.1)
    steps_of_quantum = first / 0.01
    np.testing.assert_allclose(steps_of_quantum, np.round(steps_of_quantum), atol=1e-9)


TRACK = """gradients:
  - {start: 0, end: 3000, grade: 0}
speed_limits:
  - {start: 0, end: 1000, limit: 15}
  - {start: 1000, end: 2000, limit: 25}
  - {start: 2000, end: 3000, limit: 12}
stations:
  - {name: A, position: 0}
  - {name: B, position: 2900}
"""


def ato_line(planned=None):
    return parse_line("name: t\nlength: 3000\n"
                      + (f"planned_run_time: {planned}\n" if planned else "") + TRACK)


def test_the_ato_curve_respects_limits_braking_and_the_stop():
    curve = AtoCurve(ato_line(), 0.6, 0.8, margin=1.0, start_speed=0.3, train_length=100.0)
    assert curve.limit(999.9) == 15.0 and curve.limit(1099.9) == 15.0
    assert curve.limit(1100.0) == 25.0
    x, v = curve.positions, curve.speeds
    assert np.all(v <= curve.limits - 1.0 + 1e-9)
    assert v[0] == pytest.approx(0.3) and v[-1] == 0.0 and x[-1] == 2900.0
    assert curve.speed(0.0, 2950.0) == 0.0
    assert np.all(v[(x > 1000) & (x < 1100)] <= 14.0 + 1e-9)  # raised only once the tail is past
    # Braking never needs more than the planned deceleration, acceleration likewise.
    change = np.diff(v * v) / (2 * np.diff(x))
    assert change.min() >= -0.8 - 1e-9 and change.max() <= 0.6 + 1e-9
    # Stopping curve into the mark: v = sqrt(2 b d).
    assert curve.speed(0.0, 2890.0) == pytest.approx(math.sqrt(2 * 0.8 * 10.0), rel=1e-3)


def test_above_the_power_speed_the_planned_acceleration_falls_as_one_over_v():
    curve = AtoCurve(ato_line(), 0.6, 0.8, power_speed=8.0)
    x, v = curve.positions, curve.speeds
    rising = (x > 5) & (x < 600) & (np.gradient(v) > 0) & (v < curve.caps - 0.2)
    acceleration = v * np.gradient(v, x)  # dv/dt = v dv/dx
    expected = 0.6 * np.minimum(1.0, 8.0 / np.maximum(v, 8.0))
    np.testing.assert_allclose(acceleration[rising], expected[rising], rtol=0.02)


def test_a_stop_jerk_eases_the_braking_off_into_the_mark():
    curve = AtoCurve(ato_line(), 0.6, 0.8, stop_jerk=0.4)
    d = np.linspace(0.0, 30.0, 3001)
    v = curve.stopping(d)
    deceleration = v * np.gradient(v, d)
    assert v[0] == 0.0 and np.all(np.diff(v) > 0)
    assert deceleration.max() <= 0.8 + 1e-3
    ease = 0.8 / 0.4  # s of easing off; inside it, deceleration = j t and v = j t^2 / 2
    inside = (v > 0.1) & (v < 0.4 * ease ** 2 / 2 * 0.95)
    np.testing.assert_allclose(deceleration[inside], np.sqrt(2 * 0.4 * v[inside]), rtol=0.02)
    assert curve.speed(0.0, 2899.0) < AtoCurve(ato_line(), 0.6, 0.8).speed(0.0, 2899.0)


def test_the_ato_curve_meets_the_planned_run_time_with_the_lowest_cruise_speed():
    fastest = AtoCurve(ato_line(), 0.6, 0.8, margin=1.0)
    planned = fastest.planned_run_time * 1.15
    curve = AtoCurve(ato_line(planned), 0.6, 0.8, margin=1.0)
    assert curve.planned_run_time == pytest.approx(planned, rel=1e-6)
    assert curve.cruise < fastest.cruise
    slow = AtoCurve(ato_line(fastest.planned_run_time * 0.9), 0.6, 0.8, margin=1.0)
    assert slow.cruise == fastest.cruise  # an impossible plan runs at the limits


def test_the_stepped_approach_holds_a_stair_one_step_above_the_speed():
    stair, published = math.nan, []
    for target, speed in ((20.0, 5.0), (20.0, 6.0), (20.0, 6.8), (20.0, 19.0), (3.0, 10.0)):
        value, stair = approach(2.0, stair, target, speed)
        published.append(value)
    # not reached yet: the stair holds; within a quarter step: the next stair; close: the
    # target itself; braking targets are never softened
    assert published == [7.0, 7.0, 8.8, 20.0, 3.0]


def test_the_command_limiter_bands_modes_limits_rate_and_saturates():
    limiter = CommandLimiter(-50.0, 60.0, period=0.1, max_rate=100.0, mode_band=0.5)
    assert limiter.apply(30.0, target=10.0, speed=10.0) == 10.0     # rate: 100 * 0.1
    assert limiter.apply(30.0, target=10.0, speed=11.0) == 0.0      # 1 m/s above: no traction
    assert limiter.apply(-30.0, target=10.0, speed=9.0) == 0.0      # 1 m/s below: no braking
    limiter = CommandLimiter(-50.0, 60.0)
    assert limiter.apply(1e4, 0.0, 0.0) == 60.0 and limiter.apply(-1e4, 0.0, 0.0) == -50.0


def test_nladrc_is_han_adrc_with_a_bandwidth_parametrised_observer():
    gains = nladrc_gains(kp=3.0, kd=2.0, omega=4.0, b=0.5, alpha1=0.75, alpha2=1.25, r0=15.0,
                         h0=0.01, delta=0.01)
    assert (gains.beta1, gains.beta2, gains.beta3) == (12.0, 48.0, 64.0)
    assert (gains.mu1, gains.mu2, gains.b0, gains.r0, gains.h0) == (3.0, 2.0, 0.5, 15.0, 0.01)


def test_the_discrete_adrc_follows_the_printed_equations_for_one_step():
    g = settings(DiscreteADRCGains, "dadrc", defaults())._replace(
        b01=0.8, b02=0.2, b03=0.01, b1=30.0, b2=50.0, b0=2e-4)
    controller = SteppedController(DISCRETE_ADRC_STEPS, DiscreteADRCSettings(g, 0.1),
                                   CommandLimiter(-1e9, 1e9))
    controller.start(1.0, 1.0, [1.0])
    controller.state = controller.state._replace(z2=0.05, z3=0.002, u_applied=10.0)
    out = controller.step(2.0, 1.2, [2.0])
    e = 1.0 - 1.2
    z1 = 1.0 + 0.05 - 0.8 * e
    z2 = 0.05 + 0.002 - 0.2 * fal(e, 0.5, 0.01) + 2e-4 * 10.0
    z3 = 0.002 - 0.01 * fal(e, 0.25, 0.01)
    v1, v2 = controller.state.v1, controller.state.v2
    u = 30.0 * fal(v1 - z1, 0.75, 0.01) + 50.0 * fal(v2 * 0.1 - z2, 0.5, 0.01) - z3 / 2e-4
    assert out.u == pytest.approx(u) and out.extras[0] == pytest.approx(z1)
    assert out.extras[1] == pytest.approx(z2 / 0.1) and out.extras[2] == pytest.approx(z3 / 0.01)


@pytest.mark.parametrize("scenario", ["seed004-metro", "seed003-maglev", "hsr-neutral"])
def test_untuned_line_scenarios_run_to_the_station_under_the_limit(scenario):
    values = load_scenario(scenario)
    series = simulate(values)
    assert len(series["t"]) == round(values["run.duration"] / values["run.period"])
    assert np.all(series["target"] <= series["speed_limit"] + 1e-9)  # never above the limit
    stop = {"seed004-metro": 2600.0, "seed003-maglev": 9000.0, "hsr-neutral": 30000.0}[scenario]
    assert series["speed"][-1] == 0.0 and abs(series["position"][-1] - stop) < 10.0


def test_the_scorer_takes_the_line_from_the_bag_and_j_uses_the_notch_level():
    from ato_nodes.core.run.scoring import LINE_BASE64, encode_line, notch_level, score_series
    t = np.arange(0.0, 10.0, 1.0)
    series = {"t": t, "target": np.zeros_like(t), "speed": np.zeros_like(t),
              "position": np.full_like(t, 2899.5), "acceleration": np.zeros_like(t),
              "force": np.zeros_like(t), "command": np.where(t < 5, 50.0, -20.0)}
    parameters = {"profile.kind": "ato", "plant.mass": 200.0, "controller.u_max": 100.0,
                  "controller.u_min": -40.0,
                  LINE_BASE64: encode_line("name: t\nlength: 3000\nplanned_run_time: 5\n" + TRACK)}
    indices = score_series(series, parameters)
    assert indices["stopping_error"] == pytest.approx(-0.5)  # B's mark is at 2900 m
    np.testing.assert_allclose(notch_level(series["command"], parameters),
                               np.where(t < 5, 0.5, -0.5))
    assert indices["j_seed004"] == pytest.approx(10.0 * 0.25 * 9.0)  # |e| = 0, u^2 = 0.25
    unlimited = {**parameters, "controller.u_max": 1e6, "controller.u_min": -1e6}
    np.testing.assert_array_equal(notch_level(series["command"], unlimited), series["command"])


def test_the_scorer_finds_the_stepped_approach_and_the_error_outside_it():
    from ato_nodes.core.run.scoring import score_series
    values = apply_overrides(load_scenario("seed003-maglev"), ["run.duration=80"])
    series = simulate(values)
    indices = score_series(series, values)
    assert indices["stepped_time"] > 5.0  # the departure climbs in 2 km/h stairs
    assert indices["max_abs_error_outside_steps_kmh"] <= indices["max_abs_error_kmh"]
    smooth = apply_overrides(values, ["profile.approach_step=0"])
    indices = score_series(simulate(smooth), smooth)
    assert "stepped_time" not in indices


def test_the_tuned_metro_meets_the_operational_targets():
    """The shipped seed-004 tuning: stop within 0.3 m, jerk under 0.75 m/s^3 (1 s),
    never above the limit, and a lower J than the untuned gains."""
    from ato_nodes.core.run.scoring import score_series
    results = {}
    for scenario in ("seed004-metro", "seed004-metro-tuned"):
        values = load_scenario(scenario)
        series = simulate(values)
        results[scenario] = score_series(series, values)
        assert np.all(series["speed"] <= series["speed_limit"]) or scenario == "seed004-metro"
    tuned = results["seed004-metro-tuned"]
    assert tuned["abs_stopping_error"] <= 0.3 and tuned["max_jerk"] < 0.75
    assert tuned["overspeed_time"] == 0.0 and tuned["running_time_error"] <= 5.0
    assert tuned["j_seed004"] < results["seed004-metro"]["j_seed004"]


def test_the_tuned_maglev_tracks_better_than_the_untuned_one():
    from ato_nodes.core.run.scoring import score_series
    itae = {}
    for scenario in ("seed003-maglev", "seed003-maglev-tuned"):
        values = load_scenario(scenario)
        indices = score_series(simulate(values), values)
        itae[scenario] = indices["itae"]
    assert itae["seed003-maglev-tuned"] < 0.6 * itae["seed003-maglev"]
    assert indices["abs_stopping_error"] <= 0.5 and indices["overspeed_time"] == 0.0
