"""A controller of your own in the run, in place of the project's controller node: the
run's contract (docs/external-nodes.md) is kept here, the law stays yours.

    from ato_nodes.nodes.external import run_controller

    def proportional(parameters):
        gain = parameters["gain"]
        return lambda target, measured, horizon: gain * (target - measured)

    run_controller(proportional, own=[("gain", 50.0, "N/kN per m/s", 0.0, 1000.0)])

`run_controller(make_law, outputs, own)` builds the law once the node has its
parameters: `make_law(parameters)` gets the run's controller values (what the project's
controller node declares: run.period, the nominal train, controller.preview, the
chosen kind's gains) and your own parameters (`own`: name, default, description, low,
high; declared with a FloatingPointRange, changeable with `ros2 param set` during the
run). A law is a callable `law(target, measured, horizon)`, or an object with
`step(target, measured, horizon)` and, if it needs one, `start(target, measured,
horizon)` (called once, before step 0) and `retune(changes)` (your own parameters
changed, between two steps). It returns the command u_k (N/kN) or (u_k, outputs), the
outputs one float per name of `outputs`, in that order. `target` is r_k, the plan's
target now, `measured` y_k, `horizon` r_k .. r_k+N (N = controller.preview).
`nominal_train(parameters)` and `command_limiter(parameters)` give a law the run's nominal
train and command limiter as the project's controllers have them.
"""

from __future__ import annotations

import json
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor, SetParametersResult
from std_msgs.msg import Float64, Float64MultiArray, MultiArrayDimension, String

from ato_nodes.bags.bagio import EXTERNAL_LAW
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.context import RunContext
from ato_nodes.core.config.schema import NodeValues, defaults, for_node
from ato_nodes.core.control.limiter import CommandLimiter
from ato_nodes.core.train.plant import TrainConstants
from ato_nodes.nodes.base import AtoNode, run_node

OwnParameter = tuple[str, float, str, float, float]  # name, default, description, low, high


def command_and_outputs(result: Any, names: Sequence[str]) -> tuple[float, list[float]]:
    """A law's result as (u_k, its outputs); a result that does not match `names` is a
    ValueError (the node stops with one line)."""
    if hasattr(result, "u"):  # the project's ControllerOutput
        u, outputs = result.u, result.extras
    elif isinstance(result, (tuple, list)):
        u, outputs = result
    else:
        u, outputs = result, ()
    outputs = [float(value) for value in outputs]
    if len(outputs) != len(names):
        raise ValueError(f"the law returned {len(outputs)} outputs for the {len(names)} "
                         f"named ({', '.join(names) or 'none'})")
    return float(u), outputs


