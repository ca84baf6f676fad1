"""Target-speed profile node: on step k's position, the target horizon of step k+2
(see ato_nodes.core.run.stages for why two steps ahead) and the speed limit of step k;
on a journey, each re-plan of a late departure said on the events topic and published
for the recorder."""

from __future__ import annotations

import json

from rclpy.duration import Duration
from std_msgs.msg import Float64, Float64MultiArray, String

from ato_nodes.core.run.stages import ProfileStage
from ato_nodes.nodes.base import FLUSH_TIMEOUT, AtoNode, run_node


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
        self.replans_pub, self.replans_said = self.publisher("replans"), 0
        self.subscription("position", self.on_position)
        self.ready_when_matched()

    def on_position(self, msg: Float64) -> None:
        self.inject_fault(self.stage.received)
        horizons = self.stage.on_position(msg.data)
        self.say_replans()  # before the step's messages: see say_replans
        for horizon in horizons:
            self.horizon_msg.data = horizon
            self.horizon_pub.publish(self.horizon_msg)
            self.target_msg.data = horizon[0]
            self.target_pub.publish(self.target_msg)
        self.limit_msg.data = self.stage.speed_limit(msg.data)
        self.limit_pub.publish(self.limit_msg)

    def say_replans(self) -> None:
        """The plan's new re-plans (a journey's late departures): on the events topic (an
        INFO record on /rosout) and, stamped with their step, for the recorder, which has
        them before this step's messages leave: the last of those may complete its bag,
        and another topic's message may arrive after it (a re-plan at the run's last
        step was lost so)."""
        made = getattr(self.stage.context.plan, "replans", ())
        for replan in made[self.replans_said:]:
            self.announce(f"replanned {replan.text()}")
            step = round(replan.time / self.values["run.period"])
            self.replans_pub.publish(String(data=json.dumps({"step": step,
                                                             **replan._asdict()})))
        if len(made) > self.replans_said:
            self.replans_pub.wait_for_all_acked(Duration(seconds=FLUSH_TIMEOUT))
        self.replans_said = len(made)


def main() -> None:
    run_node(ProfileNode)


if __name__ == "__main__":
    main()
