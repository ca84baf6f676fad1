"""Target-speed profile node: on step k's position, the target of step k+1
(see ato_nodes.core.loop for why one step ahead)."""

from __future__ import annotations

from std_msgs.msg import Float64

from ato_nodes.core.loop import ProfileStage
from ato_nodes.nodes.base import AtoNode, run_node


class ProfileNode(AtoNode):
    role = "profile"

    def __init__(self):
        super().__init__()
        self.stage = ProfileStage(self.values)
        self.target_msg = Float64()
        self.target_pub = self.publisher("target_speed")
        self.subscription("position", self.on_position)
        self.ready_when_matched()

    def on_position(self, msg: Float64) -> None:
        self.inject_fault(self.stage.received)
        for target in self.stage.on_position(msg.data):
            self.target_msg.data = target
            self.target_pub.publish(self.target_msg)


def main() -> None:
    run_node(ProfileNode)


if __name__ == "__main__":
    main()