class ExternalController(AtoNode):
    """The controller node's part of the run around a law of the user's."""

    role = "controller"

    def __init__(self, make_law: Callable[[dict], Any], outputs: Sequence[str] = (),
                 own: Sequence[OwnParameter] = (), name: str = "external"):
        self.own = {spec[0]: spec for spec in own}
        self.mark = name
        super().__init__()
        self.parameters = {**{key: self.get_parameter(key).value for key in self.own},
                           **self.values}
        self.law = make_law(self.parameters)
        self.names = tuple(outputs)
        self.speeds: deque[float] = deque()
        self.horizons: deque[Sequence[float]] = deque()
        self.step_index = 0
        self.pending: dict[str, float] = {}
        self.command_pub = self.publisher("command")
        self.outputs_pub = self.publisher("controller_state")
        self.changes_pub = self.publisher("parameter_changes")
        self.outputs_msg = Float64MultiArray()
        self.outputs_msg.layout.dim = [MultiArrayDimension(
            label=",".join(self.names), size=len(self.names), stride=len(self.names))]
        self.add_on_set_parameters_callback(self.on_set_parameters)
        # y_k first, then the horizons (they come two steps ahead: waited for only when
        # none is queued), as the project's controller node takes them
        self.subscription("measured_speed", self.on_speed)
        self.subscription("target_preview", self.on_horizon, wakes=lambda: not self.horizons)
        self.ready_when_matched()

    def _declare_parameters(self, use_sim_time: bool):
        """The run's controller values as the project's node declares them, and the
        user's own parameters, live, with their ranges."""
        overrides = self._parameter_overrides
        try:  # those the run's schema declares too keep their place (the run's values)
            run = {spec.name for spec in for_node(self.role, {
                **defaults(), **{key: overrides[key].value for key in overrides}})}
        except ScenarioError:  # a kind this process learns from the run's plug-ins: theirs
            run = set(self.own)
        given = {key: overrides.pop(key) for key in set(self.own) - run if key in overrides}
        values = super()._declare_parameters(use_sim_time)
        for key, default, description, low, high in self.own.values():
            if key in values:  # the run's schema declares it (a plug-in kind's): its value
                continue
            descriptor = ParameterDescriptor(name=key, description=description,
                                             floating_point_range=[FloatingPointRange(
                                                 from_value=float(low), to_value=float(high))])
            self.declare_parameter(key, float(given[key].value) if key in given else float(default),
                                   descriptor)
        return values

    def announce_parameters(self) -> None:
        """The values it runs with, the user's own and the mark of an external law with
        them (before they are declared: AtoNode announces at construction)."""
        values = {**self.values, EXTERNAL_LAW: self.mark}
        values.update({key: self.get_parameter(key).value for key in self.own
                       if key not in self.values})
        self.announce(f"parameters {self.role} {json.dumps(values)}")

    def on_set_parameters(self, parameters) -> SetParametersResult:
        """The user's own parameters (rclpy checks their ranges) take effect at the next
        step boundary."""
        changes = {parameter.name: float(parameter.value) for parameter in parameters
                   if parameter.name in self.own}
        if changes and not hasattr(self.law, "retune"):
            return SetParametersResult(successful=False,
                                       reason="this law cannot change during a run")
        self.pending.update(changes)
        return SetParametersResult(successful=True)

    def on_speed(self, msg: Float64) -> None:
        self.speeds.append(msg.data)
        self.run_ready_steps()

    def on_horizon(self, msg: Float64MultiArray) -> None:
        self.horizons.append(msg.data)
        self.run_ready_steps()

    def run_ready_steps(self) -> None:
        """Every step whose y_k and horizon have both arrived (the k-th of each)."""
        while self.speeds and self.horizons:
            self.retune_pending()
            horizon, measured = self.horizons.popleft(), self.speeds.popleft()
            target = horizon[0]
            if self.step_index == 0 and hasattr(self.law, "start"):
                self.law.start(target, measured, horizon)
            step = getattr(self.law, "step", self.law)
            u, outputs = command_and_outputs(step(target, measured, horizon), self.names)
            self.inject_fault(self.step_index)
            self.command_pub.publish(Float64(data=u))
            self.outputs_msg.data = outputs
            self.outputs_pub.publish(self.outputs_msg)
            self.step_index += 1

    def retune_pending(self) -> None:
        if not self.pending:
            return
        changes, self.pending = self.pending, {}
        self.law.retune(changes)
        self.changes_pub.publish(String(data=json.dumps({"step": self.step_index,
                                                         "parameters": changes})))
        self.log.info(f"from step {self.step_index}: "
                      + ", ".join(f"{key} = {value!r}" for key, value in changes.items()))


def nominal_train(parameters: dict) -> TrainConstants:
    """The run's nominal train as the project's controllers model it (mass, xi, Davis
    coefficients; the load weighing's reading included), from make_law's parameters."""
    return RunContext(NodeValues("controller", parameters)).train.constants()


def command_limiter(parameters: dict) -> CommandLimiter:
    """The run's command limiter (bounds, jerk limit, holding brake, mode band) as the
    project's controllers apply it, from make_law's parameters."""
    return CommandLimiter.from_values(NodeValues("controller", parameters))


def run_controller(make_law: Callable[[dict], Any], outputs: Sequence[str] = (),
                   own: Sequence[OwnParameter] = (), name: str = "external") -> None:
    """Run a law of the user's as the run's controller node until the run ends (the
    process exits: 0, or 2 with one line for bad parameters, 1 for a failure). `name`
    is what the bag records of the law (parameter controller.external)."""
    def factory() -> ExternalController:
        return ExternalController(make_law, outputs, own, name)
    factory.role = "controller"
    run_node(factory)

