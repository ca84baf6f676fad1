"""Speed-tracking controller node: pairs step k's measured speed with its target
horizon (by arrival order; Float64 carries no stamp) and publishes the command and
the controller's named outputs.

The controller kind's gains are live (core.registry.Component.state_paths): a `ros2 param
set` is checked against the schema, takes effect at the next step boundary
(stages.ControllerStage.pending), and is published on the parameter_changes topic with
the step it took effect at, for the bag."""

from __future__ import annotations

import json

from rcl_interfaces.msg import SetParametersResult
from std_msgs.msg import Float64, Float64MultiArray, String

from ato_nodes.core.config.components import CONTROLLERS
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.run.stages import ControllerStage
from ato_nodes.core.config.schema import SPEC_BY_NAME
from ato_nodes.nodes.base import AtoNode, labelled, run_node


class ControllerNode(AtoNode):
    role = "controller"

    def __init__(self):
        super().__init__()
        self.stage = ControllerStage(self.values)
        self.command_pub = self.publisher("command")
        self.outputs_pub = self.publisher("controller_state")
        self.command_msg = Float64()
        self.outputs_msg = labelled(self.stage.output_names)
        self.changes_pub = self.publisher("parameter_changes")
        self.live = self.stage.component.live_parameters
        self.add_on_set_parameters_callback(self.on_set_parameters)
        # The horizon of step k comes two steps ahead of y_k (the profile runs ahead):
        # waited for only when none is queued, the controller wakes once a step, for y_k.
        # Inputs are handled in the order subscribed: y_k first, so u_k goes out with the
        # horizon already queued before the horizons that came meanwhile are taken.
        self.subscription("measured_speed", self.on_speed)
        if self.stage.efforts is not None:  # controller.slip_hold: published beside y_k
            self.subscription("drive_effort", self.on_effort)
        self.subscription("target_preview", self.on_horizon,
                          wakes=lambda: not self.stage.horizons)
        self.ready_when_matched()

    def live_parameters(self, values) -> tuple[str, ...]:
        return CONTROLLERS.chosen(values).live_parameters

    def on_set_parameters(self, parameters) -> SetParametersResult:
        """A live gain: checked as the schema checks it at start-up, then pending until
        the next step boundary (read-only ones never get here: rclpy refuses them)."""
        changes = {}
        for parameter in parameters:
            if parameter.name in self.live:
                try:
                    changes[parameter.name] = SPEC_BY_NAME[parameter.name].check(
                        parameter.value, self.role)
                except ScenarioError as exc:
                    return SetParametersResult(successful=False, reason=str(exc))
        self.stage.pending.update(changes)
        return SetParametersResult(successful=True)

    def on_horizon(self, msg: Float64MultiArray) -> None:
        self.stage.horizons.append(msg.data)
        self.publish(self.stage.run_ready_steps())

    def on_effort(self, msg: Float64) -> None:
        self.stage.efforts.append(msg.data)
        self.publish(self.stage.run_ready_steps())

    def on_speed(self, msg: Float64) -> None:
        self.stage.speeds.append(msg.data)
        self.publish(self.stage.run_ready_steps())

    def publish(self, outputs) -> None:
        for step, changes in self.stage.applied:
            self.changes_pub.publish(String(data=json.dumps({"step": step,
                                                             "parameters": changes})))
            self.log.info(f"from step {step} (t = {step * self.stage.context.period:g}"
                                   f" s): " + ", ".join(f"{n} = {v!r}" for n, v in changes.items()))
        self.stage.applied.clear()
        for out in outputs:
            self.inject_fault(self.stage.step_index)
            self.command_msg.data = out.u
            self.command_pub.publish(self.command_msg)
            self.outputs_msg.data = out.extras
            self.outputs_pub.publish(self.outputs_msg)


def main() -> None:
    run_node(ControllerNode)


if __name__ == "__main__":
    main()
