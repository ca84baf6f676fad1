"""Han's ADRC pieces against values worked out by hand or closed forms."""

import math

import pytest

from ato_nodes.core.control.estimation import on_board_estimator
from ato_nodes.core.control.adrc import (HanADRCGains, LinearADRCGains, eso_update, fal,
                                         fal_gain, fhan, han_adrc, linear_adrc_gains,
                                         linear_adrc_of, nlsef, target_past_preview, td_update)
from ato_nodes.core.train.plant import TrainParameters
from ato_nodes.core.control.limiter import CommandLimiter
from ato_nodes.core.config.schema import defaults
from ato_nodes.core.base.spec import settings


class TrackingDifferentiator:
    """Han's discrete TD (td_update): v1 follows the input, v2 its derivative."""

    def __init__(self, r0, h0, period):
        self.settings = (r0, h0, period)
        self.v = (0.0, 0.0)

    def update(self, target):
        self.v = td_update(*self.v, target, *self.settings)
        return self.v


class NonlinearESO:
    """Han's nonlinear ESO (eq. 10) stepped by eso_update, as HanADRC steps it."""

    def __init__(self, beta1, beta2, beta3, b0, delta, period):
        self.gains = (beta1, beta2, beta3, b0, delta, period)
        self.z = (0.0, 0.0, 0.0)

    def update(self, y, u):
        self.z = eso_update(*self.z, y, u, *self.gains)
        return self.z


def han_gains() -> HanADRCGains:
    """Seed 000's initial parameters, as the schema gives them."""
    return settings(HanADRCGains, "adrc", defaults())


class TestFal:
    def test_power_law_outside_the_linear_zone(self):
        assert fal(0.5, 0.5, 0.01) == pytest.approx(math.sqrt(0.5))
        assert fal(-4.0, 0.25, 0.01) == pytest.approx(-math.sqrt(2.0))
        assert fal(2.0, 1.5, 0.01) == pytest.approx(2.0 ** 1.5)

    def test_linear_inside_the_zone(self):
        # e / delta^(1 - alpha): 0.005 / 0.1 = 0.05
        assert fal(0.005, 0.5, 0.01) == pytest.approx(0.05)
        assert fal(-0.005, 0.5, 0.01) == pytest.approx(-0.05)

    def test_continuous_at_the_zone_edge(self):
        delta = 0.01
        for alpha in (0.25, 0.5, 0.75, 1.5):
            inside, outside = fal(delta, alpha, delta), fal(delta * (1 + 1e-12), alpha, delta)
            assert inside == pytest.approx(outside, rel=1e-9)
            assert inside == pytest.approx(delta ** alpha)

    def test_gain_is_fal_over_e(self):
        for e in (-3.0, -0.004, 0.002, 0.7):
            assert fal_gain(e, 0.5, 0.01) * e == pytest.approx(fal(e, 0.5, 0.01))
        assert fal_gain(0.0, 0.5, 0.01) == pytest.approx(0.01 ** -0.5)


class TestFhan:
    def test_bang_bang_far_from_the_origin(self):
        assert fhan(10.0, 0.0, 5.0, 0.01) == -5.0
        assert fhan(-10.0, 0.0, 5.0, 0.01) == 5.0

    def test_zero_at_the_origin(self):
        assert fhan(0.0, 0.0, 5.0, 0.01) == 0.0

    def test_linear_zone_by_hand(self):
        # r = 5, h0 = 0.01: d = 5e-4; x1 = 1e-4, x2 = 0 -> y = a = 1e-4, |a| < d
        # fhan = -r (a/d - sign a) - r sign a = -5 (0.2 - 1) - 5 = -1
        assert fhan(1e-4, 0.0, 5.0, 0.01) == pytest.approx(-1.0)

    def test_odd_symmetry(self):
        for x1, x2 in ((0.3, -0.2), (1e-4, 2e-3), (-2.0, 5.0)):
            assert fhan(-x1, -x2, 5.0, 0.01) == pytest.approx(-fhan(x1, x2, 5.0, 0.01))


