"""Single mass-point train (seed 000 eq. 1-2), ROS-free.

    ds/dt = v
    dv/dt = xi (F - w0(v)) + phi(t),   xi = g/1000 / (1 + gamma)
    w0(v) = a + b v + c v^2            [N/kN, v in m/s]
    phi(t) = A sin(omega t + phase)     [m/s^2]

F is the specific force actually applied by the train (N/kN, + traction,
- braking). The commanded force u reaches F through optional envelopes
(constant force, then constant power, for traction and braking) and an
optional first-order actuator lag tau: dF/dt = (sat(u) - F) / tau. With
no envelope and tau = 0 (the paper-faithful variant) F = u.

Integration: classic RK4 with `substeps` equal sub-steps per control
period, the command held constant over the period (zero-order hold).
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class TrainParameters:
    gamma: float = 0.11
    gravity: float = 9.8
    davis_a: float = 0.16
    davis_b: float = 0.0053
    davis_c: float = 0.0018
    mass: float = 388.4                       # t, converts kN/kW envelopes to N/kN
    disturbance_amplitude: float = 1.0 / 3.6  # m/s^2 (1 km/h per s)
    disturbance_frequency: float = 0.77       # rad/s
    disturbance_phase: float = 0.0            # rad
    max_traction_force: float = math.inf      # kN
    max_traction_power: float = math.inf      # kW
    max_brake_force: float = math.inf         # kN
    max_brake_power: float = math.inf         # kW
    actuator_lag: float = 0.0                 # s, first-order time constant

    @property
    def xi(self) -> float:
        """Acceleration per unit specific force, m/s^2 per N/kN."""
        return self.gravity / 1000.0 / (1.0 + self.gamma)

    def resistance(self, v: float) -> float:
        """Basic running resistance w0 in N/kN, opposing the motion."""
        speed = abs(v)
        return math.copysign(self.davis_a + self.davis_b * speed + self.davis_c * speed * speed, v) \
            if v != 0.0 else 0.0

    def disturbance(self, t: float) -> float:
        return self.disturbance_amplitude * math.sin(self.disturbance_frequency * t
                                                     + self.disturbance_phase)

    def force_limits(self, v: float) -> tuple[float, float]:
        """(most negative, most positive) achievable specific force at speed v, N/kN."""
        weight = self.mass * self.gravity  # kN
        speed = max(abs(v), 1e-6)
        traction = min(self.max_traction_force, self.max_traction_power / speed)
        brake = min(self.max_brake_force, self.max_brake_power / speed)
        return -brake * 1000.0 / weight, traction * 1000.0 / weight


@dataclass
class TrainState:
    position: float = 0.0      # m
    speed: float = 0.0         # m/s
    force: float = 0.0         # N/kN actually applied
    time: float = 0.0          # s


class PointMassTrain:
    """Integrates the train over one control period per call."""

    def __init__(self, params: TrainParameters, period: float, substeps: int = 1,
                 state: TrainState | None = None):
        self.p = params
        self.period = period
        self.substeps = substeps
        self.state = state or TrainState()
        self.steps = round(self.state.time / period)
        self.lagged = params.actuator_lag > 0.0
        self.limited = math.isfinite(params.max_traction_force + params.max_traction_power
                                     + params.max_brake_force + params.max_brake_power)
        self.rates = self._make_rates()

    def _make_rates(self):
        """rates(t, v, F, command) -> (dv/dt, dF/dt) with every constant bound once:
        this runs four times per sub-step, in every node and every tuning candidate."""
        p = self.p
        xi, a, b, c = p.xi, p.davis_a, p.davis_b, p.davis_c
        amplitude, omega, phase = (p.disturbance_amplitude, p.disturbance_frequency,
                                   p.disturbance_phase)
        sin, copysign = math.sin, math.copysign
        limits, limited, tau = p.force_limits, self.limited, p.actuator_lag

        def achievable(command: float, v: float) -> float:
            if limited:
                low, high = limits(v)
                return low if command < low else high if command > high else command
            return command

        def rates(t: float, v: float, force: float, command: float) -> tuple[float, float]:
            speed = v if v >= 0.0 else -v
            resistance = copysign(a + b * speed + c * speed * speed, v) if v != 0.0 else 0.0
            if tau > 0.0:
                dforce = (achievable(command, v) - force) / tau
            else:
                force, dforce = achievable(command, v), 0.0
            return xi * (force - resistance) + amplitude * sin(omega * t + phase), dforce

        self.achievable = achievable
        return rates

    def acceleration(self, command: float) -> float:
        """True acceleration at the current state under `command`."""
        s = self.state
        return self.rates(s.time, s.speed, s.force, command)[0]

    def step(self, command: float) -> TrainState:
        """Classic RK4 on (s, v, F), `substeps` equal steps, command held."""
        s, rates = self.state, self.rates
        h = self.period / self.substeps
        start = s.time
        x, v, f = s.position, s.speed, s.force
        for i in range(self.substeps):
            t = start + i * h
            a1, g1 = rates(t, v, f, command)
            v2 = v + h / 2 * a1
            a2, g2 = rates(t + h / 2, v2, f + h / 2 * g1, command)
            v3 = v + h / 2 * a2
            a3, g3 = rates(t + h / 2, v3, f + h / 2 * g2, command)
            v4 = v + h * a3
            a4, g4 = rates(t + h, v4, f + h * g3, command)
            x += h / 6 * (v + 2 * v2 + 2 * v3 + v4)
            v += h / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
            f += h / 6 * (g1 + 2 * g2 + 2 * g3 + g4)
        if not self.lagged:
            f = self.achievable(command, v)
        self.steps += 1
        s.time, s.position, s.speed, s.force = self.steps * self.period, x, v, f
        return s
