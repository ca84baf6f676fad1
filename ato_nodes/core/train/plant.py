"""Single mass-point train (seed 000 eq. 1-2), ROS-free.

    ds/dt = v
    dv/dt = xi (F - w0(v)) + phi(t),   xi = g/1000 / (1 + gamma)
    w0(v) = a + b v + c v^2            [N/kN, v in m/s]
    phi(t) = A sin(omega t + phase)     [m/s^2]

F is the specific force actually applied by the train (N/kN, + traction,
- braking). The commanded force u reaches F through an optional dead time
(whole control periods), optional envelopes (constant force, then constant
power, for traction and braking) and an optional first-order actuator lag
tau: dG/dt = (sat(u) - G) / tau, F = sat(G) (seed 004's Gn(s); saturating
again after the lag keeps F inside the envelope as the speed changes). With
none of them (the paper-faithful variant) F = u.

On a line (core.line), the mass belt's gradient, curve and tunnel
resistance is added to w0 at the belt's position, and traction is cut
(command and applied force -> min(., 0)) during every sub-step that starts
with the pantograph inside a neutral section, and at a step's end there (the
recorded force and acceleration); it returns through the lag.
`hold_at_standstill` floors the speed at 0: a stopped train is held by its
brakes (acceleration 0) instead of rolling back.

Integration: classic RK4 with `substeps` equal sub-steps per control
period, the command held constant over the period (zero-order hold).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..base.kernels import jitable
from .adhesion import UNLIMITED, Adhesion, adhered, wheel_creep
from .line import Line, LineTables, belt_resistance, in_neutral_section, line_tables

OPEN_TRACK = line_tables(None, tuple)  # no gradients, curves, tunnels, limits or neutral sections


class Envelope(NamedTuple):
    """The traction and brake envelope: constant force, then constant power."""

    weight: float              # kN, converts the forces to N/kN
    max_traction_force: float  # kN (inf: no envelope)
    max_traction_power: float  # kW
    max_brake_force: float     # kN
    max_brake_power: float     # kW


class TrainConstants(NamedTuple):
    """What rates() and rk4_substep() read of the train (TrainParameters.constants()):
    plain values, so compiled code reads them by name too."""

    xi: float                     # m/s^2 per N/kN
    davis_a: float                # N/kN
    davis_b: float                # N/kN per m/s
    davis_c: float                # N/kN per (m/s)^2
    disturbance_amplitude: float  # m/s^2
    disturbance_frequency: float  # rad/s
    disturbance_phase: float      # rad
    limited: bool                 # the envelope applies
    actuator_lag: float           # s
    hold_at_standstill: bool
    envelope: Envelope
    length: float                 # m, the mass belt's (line resistance)
    adhesion: Adhesion = UNLIMITED  # what the rail gives (core/train/adhesion.py)


@dataclass(frozen=True)
class TrainParameters:
    """The train's physics (the plant.* parameters of the schema hold the defaults)."""

    gamma: float
    gravity: float
    davis_a: float
    davis_b: float
    davis_c: float
    mass: float                   # t, converts kN/kW envelopes to N/kN
    disturbance_amplitude: float  # m/s^2
    disturbance_frequency: float  # rad/s
    disturbance_phase: float      # rad
    max_traction_force: float     # kN (inf: no envelope)
    max_traction_power: float     # kW
    max_brake_force: float        # kN
    max_brake_power: float        # kW
    actuator_lag: float           # s, first-order time constant
    dead_time: float              # s, before a command starts to act
    length: float                 # m, train (mass belt) length
    pantograph_offset: float      # m behind the head
    hold_at_standstill: bool
    adhesion: Adhesion            # what the rail gives it (PlantStage's); the ATO's: UNLIMITED

    @classmethod
    def from_values(cls, values) -> TrainParameters:
        """From the run's plant.* values; without plant.envelope the limits are infinite."""
        envelope = values["plant.envelope"]
        return cls(
            gamma=values["plant.gamma"], gravity=values["plant.gravity"],
            davis_a=values["plant.davis_a"], davis_b=values["plant.davis_b"],
            davis_c=values["plant.davis_c"], mass=values["plant.mass"],
            disturbance_amplitude=values["plant.disturbance.amplitude"],
            disturbance_frequency=values["plant.disturbance.frequency"],
            disturbance_phase=values["plant.disturbance.phase"],
            **{name: values[f"plant.{name}"] if envelope else math.inf for name in (
                "max_traction_force", "max_traction_power", "max_brake_force",
                "max_brake_power")},
            actuator_lag=values["plant.actuator_lag"], dead_time=values["plant.dead_time"],
            length=values["plant.length"], pantograph_offset=values["plant.pantograph_offset"],
            hold_at_standstill=values["plant.hold_at_standstill"],
            adhesion=UNLIMITED)  # the ATO's train knows no rail: PlantStage sets the real one's

    @property
    def xi(self) -> float:
        """Acceleration per unit specific force, m/s^2 per N/kN."""
        return self.gravity / 1000.0 / (1.0 + self.gamma)

    def resistance(self, v: float) -> float:
        """Basic running resistance w0 in N/kN, opposing the motion."""
        return basic_resistance(v, self.davis_a, self.davis_b, self.davis_c)

    def disturbance(self, t: float) -> float:
        return disturbance(t, self.disturbance_amplitude, self.disturbance_frequency,
                           self.disturbance_phase)

    def net_traction(self, v: float, share: float, line_resistance: float = 0.0,
                     powered: bool = True) -> float:
        """What `share` of the traction envelope leaves at v against the basic and
        `line_resistance`, N/kN (negative: the share cannot hold v); no traction when not
        `powered` (a neutral section). Times xi: the acceleration a plan may ask."""
        traction = self.force_limits(v)[1] if powered else 0.0
        return share * traction - self.resistance(v) - line_resistance

    def net_braking(self, v: float, share: float, line_resistance: float = 0.0) -> float:
        """What `share` of the brake envelope gives at v, helped by the basic and
        `line_resistance`, N/kN. Times xi: the deceleration a plan may ask."""
        return self.resistance(v) + line_resistance - share * self.force_limits(v)[0]

    def force_limits(self, v: float) -> tuple[float, float]:
        """(most negative, most positive) achievable specific force at speed v, N/kN."""
        return force_limits(v, self.envelope)

    @property
    def envelope(self) -> Envelope:
        return Envelope(self.mass * self.gravity, self.max_traction_force,
                        self.max_traction_power, self.max_brake_force, self.max_brake_power)

    @property
    def limited(self) -> bool:
        """Whether the train has a traction or brake envelope (plant.envelope)."""
        return math.isfinite(self.max_traction_force + self.max_traction_power
                             + self.max_brake_force + self.max_brake_power)

    def loaded(self, factor: float, davis_absolute: bool) -> TrainParameters:
        """This train at `factor` times its mass (a load, plant.mass_factor, or the mass
        the ATO weighs): its envelopes in kN and kW then give 1/factor the specific force.
        Its basic resistance in kN grows with the weight (the specific Davis coefficients,
        N/kN, kept), or with `davis_absolute` (plant.davis_absolute: a TTOBench train's
        whole-train r0, r1, r2) stays as it is: the coefficients over the factor."""
        davis = {name: getattr(self, name) / factor if davis_absolute else getattr(self, name)
                 for name in ("davis_a", "davis_b", "davis_c")}
        return dataclasses.replace(self, mass=factor * self.mass, **davis)

    def constants(self) -> TrainConstants:
        return TrainConstants(
            self.xi, self.davis_a, self.davis_b, self.davis_c, self.disturbance_amplitude,
            self.disturbance_frequency, self.disturbance_phase, self.limited,
            self.actuator_lag, self.hold_at_standstill, self.envelope, self.length,
            self.adhesion)


