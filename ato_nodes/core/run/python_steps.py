"""Controllers without compiled steps, inside the loop (compiled, or as Python): the loop calls the
controller's own Python start and step (numba's object mode, ~2 us a call), so the
plant, the line, the plan's horizons and the scoring run compiled around it while
the controller computes what it computes in its node: the same object, given the same
numbers, so the same bits (tests/test_stages.py).

The compiled loop is handed a PythonController (the controller's slot in RUNNING)
as the kind's settings and state; every such kind shares its one compiled signature.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from contextlib import contextmanager, nullcontext
from typing import Any, NamedTuple

import numpy as np

from ..base.kernels import jitable, objmode
from ..control.stepped import ControllerSteps


class PythonController(NamedTuple):
    slot: int  # the controller's key in RUNNING


def _as_python(**types):
    """Without numba: the controller's call is Python anyway."""
    return nullcontext()


_objmode = objmode if objmode is not None else _as_python

RUNNING: dict[int, Any] = {}  # the controller stages of the runs in progress, by slot
_slots = itertools.count()


@contextmanager
def running(stage) -> Iterator[PythonController]:
    """The controller `stage` (its controller and limiter, a retune's controller too)
    reachable from compiled code for the time of a run."""
    slot = next(_slots)
    RUNNING[slot] = stage
    try:
        yield PythonController(slot)
    finally:
        del RUNNING[slot]


def _start(slot: int, target: float, measured: float, horizon: np.ndarray) -> None:
    RUNNING[slot].controller.start(target, measured, horizon)


def _step(slot: int, target: float, measured: float, horizon: np.ndarray, last: float,
          slip_hold: bool) -> tuple[float, np.ndarray]:
    stage = RUNNING[slot]
    if slip_hold:  # the loop's last, held at the rail (ControllerStage.run_ready_steps)
        stage.limiter.last = last
    output = stage.controller.step(target, measured, horizon)
    return output.u, np.array(output.extras, dtype=float)


@jitable
def python_start(settings: PythonController, state: PythonController, target: float,
                 measured: float, horizon) -> PythonController:
    with _objmode():
        _start(state.slot, target, measured, horizon)
    return state


@jitable
def python_step(settings: PythonController, state: PythonController, target: float,
                measured: float, horizon, last: float, limits):
    """The controller's step; it applies its own limiter (`last`, held at the rail, read
    with controller.slip_hold only)."""
    with _objmode(u="float64", outputs="float64[:]"):
        u, outputs = _step(state.slot, target, measured, horizon, last, limits.slip_hold)
    return u, outputs, state


PYTHON_STEPS = ControllerSteps(python_start, python_step, PythonController)
