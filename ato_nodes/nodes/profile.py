"""Target-speed profile node: one target per step, for the train's position."""

from __future__ import annotations

from std_msgs.msg import Float64

from ato_nodes.core.loop import ProfileStage
from ato_nodes.nodes.base import AtoNode, run_node


class ProfileNode(AtoNode):
    role = "profile"

    def __init__(self):
        super().__init__()
        self.stage = ProfileStage(self.values)
        self.step_index = 0
        self.target_pub = self.publisher("target_speed")
        self.subscription("position", self.on_position)
        self.ready_when_matched()

    def on_position(self, msg: Float64) -> None:
        self.target_pub.publish(Float64(data=self.stage.target(self.step_index, msg.data)))
        self.step_index += 1


def main() -> None:
    run_node(ProfileNode)


if __name__ == "__main__":
    main()