@jitable
def basic_resistance(v: float, a: float, b: float, c: float) -> float:
    """Davis resistance w0 in N/kN at v, opposing the motion."""
    speed = v if v >= 0.0 else -v
    return math.copysign(a + b * speed + c * speed * speed, v) if v != 0.0 else 0.0


@jitable
def disturbance(t: float, amplitude: float, omega: float, phase: float) -> float:
    """phi(t), m/s^2."""
    return amplitude * math.sin(omega * t + phase)


@jitable
def force_limits(v: float, envelope: Envelope) -> tuple[float, float]:
    """(most negative, most positive) achievable specific force at speed v, N/kN."""
    speed = max(abs(v), 1e-6)
    traction = min(envelope.max_traction_force, envelope.max_traction_power / speed)
    brake = min(envelope.max_brake_force, envelope.max_brake_power / speed)
    return -brake * 1000.0 / envelope.weight, traction * 1000.0 / envelope.weight


@jitable
def achievable(command: float, v: float, limited: bool, envelope: Envelope) -> float:
    """The command cut to the envelope at v (unchanged without one)."""
    if limited:
        low, high = force_limits(v, envelope)
        return low if command < low else high if command > high else command
    return command


@jitable
def rates(t: float, v: float, force: float, command: float, powered: bool,
          line_resistance: float, constants: TrainConstants) -> tuple[float, float]:
    """(dv/dt, dG/dt), G the lag's state, `line_resistance` the belt's at the position.
    Unpowered (pantograph in a neutral section), traction is gone at once, from the
    lag's input and from its output alike."""
    c = constants
    resistance = basic_resistance(v, c.davis_a, c.davis_b, c.davis_c) + line_resistance
    if not powered and command > 0.0:
        command = 0.0
    if c.actuator_lag > 0.0:  # `force` is the lag's state; the envelope holds at every speed
        dforce = (achievable(command, v, c.limited, c.envelope) - force) / c.actuator_lag
        force = achievable(force, v, c.limited, c.envelope)
    else:
        force, dforce = achievable(command, v, c.limited, c.envelope), 0.0
    if not powered and force > 0.0:
        force = 0.0
    force = adhered(force, v, c.adhesion)
    acceleration = c.xi * (force - resistance) + disturbance(
        t, c.disturbance_amplitude, c.disturbance_frequency, c.disturbance_phase)
    if c.hold_at_standstill and v <= 0.0 and acceleration < 0.0:  # held by the brakes
        acceleration = 0.0
    return acceleration, dforce


