"""Target-speed profile node: on step k's position, the target horizon of step k+2
(see ato_nodes.core.run.stages for why two steps ahead) and the speed limit of step k;
on a journey, each re-plan of a late departure said on the events topic and published
for the recorder, and so each mid-run re-plan of the ato curve (profile.replan: the
position of step k then waits for the controller's outputs of step k - 1, its mass
estimate). Once it has handled the run's last step it says how many re-plans it
made ('replans <count>'): the recorder closes the bag only once it holds them all."""

from __future__ import annotations

import json
import math
from collections import deque

from std_msgs.msg import Float64, Float64MultiArray, String

from ato_nodes.core.run.located import ODOMETRY_SERIES
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
        self.replans_pub, self.replans_said = self.publisher("replans"), 0
        self.run_steps = None  # the plant's 'finished N': the steps of the run
        self.count_said = False
        # Step k's position waits, with profile.replan, for the controller's outputs of
        # step k - 1 (its on-board mass estimate): both queued, paired in step order.
        # with the adhesion seen and the located speed
        self.positions: deque[tuple[float, float, float]] = deque()
        self.estimates: deque[tuple[float, float]] = deque()
        self.estimate_columns: tuple[int, int] | None = None  # from the outputs' names
        if self.values["odometry.enabled"]:  # it drives on the located position (and the
            # adhesion seen, the located speed); the true one's edge is matched (the topic
            # map's), left unread
            entries = [ODOMETRY_SERIES.index(name) for name in (
                "located_position", "adhesion_seen", "located_speed")]
            self.subscription("odometry", lambda msg: self.on_located(
                *(msg.data[i] for i in entries)))
            self.subscription("position", lambda msg: None)
        else:
            self.subscription("position", self.on_position)
        if self.stage.settings.replan.enabled:
            self.subscription("controller_state", self.on_estimate,
                              wakes=lambda: bool(self.positions) and not self.estimates)
        self.ready_when_matched()

    def on_position(self, msg: Float64) -> None:
        self.on_located(msg.data, math.nan, math.nan)

    def on_located(self, position: float, adhesion: float, speed: float) -> None:
        self.positions.append((position, adhesion, speed))
        self.run_ready_steps()

    def on_estimate(self, msg: Float64MultiArray) -> None:
        if self.estimate_columns is None:
            names = msg.layout.dim[0].label.split(",")
            self.estimate_columns = (names.index("mass_factor"), names.index("mass_sigma"))
        mass, sigma = self.estimate_columns
        self.estimates.append((msg.data[mass], msg.data[sigma]))
        self.run_ready_steps()

    def run_ready_steps(self) -> None:
        replanning = self.stage.settings.replan.enabled
        while self.positions and (not replanning or self.stage.received == 0
                                  or self.estimates):
            estimate = self.estimates.popleft() if replanning and self.stage.received else (
                math.nan, math.nan)
            self.step(*self.positions.popleft(), *estimate)

    def step(self, position: float, adhesion: float, speed: float, mass: float,
             mass_sigma: float) -> None:
        self.inject_fault(self.stage.received)
        horizons = self.stage.on_position(position, mass, mass_sigma, adhesion, speed)
        self.say_replans()
        for horizon in horizons:
            self.horizon_msg.data = horizon
            self.horizon_pub.publish(self.horizon_msg)
            self.target_msg.data = horizon[0]
            self.target_pub.publish(self.target_msg)
        self.limit_msg.data = self.stage.speed_limit(position)
        self.limit_pub.publish(self.limit_msg)
        self.say_replan_count()

    def say_replans(self) -> None:
        """The plan's new re-plans (a journey's late departures, the ato curve's mid-run
        re-plans from the estimate): on the events topic (an INFO record on /rosout) and,
        stamped with their step, for the recorder."""
        replan = self.stage.settings.replan
        made = (self.stage.replans if replan.enabled or replan.degraded
                else getattr(self.stage.context.plan, "replans", ()))
        for replan in made[self.replans_said:]:
            self.announce(f"replanned {replan.text()}")
            step = round(replan.time / self.values["run.period"])
            self.replans_pub.publish(String(data=json.dumps({"step": step,
                                                             **replan._asdict()})))
        self.replans_said = len(made)

    def on_event(self, word: str, argument: str) -> None:
        if word == "finished":
            self.run_steps = int(argument.split()[0])
            self.say_replan_count()

    def say_replan_count(self) -> None:
        """Once the run's last step is handled (its 'finished' may come before or after
        that step's position), how many re-plans the run made: a re-plan travels on a
        topic of its own, so it may reach the recorder after the last step's messages;
        the recorder waits for as many as are said here before it closes the bag."""
        if self.count_said or self.run_steps is None or self.stage.received < self.run_steps:
            return
        self.count_said = True
        self.announce(f"replans {self.replans_said}")


def main() -> None:
    run_node(ProfileNode)


if __name__ == "__main__":
    main()
