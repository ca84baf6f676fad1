"""The ATO's own model of its train, for controllers that use it (ROS-free).

What an ATO knows before the run (the run context's nominal train and line),
stepped along with the real train from the commands it sends and the speeds it
measures:

* the actuator: the commands still inside the dead time, the first-order lag
  (its state, discretised exactly for a command held over the period), the
  traction and brake envelope at the speed, traction cut while the pantograph
  is inside a neutral section (as core/train/plant.py does to the real train);
* where the train is: dead reckoning from the measured speeds (the position
  only picks the gradient under the train, so centimetres of drift do not matter);
* the known resistance: basic (Davis) plus gradient, curve and tunnel of the belt.

It predicts the speed some steps ahead from the commands already sent (then the
last one held), which is what a controller facing dead time and lag must act on.
The real train may differ (core/train/plant.py's plant.*_factor): the controller's
observer estimates what this model does not explain.
"""

from __future__ import annotations

import math
from collections import deque

from ..train.line import Line
from ..train.plant import TrainParameters
from .limiter import clamp


class NominalTrain:
    def __init__(self, train: TrainParameters, period: float, position: float = 0.0,
                 line: Line | None = None):
        self.train, self.h, self.line = train, period, line
        self.pending = deque([0.0] * round(train.dead_time / period))
        lag = train.actuator_lag
        self.decay = math.exp(-period / lag) if lag > 0.0 else 0.0
        self.spread = lag * (1.0 - self.decay) / period if lag > 0.0 else 0.0  # step mean
        self.limited = train.limited
        self.neutral = line is not None and bool(line.neutral_sections)
        self.lag_state = 0.0  # N/kN, the lag's output before the envelope
        self.position = position

    def _act(self, lag_state: float, command: float, speed: float, position: float
             ) -> tuple[float, float]:
        """One period with `command` reaching the lag: (next lag state, mean force N/kN)."""
        if self.neutral and command > 0.0 and self.line.in_neutral_section(
                position - self.train.pantograph_offset):
            command, powered = 0.0, False
        else:
            powered = True
        if self.limited:
            low, high = self.train.force_limits(speed)
            command = clamp(command, low, high)
        mean = command + (lag_state - command) * self.spread
        if self.limited:
            mean = clamp(mean, low, high)
        if not powered and mean > 0.0:
            mean = 0.0
        return command + (lag_state - command) * self.decay, mean

    def advance(self, command: float, speed: float) -> float:
        """The period that starts now, `command` just sent and `speed` just measured:
        the mean force the train will apply over it, N/kN (the model moves on)."""
        if self.pending:
            self.pending.append(command)
            command = self.pending.popleft()
        self.lag_state, mean = self._act(self.lag_state, command, speed, self.position)
        self.position += self.h * speed
        return mean

    def known_resistance(self, speed: float, position: float) -> float:
        """Basic plus line resistance the model knows at `speed` and `position`, N/kN."""
        resistance = self.train.resistance(speed)
        if self.line is not None:
            resistance += self.line.additional_resistance(position, self.train.length)
        return resistance

    def predict(self, speed: float, unexplained: float, gain: float, steps: int,
                held: float, resisted: bool = True) -> float:
        """The speed `steps` periods from now, from `speed` now: the commands inside the
        dead time act in turn, then `held`; acceleration gain (force - known
        resistance) + `unexplained` (m/s^2, an observer's estimate of the rest; without
        `resisted` it holds the resistance too, and the model's is left out)."""
        h, lag_state, position = self.h, self.lag_state, self.position
        queued = iter(self.pending)
        for _ in range(steps):
            command = next(queued, held)
            lag_state, mean = self._act(lag_state, command, speed, position)
            if resisted:
                mean -= self.known_resistance(speed, position)
            acceleration = gain * mean + unexplained
            position += h * speed
            speed += h * acceleration
        return speed