@jitable(inline=True)
def rk4_substep(t: float, x: float, v: float, f: float, h: float, command: float,
                powered: bool, constants: TrainConstants, line: LineTables
                ) -> tuple[float, float, float]:
    """One classic RK4 step of length h on (s, v, G), the command held, on `line`."""
    length = constants.length
    a1, g1 = rates(t, v, f, command, powered, belt_resistance(line, x, length), constants)
    x2, v2 = x + h / 2 * v, v + h / 2 * a1
    a2, g2 = rates(t + h / 2, v2, f + h / 2 * g1, command, powered,
                   belt_resistance(line, x2, length), constants)
    x3, v3 = x + h / 2 * v2, v + h / 2 * a2
    a3, g3 = rates(t + h / 2, v3, f + h / 2 * g2, command, powered,
                   belt_resistance(line, x3, length), constants)
    x4, v4 = x + h * v3, v + h * a3
    a4, g4 = rates(t + h, v4, f + h * g3, command, powered, belt_resistance(line, x4, length),
                   constants)
    x_next = x + h / 6 * (v + 2 * v2 + 2 * v3 + v4)
    v += h / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
    f += h / 6 * (g1 + 2 * g2 + 2 * g3 + g4)
    if constants.hold_at_standstill and v < 0.0:
        v, x_next = 0.0, max(x, x_next)
    return x_next, v, f


@dataclass
class TrainState:
    position: float = 0.0      # m
    speed: float = 0.0         # m/s
    force: float = 0.0         # N/kN actually applied
    time: float = 0.0          # s


class TrainSettings(NamedTuple):
    """What a train's step reads and none changes (train_step)."""

    period: float              # s, one step
    substeps: int              # RK4 sub-steps per period
    constants: TrainConstants  # the real train's
    pantograph_offset: float   # m behind the head
    lagged: bool               # the force follows the command through the actuator lag
    line: LineTables           # arrays (OPEN_TRACK: none)


class TrainMotion(NamedTuple):
    """What the train carries from one period to the next (train_step)."""

    steps: int                 # periods run
    time: float                # s, the train's clock
    position: float            # m
    speed: float               # m/s, true
    force: float               # N/kN applied
    lag: float                 # the lag's output before the envelope
    acting: float              # the command that acted over the last period (after the delay)
    powered: bool              # the pantograph outside every neutral section, at the end
    delayed: np.ndarray        # commands inside the dead time (a ring, the oldest at `oldest`)
    oldest: int


def train_start(params: TrainParameters, period: float, substeps: int, state: TrainState,
                line: Line | None) -> tuple[TrainSettings, TrainMotion]:
    """The settings and first motion of a train starting in `state` on `line` (None: the
    open track), standing behind a dead time of zero commands."""
    settings = TrainSettings(float(period), int(substeps), params.constants(),
                             float(params.pantograph_offset), bool(params.actuator_lag > 0.0),
                             line.tables if line is not None else OPEN_TRACK)
    motion = TrainMotion(
        steps=round(state.time / period), time=float(state.time),
        position=float(state.position), speed=float(state.speed), force=float(state.force),
        lag=float(state.force), acting=0.0, powered=True,
        delayed=np.zeros(round(params.dead_time / period)), oldest=0)
    return settings, motion


