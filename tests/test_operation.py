"""Operation indices against values worked out by hand."""

import math

import numpy as np
import pytest

from ato_nodes.core.scoring.operation import format_operation, operation_indices


def run(t, speed=None, force=None, acceleration=None, position=None, **extra):
    t = np.asarray(t, dtype=float)
    zeros = np.zeros_like(t)
    series = {
        "t": t,
        "position": zeros if position is None else np.asarray(position, dtype=float),
        "speed": zeros if speed is None else np.asarray(speed, dtype=float),
        "acceleration": zeros if acceleration is None else np.asarray(acceleration, dtype=float),
        "force": zeros if force is None else np.asarray(force, dtype=float),
    }
    series.update({name: np.asarray(values, dtype=float) for name, values in extra.items()})
    return series


T = np.linspace(0.0, 100.0, 1001)


def test_constant_traction_energy():
    # 10 N/kN on 400 t: 10 * 400 * 9.8 / 1000 = 39.2 kN; at 20 m/s that is 784 kW
    # for 100 s = 78400 kJ at the wheel, drawn through eta = 0.8.
    series = run(T, speed=np.full_like(T, 20.0), force=np.full_like(T, 10.0))
    result = operation_indices(series, mass=400.0, gravity=9.8, efficiency=0.8)
    assert result["traction_energy_kwh"] == pytest.approx(78400.0 / 0.8 / 3600.0)
    assert result["regenerated_energy_kwh"] == 0.0
    assert result["net_energy_kwh"] == pytest.approx(result["traction_energy_kwh"])


def test_braking_regenerates_with_efficiency():
    # -5 N/kN on 400 t is 19.6 kN of braking; at 20 m/s for 100 s: 39200 kJ.
    series = run(T, speed=np.full_like(T, 20.0), force=np.full_like(T, -5.0))
    result = operation_indices(series, mass=400.0, efficiency=0.9)
    assert result["traction_energy_kwh"] == 0.0
    assert result["regenerated_energy_kwh"] == pytest.approx(39200.0 * 0.9 / 3600.0)
    assert result["net_energy_kwh"] == pytest.approx(-39200.0 * 0.9 / 3600.0)


def test_jerk_of_acceleration_ramp_is_its_slope():
    t = np.linspace(0.0, 10.0, 101)
    result = operation_indices(run(t, acceleration=0.3 * t), mass=400.0)
    assert result["max_jerk"] == pytest.approx(0.3)
    # total change 3 m/s^2 over 10 s
    assert result["comfort_index"] == pytest.approx(0.3)


def test_comfort_of_triangle():
    # acceleration 0 -> 1 -> 0 m/s^2 over 4 s: |change| adds to 2 over a 4 s span,
    # and the steepest slope is 1 m/s^2 in 2 s.
    t = np.linspace(0.0, 4.0, 41)
    acceleration = np.where(t <= 2.0, t / 2.0, (4.0 - t) / 2.0)
    result = operation_indices(run(t, acceleration=acceleration), mass=400.0)
    assert result["comfort_index"] == pytest.approx(0.5)
    assert result["max_jerk"] == pytest.approx(0.5)


def test_single_sample_has_no_jerk():
    result = operation_indices(run([0.0], acceleration=[1.0]), mass=400.0)
    assert result["max_jerk"] == 0.0 and result["comfort_index"] == 0.0


def test_switch_count_ignores_coasting():
    force = [3.0, 0.0, 2.0, -1.0, 0.2, -4.0, 1.0]
    t = np.arange(len(force), dtype=float)
    result = operation_indices(run(t, force=force), mass=400.0)
    assert result["switch_count"] == 2
    assert isinstance(result["switch_count"], int)
    # within the threshold is coasting: no mode at all, hence no switch
    small = run(t[:4], force=[0.4, -0.4, 0.4, -0.4])
    assert operation_indices(small, mass=400.0, switch_threshold=0.5)["switch_count"] == 0


def test_overspeed_time_and_excess():
    t = [0.0, 1.0, 2.0, 4.0, 5.0]
    speed = [10.0, 12.0, 12.0, 10.0, 13.0]
    series = run(t, speed=speed, speed_limit=np.full(5, 11.0))
    result = operation_indices(series, mass=400.0)
    # intervals starting at samples 1 (1 s) and 2 (2 s); the last sample adds no time
    assert result["overspeed_time"] == pytest.approx(3.0)
    assert result["max_overspeed_kmh"] == pytest.approx(2.0 * 3.6)


def test_below_limit_has_no_overspeed():
    series = run(T, speed=np.full_like(T, 5.0), speed_limit=np.full_like(T, 10.0))
    result = operation_indices(series, mass=400.0)
    assert result["overspeed_time"] == 0.0 and result["max_overspeed_kmh"] == 0.0


def test_missing_optional_inputs_leave_keys_out():
    result = operation_indices(run(T), mass=400.0)
    for key in ("overspeed_time", "max_overspeed_kmh", "stopping_error",
                "abs_stopping_error", "running_time_error", "abs_running_time_error"):
        assert key not in result


def test_stopping_error_sign():
    t = [0.0, 1.0]
    over = operation_indices(run(t, position=[990.0, 1000.3]), mass=400.0, stop_position=1000.0)
    assert over["stopping_error"] == pytest.approx(0.3)
    assert over["abs_stopping_error"] == pytest.approx(0.3)
    short = operation_indices(run(t, position=[990.0, 999.8]), mass=400.0, stop_position=1000.0)
    assert short["stopping_error"] == pytest.approx(-0.2)
    assert short["abs_stopping_error"] == pytest.approx(0.2)


def test_arrival_time_and_running_time_error():
    t = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]
    speed = [0.0, 5.0, 3.0, 1.0, 0.005, 0.0]
    result = operation_indices(run(t, speed=speed), mass=400.0, planned_run_time=3.5)
    # last moving sample is at 3 s, so the train stands from the next sample at 4 s
    assert result["arrival_time"] == pytest.approx(4.0)
    assert result["running_time_error"] == pytest.approx(0.5)
    early = operation_indices(run(t, speed=speed), mass=400.0, planned_run_time=4.75)
    assert early["running_time_error"] == pytest.approx(-0.75)
    assert early["abs_running_time_error"] == pytest.approx(0.75)  # punctuality either way


def test_arrival_is_nan_when_still_moving_or_never_moved():
    t = [0.0, 1.0, 2.0]
    moving = operation_indices(run(t, speed=[0.0, 2.0, 1.0]), mass=400.0, planned_run_time=2.0)
    assert math.isnan(moving["arrival_time"])
    assert math.isnan(moving["running_time_error"])
    assert math.isnan(operation_indices(run(t), mass=400.0)["arrival_time"])


def test_format_operation_lists_present_keys():
    lines = format_operation({"traction_energy_kwh": 12.346, "switch_count": 3,
                              "stopping_error": -0.25})
    assert lines == [
        "traction energy".ljust(17) + "12.35 kWh",
        "switches".ljust(17) + "3",
        "stopping error".ljust(17) + "-0.250 m",
    ]


def test_jerk_is_judged_over_one_second_and_per_sample():
    # The acceleration steps from -0.6 to 0 (a train stopping under braking), 0.1 s samples.
    t = np.arange(0.0, 5.0, 0.1)
    acceleration = np.where(t < 2.0, -0.6, 0.0)
    result = operation_indices(run(t, acceleration=acceleration), mass=400.0)
    assert result["max_jerk"] == pytest.approx(0.6)          # 0.6 m/s^2 over 1 s
    assert result["max_jerk_sampled"] == pytest.approx(6.0)  # 0.6 m/s^2 over 0.1 s
