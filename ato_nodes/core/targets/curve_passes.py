"""The ATO curve's passes over its grid (core/targets/profiles.py AtoCurve), as loops that
numba compiles when it is installed (core/base/kernels.py; without it they run as Python).

The on-time curve bisects its cruise speed: some sixty curves of up to 10^5 cells each,
every one capped, rounded in time and timed. As numpy expressions each curve took a few
dozen passes over its arrays; here it is a few loops. Every loop computes what the numpy
expression it stands for computes, operation for operation, so the curves keep their
bits: np.interp's formula (interpolated_in), np.cumsum's sums in order, np.sum's pairwise
sum (pairwise_sum), np.minimum's and np.maximum's choice of operand
(tests/test_curve_passes.py holds each against numpy, compiled and as Python).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..base.kernels import compiled, jitable
from ..train.plant import Envelope, basic_resistance, force_limits

ROUNDING_WIDTH = 20  # samples per averaging window of round_corners
PAIRWISE_BLOCK = 128  # numpy's pairwise summation sums blocks up to this long in 8 lanes


class CurveGrid(NamedTuple):
    """What an ATO curve's passes read of its grid, the same for each of its cruise speeds:
    the cells' positions (m) and what the forward pass knows of them (Cells), the curve
    without a cruise speed, the limits the rounded curve keeps under and the braking into
    the mark, both m/s; the train's envelope and resistance, and the planned rates."""

    x: np.ndarray
    feasible: np.ndarray
    powered: np.ndarray
    line_resistance: np.ndarray
    neutral_entries: np.ndarray  # cells where a neutral section starts (int64)
    ceiling: np.ndarray          # limits less half the margin
    stop_curve: np.ndarray
    envelope: Envelope
    davis_a: float
    davis_b: float
    davis_c: float
    xi: float
    share: float
    acceleration: float   # m/s^2
    deceleration: float   # m/s^2
    power_speed: float    # m/s
    start: float          # the start speed squared, m^2/s^2


@jitable
def interpolated_in(x: float, x0: float, x1: float, y0: float, y1: float, slope: float
                    ) -> float:
    """np.interp at an x in the cell from (x0, y0) to (x1, y1), x0 <= x < x1, of slope
    `slope` (sloped), as numpy's C code computes it. Scalars only: compiled code counts
    the references of every array it hands to a function, dearer than this arithmetic."""
    if x0 == x:
        return y0
    result = slope * (x - x0) + y0
    if result != result:  # numpy tries the other end, then a flat segment's value
        result = slope * (x - x1) + y1
        if result != result and y0 == y1:
            result = y0
    return result


@jitable
def sloped(x0: float, x1: float, y0: float, y1: float) -> float:
    """The slope of the cell from (x0, y0) to (x1, y1) as np.interp computes it."""
    return (y1 - y0) / (x1 - x0)


@jitable
def interpolated_along(xs, points, values) -> np.ndarray:
    """np.interp(xs, points, values) for xs not decreasing and increasing points, walking
    the cells once instead of searching each (with more xs than points every cell's slope
    first, as numpy does: a division per x would cost more than the rest)."""
    ahead = len(points) <= len(xs)
    slopes = np.empty(len(points) - 1 if ahead else 0)
    for j in range(len(slopes)):
        slopes[j] = sloped(points[j], points[j + 1], values[j], values[j + 1])
    out = np.empty(len(xs))
    last, j = len(points) - 1, 0
    for i in range(len(xs)):
        x = xs[i]
        if x != x:
            out[i] = x
        elif x >= points[last]:
            out[i] = values[last]
        elif x < points[0]:
            out[i] = values[0]
        else:
            while points[j + 1] <= x:
                j += 1
            x0, x1, y0, y1 = points[j], points[j + 1], values[j], values[j + 1]
            out[i] = interpolated_in(x, x0, x1, y0, y1,
                                     slopes[j] if ahead else sloped(x0, x1, y0, y1))
    return out


@jitable
def smaller(a: float, b: float) -> float:
    """np.minimum(a, b): NaN if either is, else b unless a is smaller."""
    return a if (a < b or a != a) else b


@jitable
def larger(a: float, b: float) -> float:
    """np.maximum(a, b): NaN if either is, else b unless a is larger."""
    return a if (a > b or a != a) else b


@jitable
def block_sum(values, first: int, count: int) -> float:
    """numpy's pairwise sum of values[first:first + count], count <= PAIRWISE_BLOCK: in
    order under 8, else in 8 lanes added up as a tree, then the rest in order."""
    if count < 8:
        total = 0.0
        for i in range(first, first + count):
            total += values[i]
        return total
    lanes = values[first:first + 8].copy()
    i = 8
    while i < count - count % 8:
        for lane in range(8):
            lanes[lane] += values[first + i + lane]
        i += 8
    total = ((lanes[0] + lanes[1]) + (lanes[2] + lanes[3])) + \
        ((lanes[4] + lanes[5]) + (lanes[6] + lanes[7]))
    for rest in range(first + i, first + count):
        total += values[rest]
    return total


