"""Train plant simulator node: owns simulated time and publishes /clock.

Like a physics simulator it is the clock source: on 'start' it publishes step
0, and every command it receives advances the train one period and
publishes the next step, until run.duration is reached ('finished N'), the run
diverges ('finished N diverged') or a journey's train has stood run.last_stop_hold at
its last stop ('finished N at the last stop': a complete run, core/run/last_stop.py).
"""

from __future__ import annotations

import time

from geometry_msgs.msg import Twist
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64

from ato_nodes.core.run.last_stop import AT_LAST_STOP
from ato_nodes.core.run.stages import PlantStage
from ato_nodes.core.config.schema import recording_steps, steps
from ato_nodes.core.run.located import ODOMETRY_SERIES
from ato_nodes.nodes.base import AtoNode, labelled, run_node


class PlantNode(AtoNode):
    role = "plant"

    def __init__(self):
        super().__init__(use_sim_time=False)
        self.stage = PlantStage(self.values)
        self.period = self.values["run.period"]
        self.total_steps = steps(self.values)
        self.real_time = self.values["run.real_time"]
        self.step_index = 0
        self.started_at = 0.0
        self.clock_pub = self.publisher("clock")
        self.position_pub = self.publisher("position")
        self.speed_pub = self.publisher("measured_speed")
        # with controller.slip_hold, the controller's second input of a step
        self.effort_pub = (self.publisher("drive_effort")
                           if self.values["controller.slip_hold"] else None)
        self.effort_msg = Float64()
        # with odometry, the profile takes the located position from it (core/run/located.py)
        self.odometry_pub = (self.publisher("odometry")
                             if self.values["odometry.enabled"] else None)
        self.odometry_msg = labelled(ODOMETRY_SERIES)
        self.state_pub = self.publisher("state")
        self.speed_msg, self.position_msg = Float64(), Float64()
        self.clock_msg, self.state_msg = Clock(), Twist()
        _, self.record_window = recording_steps(self.values)
        self.recorded_steps = 0
        self.held = False  # the next step waits for the recorder
        self.subscription("command", self.on_command)
        self.subscription("recorded", self.on_recorded)
        self.ready_when_matched()

    def on_event(self, word: str, argument: str) -> None:
        if word == "start" and self.step_index == 0:
            self.started_at = time.monotonic()
            self.publish_step()

    def publish_step(self) -> None:
        """Publish step k, the controller's input first: y_k -> u_k is the critical path
        of a step, and each publish costs tens of us per subscribing process. The
        profile's position next (it works two steps ahead), then the rest."""
        out = self.stage.outputs()
        self.speed_msg.data = out.measured_speed
        self.speed_pub.publish(self.speed_msg)
        if self.effort_pub is not None:
            self.effort_msg.data = out.drive_effort
            self.effort_pub.publish(self.effort_msg)
        if self.odometry_pub is not None:
            self.odometry_msg.data = out.odometry
            self.odometry_pub.publish(self.odometry_msg)
        self.position_msg.data = out.position
        self.position_pub.publish(self.position_msg)
        nanoseconds = round(self.step_index * self.period * 1e9)
        self.clock_msg.clock.sec, self.clock_msg.clock.nanosec = divmod(nanoseconds, 1_000_000_000)
        self.clock_pub.publish(self.clock_msg)
        state = self.state_msg
        state.linear.x, state.linear.y, state.linear.z = (out.speed, out.acceleration,
                                                          out.disturbance)
        state.angular.x, state.angular.y, state.angular.z = (out.force, out.resistance,
                                                             out.line_resistance)
        self.state_pub.publish(state)

    def on_command(self, msg: Float64) -> None:
        self.inject_fault(self.step_index)
        self.stage.apply(msg.data)
        self.step_index += 1
        if self.stage.diverged:
            self.announce(f"finished {self.step_index} diverged")
            return
        if self.stage.arrived:
            self.announce(f"finished {self.step_index} {AT_LAST_STOP}")
            return
        if self.step_index >= self.total_steps:
            self.announce(f"finished {self.step_index}")
            return
        if self.real_time:
            delay = self.started_at + self.step_index * self.period - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        if self.record_window is not None and \
                self.step_index > self.recorded_steps + self.record_window:
            self.held = True  # resumed by on_recorded
            return
        self.publish_step()

    def on_recorded(self, msg) -> None:
        """The recorder's steps on disk: a step held back for it may go now."""
        self.recorded_steps = msg.data
        if self.held and self.step_index <= self.recorded_steps + self.record_window:
            self.held = False
            self.publish_step()


def main() -> None:
    run_node(PlantNode)


if __name__ == "__main__":
    main()
