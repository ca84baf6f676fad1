"""Target-speed profile node: on step k's position, the target horizon of step k+2
(see ato_nodes.core.run.stages for why two steps ahead) and the speed limit of step k."""

from __future__ import annotations

from std_msgs.msg import Float64, Float64MultiArray

from ato_nodes.core.run.stages import ProfileStage
from ato_nodes.nodes.base import AtoNode, run_node


class ProfileNode(AtoNode):
    role = "profile"

    def __init__(self):
        super().__init__()
        self.stage = ProfileStage(self.values)
        if self.stage.context.plan.notice:
            self.warn(self.stage.context.plan.notice)
        self.target_msg, self.limit_msg = Float64(), Float64()
        self.horizon_msg = Float64MultiArray()
        self.horizon_pub = self.publisher("target_preview")
        self.target_pub = self.publisher("target_speed")
        self.limit_pub = self.publisher("speed_limit")
        self.subscription("position", self.on_position)
        self.ready_when_matched()

    def on_position(self, msg: Float64) -> None:
        self.inject_fault(self.stage.received)
        for horizon in self.stage.on_position(msg.data):
            self.horizon_msg.data = horizon
            self.horizon_pub.publish(self.horizon_msg)
            self.target_msg.data = horizon[0]
            self.target_pub.publish(self.target_msg)
        self.limit_msg.data = self.stage.speed_limit(msg.data)
        self.limit_pub.publish(self.limit_msg)


def main() -> None:
    run_node(ProfileNode)


if __name__ == "__main__":
    main()