@jitable
def pairwise_sum(values) -> float:
    """np.sum(values) of a contiguous float array, to its bits: numpy halves the array
    (at a multiple of 8) until the parts are blocks (block_sum), then adds the parts up
    as the halving paired them; here the halving's tree is walked with a stack."""
    firsts, counts = np.zeros(128, np.int64), np.zeros(128, np.int64)
    sums, pending = np.zeros(128), 0
    firsts[0], counts[0], tasks = 0, len(values), 1  # count -1: add the last two sums
    while tasks > 0:
        tasks -= 1
        first, count = firsts[tasks], counts[tasks]
        if count < 0:
            pending -= 1
            sums[pending - 1] = sums[pending - 1] + sums[pending]
        elif count <= PAIRWISE_BLOCK:
            sums[pending] = block_sum(values, first, count)
            pending += 1
        else:
            half = count // 2
            half -= half % 8
            firsts[tasks], counts[tasks] = 0, -1
            firsts[tasks + 1], counts[tasks + 1] = first + half, count - half
            firsts[tasks + 2], counts[tasks + 2] = first, half
            tasks += 3
    return 0.0 + sums[0]


@jitable
def cell_times(x, speeds) -> np.ndarray:
    """What each cell takes at the mean of its ends' speeds, s: 2 dx / (v0 + v1)."""
    cells = np.empty(len(x) - 1)
    for i in range(len(cells)):
        cells[i] = 2.0 * (x[i + 1] - x[i]) / (speeds[i] + speeds[i + 1])
    return cells


def _running_time(x, speeds) -> float:
    """The sum of cell_times, s (np.sum's bits)."""
    return pairwise_sum(cell_times(x, speeds))


running_time = compiled(_running_time) or _running_time


@jitable
def moving_mean(samples, width: int, after: float, lead: int) -> np.ndarray:
    """The mean over `width` samples of a curve sampled evenly, the window of sample i
    ending `lead` samples after it (0: the past; width // 2 of an odd width: centred);
    before its start the curve holds its first value, after its end `after`. The running
    sum is np.cumsum's, in order."""
    count = len(samples)
    sums = np.empty(count + 2 * width + 1)
    sums[0] = 0.0
    for k in range(count + 2 * width):
        value = samples[0] if k < width else samples[k - width] if k < width + count else after
        sums[k + 1] = value if k == 0 else sums[k] + value
    means = np.empty(count)
    for i in range(count):
        means[i] = (sums[i + width + lead + 1] - sums[i + lead + 1]) / width
    return means


