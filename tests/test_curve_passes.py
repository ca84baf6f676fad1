"""The ATO curve's passes (core/targets/curve_passes.py) give numpy's bits: compiled and
run as Python, against the numpy expressions they stand for, and on the shipped
scenarios' curves against the curve computed with numpy throughout."""

import math

import numpy as np
import pytest

from ato_nodes.core.base.kernels import AVAILABLE, compiled
from ato_nodes.core.config.context import RunContext
from ato_nodes.core.config.scenario import load_scenario
from ato_nodes.core.targets import curve_passes as passes
from ato_nodes.core.targets.curve_passes import ROUNDING_WIDTH

# each function compiled by itself (the module compiles only its entry points) and as Python
KINDS = [pytest.param(compiled, id="compiled",
                      marks=pytest.mark.skipif(not AVAILABLE, reason="numba not installed")),
         pytest.param(lambda function: function, id="python")]


@pytest.mark.parametrize("kind", KINDS)
def test_pairwise_sum_is_np_sum(kind):
    total = kind(passes.pairwise_sum)
    rng = np.random.default_rng(3)
    for count in [*range(0, 300, 7), 1023, 1024, 1025, 8193, 60001]:
        values = rng.random(count) * 10.0 ** rng.uniform(-6, 6, count)
        assert total(values) == np.sum(values), count


@pytest.mark.parametrize("kind", KINDS)
def test_interpolated_along_is_np_interp(kind):
    along = kind(passes.interpolated_along)
    rng = np.random.default_rng(4)
    points = np.cumsum(rng.random(500) + 1e-3)
    values = rng.random(500) * 80.0
    for xs in (np.sort(rng.uniform(points[0] - 5, points[-1] + 5, 3000)),  # more xs
               np.sort(rng.uniform(points[0] - 5, points[-1] + 5, 90)),    # fewer xs
               points.copy()):                                            # on the points
        assert along(xs, points, values).tobytes() == np.interp(xs, points, values).tobytes()


def numpy_round_corners(samples, width, after):
    """The numpy expression round_corners stands for."""
    padded = np.concatenate((np.full(width, samples[0]), samples, np.full(width, after)))
    sums = np.concatenate(([0.0], np.cumsum(padded)))
    i = np.arange(len(samples))
    past, centred = ((sums[i + width + lead + 1] - sums[i + lead + 1]) / width
                     for lead in (0, width // 2))
    return np.minimum(past, centred)


@pytest.mark.parametrize("kind", KINDS)
def test_round_corners_is_the_numpy_means(kind):
    corners = kind(passes.round_corners_of)
    samples = np.abs(np.cumsum(np.random.default_rng(5).normal(size=4000)))
    for width, after in ((ROUNDING_WIDTH, 0.0), (37, 0.0), (8, samples[-1])):
        assert (corners(samples, width, after).tobytes()
                == numpy_round_corners(samples, width, after).tobytes())


def numpy_curve(curve, cruise):
    """An ATO curve with a share and a jerk for `cruise`, with numpy's expressions
    throughout (the forward pass from curve_passes, checked in test_profiles.py)."""
    cells, train, x = curve.cells, curve.cells.train, curve.positions

    def forward(speeds, starts):
        squared = speeds ** 2
        for first in starts:
            passes.forward_pass(squared, int(first), x, cells.powered, cells.line_resistance,
                                train.envelope, train.davis_a, train.davis_b, train.davis_c,
                                train.xi, cells.share, curve.acceleration, curve.power_speed,
                                curve.start_speed ** 2, False)
        return np.sqrt(squared)

    speeds = np.minimum(curve.feasible, cruise)
    held = (np.where(cells.powered, cells.share * train.force_limits(cruise)[1], 0.0)
            - train.resistance(cruise) - cells.line_resistance)
    falls = (speeds >= cruise) & (held < 0.0)
    speeds = forward(speeds, np.flatnonzero(falls & ~np.concatenate(([False], falls[:-1]))))
    return forward(numpy_rounded(curve, speeds), cells.neutral_entries)


def numpy_rounded(curve, speeds):
    x = curve.positions
    times = np.concatenate(([0.0], np.cumsum(2.0 * np.diff(x) / (speeds[:-1] + speeds[1:]))))
    tick, width = curve._rounding
    grid = np.arange(0.0, times[-1] + tick / 2, tick)
    timed = np.interp(grid, times, speeds)
    cornered = numpy_round_corners(timed, ROUNDING_WIDTH, 0.0)
    centres = passes.turn_centres(timed, tick, width, curve.deceleration)
    rounded = np.interp(times, grid, cornered)
    if len(centres):
        distance = np.min(np.abs(np.arange(len(timed))[:, None] - centres[None, :]), axis=1)
        weights = np.clip((ROUNDING_WIDTH + 2 * width - distance) / width, 0.0, 1.0)
        padded = np.concatenate((np.full(width, cornered[0]), cornered, np.zeros(width)))
        sums = np.concatenate(([0.0], np.cumsum(padded)))
        i = np.arange(len(cornered))
        smoothed = (sums[i + width + width // 2 + 1] - sums[i + width // 2 + 1]) / width
        turned = np.interp(times, grid, cornered + weights * (smoothed - cornered))
        rounded = np.minimum(turned, np.maximum(curve._stop_curve, rounded))
    rounded = np.minimum(rounded, curve.limits - curve.margin / 2)
    rounded[0], rounded[-1] = speeds[0], 0.0
    return rounded


@pytest.mark.parametrize("scenario", ["seed004-metro-ato", "hsr-neutral-ato"])
def test_the_shipped_curves_are_the_numpy_curves(scenario):
    """The on-time curve, a slower one and the fastest (hsr-neutral-ato's turns from
    traction straight into braking: the second mean) of each scenario: compiled, as Python
    and with numpy throughout, the same bits; and so their running times (np.sum's)."""
    curve = RunContext(load_scenario(scenario)).plan
    tick, width = curve._rounding
    for cruise in (curve.cruise, 0.7 * curve.cruise, float(curve.caps.max())):
        expected = numpy_curve(curve, cruise)
        assert curve.curve(cruise).tobytes() == expected.tobytes()
        if cruise == curve.cruise:
            assert curve.speeds.tobytes() == expected.tobytes()
        python = passes._shaped_curve(curve.grid, cruise, tick, width)
        assert python.tobytes() == expected.tobytes()
        cells = 2.0 * np.diff(curve.positions) / (expected[:-1] + expected[1:])
        assert passes.running_time(curve.positions, expected) == np.sum(cells)
    assert math.isfinite(curve.planned_run_time)
