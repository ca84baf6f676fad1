"""Indices from series against closed forms (the trapezoid rule is exact on these)."""

import numpy as np
import pytest

from ato_nodes.core.scoring.indices import iae, ise, itae, seed004_j, tracking_indices


T = np.linspace(0.0, 10.0, 1001)


def test_constant_error():
    error = np.full_like(T, -0.5)
    assert itae(T, error) == pytest.approx(0.5 * 10.0 ** 2 / 2)
    assert iae(T, error) == pytest.approx(5.0)
    assert ise(T, error) == pytest.approx(2.5)
    assert seed004_j(T, error, np.full_like(T, 2.0), w1=1.0, w2=10.0) == pytest.approx(
        (0.5 + 10.0 * 4.0) * 10.0)


def test_ramp_error_itae():
    # integral of t * t from 0 to 10 = 1000/3; the trapezoid rule errs by h^2 T^... : tiny
    assert itae(T, T) == pytest.approx(1000.0 / 3.0, rel=1e-4)


def test_tracking_indices_in_kmh_and_finiteness():
    speed = np.zeros_like(T)
    target = np.where(T > 5.0, 1.0, 0.0)
    result = tracking_indices(T, target, speed, command=np.zeros_like(T))
    assert result["max_abs_error_kmh"] == pytest.approx(3.6)
    assert result["steps"] == len(T) and result["finite"]
    speed[3] = np.nan
    assert not tracking_indices(T, target, speed)["finite"]


def test_median_error_in_kmh():
    t = np.arange(5.0)
    result = tracking_indices(t, np.array([1.0, 1.0, 1.0, 1.0, 1.0]),
                              np.array([1.0, 0.9, 0.5, 1.2, 3.0]))
    assert result["median_abs_error_kmh"] == pytest.approx(0.2 * 3.6)  # |e|: 0 .1 .5 .2 2
