"""The PID baseline: feedforward from the preview, derivative on the filtered
measurement, back-calculation anti-windup."""

from dataclasses import replace

import pytest

from ato_nodes.core.control.limiter import CommandLimiter
from ato_nodes.core.control.estimation import on_board_estimator
from ato_nodes.core.control.pid import PID_STEPS, PIDGains, PIDSettings, PIDState
from ato_nodes.core.control.stepped import SteppedController
from ato_nodes.core.train.plant import PointMassTrain, TrainParameters
from ato_nodes.core.config.schema import defaults
from ato_nodes.core.base.spec import settings

PERIOD = 0.05


def gains(**changes) -> PIDGains:
    return settings(PIDGains, "pid", defaults())._replace(**changes)


def PID(gains: PIDGains, period: float, limiter: CommandLimiter, train: TrainParameters):
    on_board, estimated = on_board_estimator(defaults(), period)
    return SteppedController(PID_STEPS, PIDSettings(gains, period, train.constants(), on_board),
                             limiter, PIDState(0.0, 0.0, estimated))


def train() -> TrainParameters:
    return replace(TrainParameters.from_values(defaults()), disturbance_amplitude=0.0)


def test_feedforward_alone_follows_a_ramp_on_the_nominal_train():
    """No feedback at all: the planned acceleration and the basic resistance of the
    nominal model drive the train along the plan."""
    nominal = train()
    pid = PID(gains(kp=0.0, ki=0.0, kd=0.0), PERIOD, CommandLimiter(-1e6, 1e6), nominal)
    plant = PointMassTrain(nominal, PERIOD, substeps=4)
    pid.start(0.0, 0.0, [0.0])
    ramp = 0.5  # m/s^2
    for k in range(400):
        horizon = [ramp * k * PERIOD, ramp * (k + 1) * PERIOD]
        out = pid.step(horizon[0], plant.state.speed, horizon)
        plant.step(out.u)
    assert plant.state.speed == pytest.approx(ramp * 400 * PERIOD, abs=0.02)


def test_no_derivative_kick_on_a_target_step():
    pid = PID(gains(kd=100.0), PERIOD, CommandLimiter(-1e6, 1e6), train())
    pid.start(0.0, 0.0, [0.0])
    out = pid.step(10.0, 0.0, [10.0])
    assert out.extras[3] == 0.0  # derivative acts on the measurement only
    out = pid.step(10.0, 1.0, [10.0])
    assert out.extras[3] < 0.0  # the measurement rose: damping


@pytest.mark.parametrize("kt, bounded", [(1.0, True), (0.0, False)])
def test_back_calculation_keeps_the_integrator_from_winding_up(kt, bounded):
    pid = PID(gains(kp=10.0, ki=5.0, kt=kt, feedforward=0.0), PERIOD,
              CommandLimiter(-20.0, 20.0), train())
    pid.start(0.0, 0.0, [0.0])
    for _ in range(2000):  # 100 s saturated, 5 m/s short of the target
        out = pid.step(5.0, 0.0, [5.0])
    assert out.u == 20.0
    # with back-calculation the integrator settles where the cut balances the error
    assert (abs(out.extras[2]) < 100.0) is bounded
