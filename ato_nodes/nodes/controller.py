"""Speed-tracking controller node: pairs step k's measured speed with its targets
(by arrival order; Float64 carries no stamp) and publishes the command."""

from __future__ import annotations

from geometry_msgs.msg import Twist
from std_msgs.msg import Float64

from ato_nodes.core.loop import ControllerStage
from ato_nodes.nodes.base import AtoNode, run_node


class ControllerNode(AtoNode):
    role = "controller"

    def __init__(self):
        super().__init__()
        self.stage = ControllerStage(self.values)
        self.command_pub = self.publisher("command")
        self.state_pub = self.publisher("controller_state")
        self.command_msg, self.state_msg = Float64(), Twist()
        self.subscription("target_speed", self.on_target)
        self.subscription("measured_speed", self.on_speed)
        self.ready_when_matched()

    def on_target(self, msg: Float64) -> None:
        self.stage.targets.append(msg.data)
        self.publish(self.stage.ready())

    def on_speed(self, msg: Float64) -> None:
        self.stage.speeds.append(msg.data)
        self.publish(self.stage.ready())

    def publish(self, outputs) -> None:
        for out in outputs:
            self.inject_fault(self.stage.step_index)
            self.command_msg.data = out.u
            self.command_pub.publish(self.command_msg)
            state = self.state_msg
            state.linear.x, state.linear.y, state.linear.z = out.z1, out.z2, out.z3
            state.angular.x, state.angular.y = out.v1, out.v2
            self.state_pub.publish(state)


def main() -> None:
    run_node(ControllerNode)


if __name__ == "__main__":
    main()
