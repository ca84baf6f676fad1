"""Controllers whose step is a plain function of NamedTuples: the settings (what a
run fixes: gains, period, the nominal train), the state (what it carries from step
to step) and the limiter's. The Python controller below and the compiled loop
(core/run/fast_loop.py) call the same two functions, so both give the same bits,
and a live change of gains carries the one `state` over (state_paths ("state",)).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Callable, NamedTuple

from ..base.registry import Controller, ControllerOutput
from .limiter import CommandLimiter


class ControllerSteps(NamedTuple):
    """A controller kind's start and step, both jitable (core/base/kernels.py):
    start(settings, state, target, measured, horizon) -> state;
    step(settings, state, target, measured, horizon, last, limits) -> (u, outputs, state),
    `target` the plan's speed now r_k, `horizon` r_k .. r_k+N (core/base/registry.py's
    Controller), `last` and `limits` the limiter's last command and LimiterSettings,
    `outputs` the kind's declared outputs in order."""

    start: Callable[..., Any]
    step: Callable[..., Any]
    state_type: type  # the kind's state NamedTuple: compiled code dispatches on it


STATE_PATHS = ("state",)  # what a live retune carries over (Component.state_paths)


class SteppedController(Controller):
    def __init__(self, steps: ControllerSteps, settings: NamedTuple, limiter: CommandLimiter,
                 state: NamedTuple | None = None):
        """`state` the state before the first step (default: the state type's defaults)."""
        self.steps, self.settings, self.limiter = steps, settings, limiter
        self.state = steps.state_type() if state is None else state

    def start(self, target: float, measured: float, horizon: Sequence[float]) -> None:
        self.state = self.steps.start(self.settings, self.state, target, measured, horizon)

    def step(self, target: float, measured: float, horizon: Sequence[float]
             ) -> ControllerOutput:
        limiter = self.limiter
        u, outputs, self.state = self.steps.step(self.settings, self.state, target, measured,
                                                 horizon, limiter.last, limiter.settings)
        limiter.last = u
        return ControllerOutput(u, outputs)