class TestTrackingDifferentiator:
    def test_time_optimal_step_response(self):
        # Bounded acceleration r: the fastest transition 0 -> 1 takes 2 sqrt(1/r) = 0.894 s.
        td = TrackingDifferentiator(r0=5.0, h0=0.01, period=0.01)
        trajectory = [td.update(1.0) for _ in range(300)]
        reach = next(k for k, (v1, _) in enumerate(trajectory) if v1 > 0.999) * 0.01
        assert 0.8 < reach < 0.95
        assert max(v1 for v1, _ in trajectory) < 1.001
        assert max(abs(v2) for _, v2 in trajectory) <= 5.0 * 0.894 / 2 + 0.05  # r * T/2
        assert trajectory[-1][0] == pytest.approx(1.0, abs=1e-9)
        assert trajectory[-1][1] == pytest.approx(0.0, abs=1e-9)

    def test_tracks_a_ramp_and_its_slope(self):
        td = TrackingDifferentiator(r0=5.0, h0=0.01, period=0.01)
        for k in range(1000):
            v1, v2 = td.update(0.5 * k * 0.01)
        assert v2 == pytest.approx(0.5, abs=1e-6)
        # steady lag of a time-optimal tracker on a ramp: about slope^2 / (2 r)
        assert 0.0 < 0.5 * 999 * 0.01 - v1 < 0.05


class TestExtendedStateObserver:
    # The fal() gains fall as |e|^(alpha - 1) outside the linear zone, so z3 keeps
    # an error of ~0.1-0.2 on a unit sine with the seed's gains (measured).
    @pytest.mark.parametrize("period, z2_tolerance, z3_tolerance",
                             [(0.001, 0.02, 0.15), (0.05, 0.05, 0.2)])
    def test_converges_on_a_known_signal(self, period, z2_tolerance, z3_tolerance):
        # y = sin t with u = 0: a double integrator y'' = f has f = -sin t, so
        # z1 -> sin t, z2 -> cos t, z3 -> -sin t.
        eso = NonlinearESO(1200.0, 1700.0, 4500.0, b0=0.2, delta=0.01, period=period)
        errors = []
        for k in range(int(20.0 / period)):
            t = k * period
            z1, z2, z3 = eso.update(math.sin(t), 0.0)
            if t > 5.0:
                errors.append((abs(z1 - math.sin(t)), abs(z2 - math.cos(t)), abs(z3 + math.sin(t))))
        assert max(e[0] for e in errors) < 1e-4
        assert max(e[1] for e in errors) < z2_tolerance
        assert max(e[2] for e in errors) < z3_tolerance

    def test_estimates_a_constant_disturbance(self):
        # Plant y'' = f + b0 u with f = 0.3 and u = 1, b0 = 2: z3 -> 0.3.
        period, b0, f, u = 0.001, 2.0, 0.3, 1.0
        eso = NonlinearESO(300.0, 3000.0, 10000.0, b0=b0, delta=0.01, period=period)
        y = dy = 0.0
        for _ in range(int(10.0 / period)):
            z1, z2, z3 = eso.update(y, u)
            dy += period * (f + b0 * u)
            y += period * dy
        assert z3 == pytest.approx(f, abs=0.01)
        assert z2 == pytest.approx(dy, rel=1e-3)

    def test_stable_for_the_seed_gains_at_a_long_step(self):
        # Explicit Euler would need beta1 * h < ~1; backward Euler does not.
        eso = NonlinearESO(1200.0, 1700.0, 4500.0, b0=0.2, delta=0.01, period=0.1)
        for _ in range(2000):
            z = eso.update(1.0, 0.0)
        assert z[0] == pytest.approx(1.0, abs=1e-9)
        assert abs(z[1]) < 1e-6 and abs(z[2]) < 1e-6


