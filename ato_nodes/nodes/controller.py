"""Speed-tracking controller node: pairs step k's measured speed with its target
horizon (by arrival order; Float64 carries no stamp) and publishes the command and
the controller's named outputs."""

from __future__ import annotations

from std_msgs.msg import Float64, Float64MultiArray, MultiArrayDimension

from ato_nodes.core.loop import ControllerStage
from ato_nodes.nodes.base import AtoNode, run_node


class ControllerNode(AtoNode):
    role = "controller"

    def __init__(self):
        super().__init__()
        self.stage = ControllerStage(self.values)
        self.command_pub = self.publisher("command")
        self.outputs_pub = self.publisher("controller_state")
        self.command_msg, self.outputs_msg = Float64(), Float64MultiArray()
        names = self.stage.output_names
        # The outputs' names travel with every message: a bag says what it holds.
        self.outputs_msg.layout.dim = [MultiArrayDimension(
            label=",".join(names), size=len(names), stride=len(names))]
        self.subscription("target_preview", self.on_horizon)
        self.subscription("measured_speed", self.on_speed)
        self.ready_when_matched()

    def on_horizon(self, msg: Float64MultiArray) -> None:
        self.stage.horizons.append(msg.data)
        self.publish(self.stage.ready())

    def on_speed(self, msg: Float64) -> None:
        self.stage.speeds.append(msg.data)
        self.publish(self.stage.ready())

    def publish(self, outputs) -> None:
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
