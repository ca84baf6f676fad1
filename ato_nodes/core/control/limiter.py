"""What stands between every control law and the train (ROS-free)."""

from __future__ import annotations

from typing import NamedTuple

from ..base.errors import ScenarioError
from ..base.kernels import jitable
from ..base.spec import param

LIMITER_PARAMETERS = (
    param("controller.u_min", -1e6, "lowest command (braking), N/kN", "controller", -1e9, 0.0),
    param("controller.u_max", 1e6, "highest command (traction), N/kN", "controller", 0.0, 1e9),
    param("controller.max_rate", 0.0, "jerk limit: largest change of the command per second, "
          "N/kN/s (0 = none)", "controller", 0.0, 1e9),
    param("controller.mode_band", 0.0, "speed-limit module (seed 003): no traction while the "
          "speed is more than this above the target, no braking while more than this below, "
          "m/s (0 = off)", "controller", 0.0, 100.0),
    param("controller.holding_brake", 0.0, "braking held with a zero target once the train is "
          "stopped (station berth), N/kN (0 = none)", "controller", 0.0, 1e6),
    param("controller.holding_target", 0.0, "the holding brake applies once the target is at "
          "most this, m/s (0 = only a zero target; a distance-indexed target is a few mm/s in "
          "the last centimetres before the mark, where a train would otherwise creep for "
          "seconds; keep it below the departure target)", "controller", 0.0, 1.0),
    param("controller.slip_hold", False, "while the drive's anti-slip or the wheel-slide "
          "protection acts, the command asks at most the force the rail gives, and the jerk "
          "limit ramps it from there "
          "(the achieved effort a train's TCMS reports to its ATO; the plant publishes it on "
          "/train/drive_effort): back-calculation, so that a slipping train's command, and the "
          "observer fed with it, is not wound up past what the rail gives (needs "
          "controller.max_rate)", ("plant", "controller")),
)


STOPPED = 0.1  # m/s: below this (measured) speed a train with a zero target is held


class LimiterSettings(NamedTuple):
    """A CommandLimiter's settings, as limit_command() reads them."""

    u_min: float           # N/kN
    u_max: float           # N/kN
    max_change: float      # N/kN per period (0: no jerk limit)
    mode_band: float       # m/s (0: off)
    holding_brake: float   # N/kN (0: none)
    holding_target: float  # m/s
    slip_hold: bool = False  # the command held at the rail's force while the wheels slip


@jitable
def clamp(x: float, low: float, high: float) -> float:
    return low if x < low else high if x > high else x


@jitable
def holds(target: float, speed: float, settings: LimiterSettings) -> bool:
    """Whether the holding brake holds the train at its berth: a holding brake, the
    target at most holding_target, the train (nearly) stopped."""
    return settings.holding_brake > 0.0 and target <= settings.holding_target \
        and speed < STOPPED


@jitable
def limit_command(u: float, target: float, speed: float, last: float,
                  settings: LimiterSettings) -> float:
    """The command the limiter lets through (see CommandLimiter); `last` the previous
    one."""
    s = settings
    if holds(target, speed, s):
        u = min(u, -s.holding_brake)
    if s.mode_band > 0.0:
        if speed > target + s.mode_band:
            u = min(u, 0.0)
        elif speed < target - s.mode_band:
            u = max(u, 0.0)
    if s.max_change > 0.0:
        u = clamp(u, last - s.max_change, last + s.max_change)
    return clamp(u, s.u_min, s.u_max)


@jitable
def held_at_rail(last: float, effort: float, change: float) -> float:
    """The command the jerk limit ramps from with controller.slip_hold: the last one, or
    while the drive's anti-slip or the wheel-slide protection acts (`effort`, N/kN: the
    force the rail gives; NaN while the wheels roll) at most `change` (a period's ramp)
    short of it, so that the command asks no more than the rail gave and the wheels grip
    again."""
    if effort > 0.0:
        return min(last, effort - change)
    if effort < 0.0:
        return max(last, effort + change)
    return last


@jitable
def limit_under(u: float, ceiling: float, target: float, speed: float, last: float,
                settings: LimiterSettings) -> float:
    """limit_command of `u` asked at most `ceiling` (N/kN; inf: no bound, `u`'s bits). A
    ceiling of 0 (no traction: a neutral section) holds even where the jerk limit would
    keep some: its ramp came too late (a run started near the section, a speed that
    grew)."""
    limited = limit_command(ceiling if u > ceiling else u, target, speed, last, settings)
    return 0.0 if ceiling == 0.0 and limited > 0.0 else limited


class CommandLimiter:
    """What stands between a control law and the train, shared by every controller;
    the observer is fed its output, the command actually applied.

    * speed-limit module (seed 003), `mode_band` > 0: no traction while the speed is
      more than mode_band above the target, no braking while more than mode_band below
      (it picks traction or braking by comparing actual and target speed);
    * jerk limit, `max_rate` > 0: the command moves at most max_rate * h per period
      (jerk ~ xi * max_rate with the train's xi, m/s^2 per N/kN);
    * saturation to [u_min, u_max] (acceleration limit);
    * slip hold, `slip_hold`: while the wheels slip or slide, the command asks at most
      the force the rail gives and the jerk limit ramps from there, not from the last
      command (held_at_rail; the stage and the loop hold `last` before the step);
    * holding brake, `holding_brake` > 0: with a zero target (at most `holding_target`)
      and the train (nearly) stopped, at least this much braking, as an ATO holds a train
      berthed at a station; without it a controller dithers about zero speed and creeps.
    """

    def __init__(self, u_min: float, u_max: float, period: float = 0.0, max_rate: float = 0.0,
                 mode_band: float = 0.0, holding_brake: float = 0.0,
                 holding_target: float = 0.0, slip_hold: bool = False):
        if slip_hold and not max_rate > 0.0:
            raise ScenarioError("controller.slip_hold holds the command's ramp at the force the "
                                "rail gives: it needs controller.max_rate above 0")
        self.u_min, self.u_max = u_min, u_max
        self.max_change = max_rate * period
        self.mode_band = mode_band
        self.holding_brake, self.holding_target = holding_brake, holding_target
        self.settings = LimiterSettings(u_min, u_max, self.max_change, mode_band, holding_brake,
                                        holding_target, bool(slip_hold))
        self.last = 0.0

    def apply(self, u: float, target: float, speed: float) -> float:
        self.last = limit_command(u, target, speed, self.last, self.settings)
        return self.last

    @classmethod
    def from_values(cls, values) -> CommandLimiter:
        return cls(values["controller.u_min"], values["controller.u_max"], values["run.period"],
                   values["controller.max_rate"], values["controller.mode_band"],
                   values["controller.holding_brake"], values["controller.holding_target"],
                   values["controller.slip_hold"])