@jitable
def round_corners_of(samples, width: int, after: float) -> np.ndarray:
    """A speed curve sampled evenly in time, its acceleration made continuous: the mean
    over `width` samples centred where it falls, over the past where it rises, so it
    brakes earlier and accelerates later than the corners, never the other way (the
    lower of the two means; the curve before its start holds its first value, after its
    end `after`). An acceleration step of da becomes a ramp of da / (width * tick)."""
    past = moving_mean(samples, width, after, 0)
    centred = moving_mean(samples, width, after, width // 2)
    for i in range(len(past)):
        past[i] = smaller(past[i], centred[i])
    return past


round_corners = compiled(round_corners_of) or round_corners_of


@jitable
def forward_pass_of(squared, first, x, powered, line_resistance, envelope, davis_a, davis_b,
                    davis_c, xi, share, acceleration, power_speed, start, to_end) -> None:
    """The forward pass of AtoCurve._feasible and of the capped curves from cell `first`,
    in place on squared speeds: each next cell the lower of its own value and what the
    planned acceleration, or the share of the traction envelope against the resistance
    (train.net_traction's terms), gives, at least `start`; it ends where it meets the
    cells' values on a powered cell, unless `to_end`."""
    v2 = squared[first]
    for i in range(first, len(x) - 1):
        v = math.sqrt(v2)
        traction = force_limits(v, envelope)[1] if powered[i] else 0.0
        net = share * traction - basic_resistance(v, davis_a, davis_b, davis_c) \
            - line_resistance[i]
        planned = acceleration if v <= power_speed else acceleration * power_speed / v
        v2 = max(v2 + 2.0 * min(planned, xi * net) * (x[i + 1] - x[i]), start)
        if v2 < squared[i + 1]:
            squared[i + 1] = v2
        elif powered[i + 1] and not to_end:
            return
        else:
            v2 = squared[i + 1]


forward_pass = compiled(forward_pass_of) or forward_pass_of


@jitable
def forward_from_each(grid: CurveGrid, squared, starts) -> np.ndarray:
    """The speeds whose squares are `squared` (changed in place), the forward pass run
    again from each cell of `starts`, kept under them, until it meets them on a powered
    cell (the speeds it leaves alone come back as they were: sqrt(x * x) is x in binary
    floating point)."""
    for first in starts:
        forward_pass_of(squared, first, grid.x, grid.powered, grid.line_resistance,
                        grid.envelope, grid.davis_a, grid.davis_b, grid.davis_c, grid.xi,
                        grid.share, grid.acceleration, grid.power_speed, grid.start, False)
    return np.sqrt(squared)


@jitable
def capped(grid: CurveGrid, cruise: float) -> np.ndarray:
    """The feasible curve capped at `cruise` where the share can hold that speed; where it
    cannot (a neutral section, a grade too steep for the share at that speed) falling
    from it as the forward pass does, until back on the cap."""
    traction = grid.share * force_limits(cruise, grid.envelope)[1]
    resistance = basic_resistance(cruise, grid.davis_a, grid.davis_b, grid.davis_c)
    squared = np.empty(len(grid.x))
    starts = np.empty(len(grid.x), np.int64)
    count, fell = 0, False
    for i in range(len(squared)):
        speed = smaller(grid.feasible[i], cruise)
        squared[i] = speed * speed
        held = ((traction if grid.powered[i] else 0.0) - resistance) - grid.line_resistance[i]
        falls = speed >= cruise and held < 0.0
        if falls and not fell:
            starts[count] = i
            count += 1
        fell = falls
    return forward_from_each(grid, squared, starts[:count])


capped_curve = compiled(capped) or capped


@jitable
def turn_centres(timed, tick: float, width: int, deceleration: float) -> np.ndarray:
    """The ticks midway between each turn from traction (accelerating) into braking (at
    least half the service deceleration) and the last traction before it, where that is
    less than `width` ticks back (AtoCurve._rounded)."""
    centres = np.empty(len(timed))
    count, last_traction, was_braking = 0, -1, False
    for k in range(len(timed) - 1):
        acceleration = (timed[k + 1] - timed[k]) / tick
        if acceleration > 0.0:
            last_traction = k
        braking = acceleration < -0.5 * deceleration
        if braking and not was_braking and last_traction >= 0 and k - last_traction < width:
            centres[count] = (k + last_traction) / 2.0
            count += 1
        was_braking = braking
    return centres[:count]


@jitable
def turn_weights(centres, samples: int, width: int) -> np.ndarray:
    """The second mean's weight per tick: 1 within ROUNDING_WIDTH + width of a turn's
    centre, falling to 0 over a further width."""
    reach = ROUNDING_WIDTH + width
    weights = np.empty(samples)
    for i in range(samples):
        distance = abs(i - centres[0])
        for centre in centres[1:]:
            distance = min(distance, abs(i - centre))
        weights[i] = smaller(larger((reach + width - distance) / width, 0.0), 1.0)
    return weights


@jitable
def rounded(x, speeds, ceiling, stop_curve, deceleration: float, tick: float, width: int
            ) -> np.ndarray:
    """AtoCurve._rounded's curve: `speeds` rounded in time along themselves to ticks of
    `tick` s (round_corners over ROUNDING_WIDTH ticks, then the centred mean over `width`
    around each turn, kept over `stop_curve`), back on the grid `x`, under `ceiling`."""
    times = np.empty(len(speeds))
    times[0] = 0.0
    cells = cell_times(x, speeds)
    for i in range(len(cells)):
        times[i + 1] = cells[i] if i == 0 else times[i] + cells[i]
    # np.arange(0.0, stop, tick): ceil(stop / tick) ticks, i * tick
    ticks = np.arange(max(int(math.ceil((times[-1] + tick / 2) / tick)), 0)) * tick
    timed = interpolated_along(ticks, times, speeds)
    cornered = round_corners_of(timed, ROUNDING_WIDTH, 0.0)
    centres = turn_centres(timed, tick, width, deceleration)
    result = interpolated_along(times, ticks, cornered)
    if len(centres) > 0:
        weights = turn_weights(centres, len(timed), width)
        smoothed = moving_mean(cornered, width, 0.0, width // 2)
        turned = interpolated_along(times, ticks, cornered + weights * (smoothed - cornered))
        for i in range(len(result)):
            # the stop as round_corners rounds it (the wider mean would pass over it)
            result[i] = smaller(turned[i], larger(stop_curve[i], result[i]))
    for i in range(len(result)):
        result[i] = smaller(result[i], ceiling[i])
    result[0], result[-1] = speeds[0], 0.0
    return result


rounded_curve = compiled(rounded) or rounded


def _shaped_curve(grid: CurveGrid, cruise: float, tick: float, width: int) -> np.ndarray:
    """The feasible curve capped at `cruise`, rounded (`tick`, `width`: AtoCurve._rounded)
    and held to the coasting from each neutral section's start."""
    speeds = rounded(grid.x, capped(grid, cruise), grid.ceiling, grid.stop_curve,
                     grid.deceleration, tick, width)
    return forward_from_each(grid, speeds * speeds, grid.neutral_entries)


shaped_curve = compiled(_shaped_curve) or _shaped_curve