@jitable(inline=True)
def train_step(settings: TrainSettings, motion: TrainMotion, command: float) -> TrainMotion:
    """One period: the command through the dead time, classic RK4 on (s, v, G) over
    `substeps` equal sub-steps, the command held."""
    constants, line = settings.constants, settings.line
    delayed, oldest = motion.delayed, motion.oldest
    if len(delayed):  # a float, not a numpy scalar, in Python
        command, delayed[oldest] = float(delayed[oldest]), command
        oldest = (oldest + 1) % len(delayed)
    h = settings.period / settings.substeps
    x, v, lag = motion.position, motion.speed, motion.lag
    for i in range(settings.substeps):
        powered = not in_neutral_section(line, x - settings.pantograph_offset)
        x, v, lag = rk4_substep(motion.time + i * h, x, v, lag, h, command, powered, constants,
                                line)
    # the force and acceleration at the step's end are those where the pantograph is
    # then: a train that has just entered a section has lost its traction already
    powered = not in_neutral_section(line, x - settings.pantograph_offset)
    steps = motion.steps + 1
    force = adhered(demanded_force(settings, v, lag, command, powered), v, constants.adhesion)
    return TrainMotion(steps, steps * settings.period, x, v, force, lag, command, powered,
                       delayed, oldest)


@jitable(inline=True)
def demanded_force(settings: TrainSettings, v: float, lag: float, acting: float,
                   powered: bool) -> float:
    """The force the train's drive and brakes ask of the rail at v (N/kN): the lag's
    output (or the acting command) within the envelope, no traction unpowered; the rail
    gives it, or less (core/train/adhesion.py)."""
    constants = settings.constants
    force = achievable(lag if settings.lagged else acting, v, constants.limited,
                       constants.envelope)
    if not powered and force > 0.0:
        force = 0.0
    return force


@jitable
def demand_and_creep(settings: TrainSettings, motion: TrainMotion) -> tuple[float, float]:
    """At the end of `motion`'s period: the force asked of the rail (N/kN,
    demanded_force) and the wheels' creep under it (core/train/adhesion.wheel_creep)."""
    demand = demanded_force(settings, motion.speed, motion.lag, motion.acting, motion.powered)
    return demand, wheel_creep(demand, motion.speed, settings.constants.adhesion)


@jitable
def drive_effort(settings: TrainSettings, motion: TrainMotion) -> float:
    """The force the rail gives (N/kN) at the end of `motion`'s period while the drive's
    anti-slip or the wheel-slide protection acts (the achieved effort a TCMS reports to the
    ATO); NaN while the wheels roll."""
    _, creep = demand_and_creep(settings, motion)
    return math.nan if creep == 0.0 else motion.force


@jitable(inline=True)
def train_outputs(settings: TrainSettings, motion: TrainMotion
                  ) -> tuple[float, float, float, float]:
    """What the train shows now (its state at t_k) beside its motion: (true acceleration
    under the command acting, disturbance phi, basic resistance w0, the belt's gradient,
    curve and tunnel resistance), m/s^2 and N/kN."""
    c = settings.constants
    line_resistance = belt_resistance(settings.line, motion.position, c.length)
    acceleration = rates(motion.time, motion.speed, motion.lag, motion.acting, motion.powered,
                         line_resistance, c)[0]
    return (acceleration, disturbance(motion.time, c.disturbance_amplitude,
                                      c.disturbance_frequency, c.disturbance_phase),
            basic_resistance(motion.speed, c.davis_a, c.davis_b, c.davis_c), line_resistance)


@jitable
def diverged(speed: float, max_speed: float) -> bool:
    """Speed not finite or beyond `max_speed`: a run that can only get worse."""
    return not (abs(speed) <= max_speed)  # also true for NaN


class PointMassTrain:
    """Integrates the train over one control period per call: a holder of its
    TrainSettings and TrainMotion, stepped by train_step."""

    def __init__(self, params: TrainParameters, period: float, substeps: int = 1,
                 state: TrainState | None = None, line: Line | None = None):
        self.p = params
        self.line = line
        self.settings, self.motion = train_start(params, period, substeps,
                                                 state or TrainState(), line)

    @property
    def period(self) -> float:
        return self.settings.period

    @property
    def state(self) -> TrainState:
        m = self.motion
        return TrainState(m.position, m.speed, m.force, m.time)

    def line_resistance(self) -> float:
        """Additional (gradient, curve, tunnel) resistance of the belt now, N/kN."""
        return train_outputs(self.settings, self.motion)[3]

    def acceleration(self) -> float:
        """True acceleration at the current state under the command now acting."""
        return train_outputs(self.settings, self.motion)[0]

    def step(self, command: float) -> TrainState:
        """Classic RK4 on (s, v, F), `substeps` equal steps, command held."""
        self.motion = train_step(self.settings, self.motion, command)
        return self.state


@jitable
def sensor_reading(speed: float, draw: float, noise: float, quantum: float) -> float:
    """The speed sensor's reading: speed plus noise (`draw` a standard normal sample),
    to its resolution (rounded half to even, as round() does)."""
    if noise > 0.0:
        speed += noise * draw
    if quantum > 0.0:
        speed = quantum * round(speed / quantum)
    return speed
