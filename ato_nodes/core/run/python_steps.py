"""Controllers without compiled steps, inside the compiled loop: the loop calls the
controller's own Python start and step (numba's object mode, ~2 us a call), so the
plant, the line, the plan's horizons and the scoring run compiled around it while
the controller computes what it computes in the Python loop and in its node: the
same object, given the same numbers, so the same bits (tests/test_fast_loop.py).

The compiled loop is handed a PythonController (the controller's slot in RUNNING)
as the kind's settings and state; every such kind shares its one compiled signature.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any, NamedTuple

import numpy as np

from ..base.kernels import jitable, objmode
from ..control.stepped import ControllerSteps


class PythonController(NamedTuple):
    slot: int  # the controller's key in RUNNING


RUNNING: dict[int, Any] = {}  # the controllers of the runs in progress, by slot
_slots = itertools.count()


@contextmanager
def running(controller) -> Iterator[PythonController]:
    """`controller` reachable from compiled code for the time of a run."""
    slot = next(_slots)
    RUNNING[slot] = controller
    try:
        yield PythonController(slot)
    finally:
        del RUNNING[slot]


def _start(slot: int, target: float, measured: float) -> None:
    RUNNING[slot].start(target, measured)


def _step(slot: int, target: float, measured: float, horizon: np.ndarray
          ) -> tuple[float, np.ndarray]:
    output = RUNNING[slot].step(target, measured, horizon)
    return output.u, np.array(output.extras, dtype=float)


@jitable
def python_start(settings: PythonController, state: PythonController, target: float,
                 measured: float) -> PythonController:
    with objmode():
        _start(state.slot, target, measured)
    return state


@jitable
def python_step(settings: PythonController, state: PythonController, target: float,
                measured: float, horizon, last: float, limits):
    """The controller's step; it applies its own limiter (`last`, `limits` unread)."""
    with objmode(u="float64", outputs="float64[:]"):
        u, outputs = _step(state.slot, target, measured, horizon)
    return u, outputs, state


PYTHON_STEPS = ControllerSteps(python_start, python_step, PythonController)