class TestNLSEF:
    def law(self, implicit, period=0.05):
        gains = han_gains()._replace(implicit_nlsef=implicit)
        return lambda e1, e2, z2: nlsef(e1, e2, z2, gains, period)

    def test_literal_law_by_hand(self):
        law = self.law(implicit=False)
        # e1 = 0.5 (outside delta): 6000 * 0.5^0.75; e2 = 0.005 (inside): 5500 * 0.005 / 0.01^-0.5
        expected = 6000 * 0.5 ** 0.75 + 5500 * 0.005 * 0.01 ** 0.5
        assert law(0.5, 0.005, 0.0) == pytest.approx(expected)

    def test_implicit_law_tends_to_the_literal_one(self):
        literal = self.law(implicit=False)(0.02, 0.01, 0.0)
        for period, tolerance in ((1e-4, 0.5), (1e-6, 0.01)):
            implicit = self.law(implicit=True, period=period)(0.02, 0.01, 0.0)
            assert abs(implicit - literal) / abs(literal) < tolerance

    def test_implicit_law_solves_its_defining_equation(self):
        # Z = z2 + h (k1 (e1 - h Z + h z2 ... )): next model state satisfies the law.
        period = 0.05
        g = han_gains()
        e1, e2, z2 = 0.2, -0.03, 0.1
        u0 = self.law(implicit=True, period=period)(e1, e2, z2)
        next_z2 = z2 + period * u0
        k1 = g.mu1 * fal_gain(e1, g.alpha1, g.delta)
        k2 = g.mu2 * fal_gain(e2, g.alpha2, g.delta)
        # e1, e2 at the end of the step under the model z1' = z2, z2' = u0:
        e1_next = e1 - period * next_z2
        e2_next = e2 + z2 - next_z2
        assert u0 == pytest.approx(k1 * e1_next + k2 * e2_next)

    def test_command_saturates_and_observer_sees_the_saturated_value(self):
        adrc = han_adrc(han_gains(), 0.05, CommandLimiter(-5.0, 5.0))
        out = adrc.step(100.0, 0.0, [100.0])
        assert out.u == 5.0
        assert adrc.state.u_applied == 5.0


def paper_gains(**gains) -> LinearADRCGains:
    """The linear ADRC's schema defaults (every addition off) with `gains`."""
    return linear_adrc_gains(defaults())._replace(**gains)


class TestLinearADRC:
    def test_tracks_a_first_order_plant_with_constant_disturbance(self):
        period, b, disturbance = 0.05, 0.0098 / 1.11, -0.2
        adrc = linear_adrc_of(paper_gains(omega_o=20.0, omega_c=2.0, b0=b), period,
                              CommandLimiter(-1e6, 1e6), TrainParameters.from_values(defaults()),
                              on_board_estimator(defaults(), period))
        v = 0.0
        for _ in range(400):
            out = adrc.step(10.0, v, [10.0])
            v += period * (b * out.u + disturbance)
        assert v == pytest.approx(10.0, abs=1e-3)
        assert out.extras[1] == pytest.approx(disturbance, abs=1e-3)


def held_then_released(standstill: bool):
    """A train held standing by the holding brake for 120 s (a braking force does not
    move it), then a 0.1 m/s target: the observer's disturbance at the end of the hold
    and the steps until the command is traction again."""
    period, b = 0.1, 0.0098 / 1.11
    adrc = linear_adrc_of(paper_gains(omega_o=5.0, omega_c=1.0, b0=b, standstill=standstill),
                          period,
                          CommandLimiter(-60.0, 60.0, period, 60.0, holding_brake=30.0),
                          TrainParameters.from_values(defaults()),
                          on_board_estimator(defaults(), period))
    for _ in range(1200):
        adrc.step(0.0, 0.0, [0.0])
    held = adrc.state.z2
    steps = 1
    while adrc.step(0.1, 0.0, [0.1]).u <= 0.0:
        steps += 1
    return held, steps


def test_a_held_train_does_not_wind_up_the_observer_with_standstill():
    wound, slow = held_then_released(standstill=False)
    held, fast = held_then_released(standstill=True)
    assert wound > 0.2      # the holding brake read as a push forward
    assert abs(held) < 1e-9  # what it knew before the stop: nothing
    assert fast < slow


FALLING = [1.0, 0.8, 0.6]  # a preview of a stop's curve at 0.1 s: 0.16 m, the last step 0.07


def test_a_train_not_past_the_preview_tracks_the_plans_target():
    assert target_past_preview(FALLING, 0.1, 0.16) == 0.6
    assert target_past_preview(FALLING, 0.1, 0.05) == 0.6


def test_a_train_past_the_preview_tracks_the_curve_extended_down_there():
    assert target_past_preview(FALLING, 0.1, 0.18) == pytest.approx(0.6 - 0.2 / 0.07 * 0.02)
    assert target_past_preview(FALLING, 0.1, 1.0) == 0.0        # not below standstill
    assert target_past_preview([0.6, 0.8, 1.0], 0.1, 0.5) == 1.0  # never up
    assert target_past_preview([0.2, 0.0, 0.0], 0.1, 0.5) == 0.0  # the plan stopped
