"""Speed-tracking controller node: pairs step k's target and measured speed
(by arrival order; Float64 carries no stamp) and publishes the command."""

from __future__ import annotations

from collections import deque

from geometry_msgs.msg import Twist
from std_msgs.msg import Float64

from ato_nodes.core.loop import ControllerStage
from ato_nodes.nodes.base import AtoNode, run_node


class ControllerNode(AtoNode):
    role = "controller"

    def __init__(self):
        super().__init__()
        self.stage: ControllerStage | None = None
        self.targets: deque[float] = deque()
        self.speeds: deque[float] = deque()
        self.command_pub = self.publisher("command")
        self.state_pub = self.publisher("controller_state")
        self.subscription("target_speed", self.on_target)
        self.subscription("measured_speed", self.on_speed)
        self.ready_when_matched()

    def on_target(self, msg: Float64) -> None:
        self.targets.append(msg.data)
        self.try_step()

    def on_speed(self, msg: Float64) -> None:
        self.speeds.append(msg.data)
        self.try_step()

    def try_step(self) -> None:
        while self.targets and self.speeds:
            target, speed = self.targets.popleft(), self.speeds.popleft()
            if self.stage is None:
                self.stage = ControllerStage(self.values, target, speed)
            out = self.stage.step(target, speed)
            self.command_pub.publish(Float64(data=out.u))
            state = Twist()
            state.linear.x, state.linear.y, state.linear.z = out.z1, out.z2, out.z3
            state.angular.x, state.angular.y = out.v1, out.v2
            self.state_pub.publish(state)


def main() -> None:
    run_node(ControllerNode)


if __name__ == "__main__":
    main()
