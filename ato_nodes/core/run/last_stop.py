"""A journey's run ended at its last stop (run.last_stop_hold), ROS-free.

The plant ends the run once the train has stood at the timetable's last stop for
run.last_stop_hold: at or past run.last_stop_position (the last mark less
profile.journey.berth, which the scenario derives from the timetable, so the plant
needs no timetable of its own) with its true speed at most the scorer's STANDSTILL
(0.01 m/s, either way). The scorer's standstill rather than a speed of exactly 0: a
train held by the brakes stands at exactly 0 only with plant.hold_at_standstill, while
the scorer's rule holds with or without it, and the run then ends exactly the hold
after the arrival the per-station indices give (the first sample of the final
standstill, core/scoring/journey.py).

Step k's state (position and speed at t_k, the k-th recorded sample) is counted as
the step is applied; the run ends after the step whose state makes the train's
standing hold + 1 samples long, that is, with its last sample the hold (rounded to
whole periods) after the first standing one. The same functions count in the plant
stage (the node) and in the loop (simulate(), compiled or not), and count again from a
run's series (`planned_steps`: how many steps a recorded run was to make), so all
of them end at the same step. run.duration stays the longest a run may last.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..base.kernels import jitable
from ..config.schema import steps
from ..scoring.operation import STANDSTILL


# The reason of the plant's 'finished N REASON' for a run ended here: a complete run, as
# one ended at run.duration ('finished N'), unlike 'finished N diverged'.
AT_LAST_STOP = "at the last stop"


class LastStop(NamedTuple):
    """Where and how long a train stands at its last stop before the run ends."""

    position: float  # m: a train standing at or past it is at its last stop
    hold: int        # steps it stands there before the run ends (-1: the run ends at
                     # run.duration only)


NEVER = LastStop(math.inf, -1)


def last_stop(values) -> LastStop:
    """The run's LastStop from its values (run.last_stop_hold, run.last_stop_position;
    a bag of a version without them: NEVER)."""
    hold = values.get("run.last_stop_hold", 0.0)
    if hold <= 0.0:
        return NEVER
    return LastStop(float(values["run.last_stop_position"]),
                    int(round(hold / values["run.period"])))


@jitable
def standing(rule: LastStop, stood: int, position: float, speed: float) -> int:
    """The samples the train has stood at its last stop, with this one (position m and
    true speed m/s): `stood` + 1 while standing there, else 0."""
    if rule.hold >= 0 and abs(speed) <= STANDSTILL and position >= rule.position:
        return stood + 1
    return 0


@jitable
def held(rule: LastStop, stood: int) -> bool:
    """The train has stood its hold at the last stop: the run ends after this step."""
    return rule.hold >= 0 and stood > rule.hold


def planned_steps(values, position: np.ndarray, speed: np.ndarray) -> int:
    """The steps the run of `values` was to make, given its states (position and true
    speed of each step, recorded so far): steps(values), or the step after the one at
    which its train had stood its hold at the last stop."""
    rule, stood = last_stop(values), 0
    total = steps(values)
    if rule.hold < 0:
        return total
    for k in range(min(len(position), total)):
        stood = standing(rule, stood, float(position[k]), float(speed[k]))
        if held(rule, stood):
            return k + 1
    return total
