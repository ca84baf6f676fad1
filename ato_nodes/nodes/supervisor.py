"""Run supervisor: readiness gate, start, progress, end of run, report.

It waits until every node reports its edges matched, starts the plant's
stepping, shows progress, and once the plant has finished and the recorder
holds every step, writes the run report (the steps run and why the run ended: at
run.duration, diverged, at a journey's last stop or pruned) and tells every node to
shut down.
With supervisor.fitness it also follows the target and the true speed, publishes
the running fitness every step, and ends the run as pruned once it passes
supervisor.prune_above (core.indices.RunningIndex: the numbers simulate()'s
pruning gives, bit for bit).
"""

from __future__ import annotations

import json
import sys
import time
from collections import deque
from pathlib import Path

from rclpy.duration import Duration

from std_msgs.msg import Float64

from ato_nodes.results import jsontext
from ato_nodes.core.scoring.indices import RunningIndex
from ato_nodes.core.config.schema import SUPERVISED_NODES, steps
from ato_nodes.core.scoring.catalogue import format_indices
from ato_nodes.nodes.base import AtoNode, parameter_files, run_node
from ato_nodes.bags.summary import bag_contents, write_summary

PROGRESS_PERIOD = 0.5  # s of wall time
SHUTDOWN_ACK_TIMEOUT = 2.0  # s the supervisor waits for every node to have 'shutdown'
FOLLOW_GRACE = 2.0  # s after 'recorded' for the running fitness to take the last steps


class SupervisorNode(AtoNode):
    role = "supervisor"

    def __init__(self):
        super().__init__()
        self.waiting = set(SUPERVISED_NODES)
        self.total_steps = steps(self.values)
        self.period = self.values["run.period"]
        self.created = time.monotonic()
        self.started = self.finished = None
        self.finished_steps = 0
        self.diverged = False
        self.ending = ""  # why the plant finished: its 'finished N REASON'
        self.failed = False
        self.announced: dict[str, dict] = {}
        self.interactive = sys.stderr.isatty()
        self.last_line = 0.0
        self.create_timer(PROGRESS_PERIOD, self.on_tick, clock=self._wall_clock)
        self.recorded = self.recorded_at = None
        self.ended = False
        self.running = None
        if self.values["supervisor.fitness"]:
            self.follow_fitness()

    def follow_fitness(self) -> None:
        self.running = RunningIndex(self.values["supervisor.fitness"])
        self.prune_above = self.values["supervisor.prune_above"]
        self.pruned = False
        self.targets: deque[float] = deque()
        self.speeds: deque[float] = deque()
        self.paired = 0
        self.fitness_out = self.publisher("running_fitness")
        # on the lockstep fast path (base.spin_lockstep): two messages a step, the target
        # two steps ahead of the state (the profile runs ahead), so waited for only when
        # none is queued: the supervisor wakes once a step, for the state
        self.subscription("target_speed", lambda msg: self.on_sample(self.targets, msg.data),
                          wakes=lambda: not self.targets)
        self.subscription("state", lambda msg: self.on_sample(self.speeds, msg.linear.x))

    def on_sample(self, queue: deque, value: float) -> None:
        """Step k's target and true speed, in either order; once both are in, the
        running fitness moves on by step k (t_k = k run.period, as in simulate())."""
        queue.append(value)
        while self.targets and self.speeds and not self.pruned:
            target, speed = self.targets.popleft(), self.speeds.popleft()
            value = self.running.add(self.paired * self.period, target - speed)
            self.paired += 1
            self.fitness_out.publish(Float64(data=value))
            if 0.0 < self.prune_above < value and not self.ended:
                self.pruned = self.ended = True
                self.log.info(f"pruned at step {self.paired}: running "
                                       f"{self.values['supervisor.fitness']} {value:.9g} passed "
                                       f"{self.prune_above:.9g}")
                self.report(self.paired, pruned=True)
                self.shut_down_all()
                return
        self.finish_when_followed()

    def on_event(self, word: str, argument: str) -> None:
        if word == "parameters":
            node, _, values = argument.partition(" ")
            self.check_agreement(node, json.loads(values))
        elif word == "ready":
            self.waiting.discard(argument)
            if not self.waiting and self.started is None and not self.failed:
                self.started = time.monotonic()
                self.announce("start")
        elif word == "finished":
            self.finished = time.monotonic()
            count, _, reason = argument.partition(" ")
            self.finished_steps, self.diverged = int(count), reason == "diverged"
            self.ending = reason or "at run.duration"
        elif word == "recorded":
            self.recorded, self.recorded_at = int(argument), time.monotonic()
            self.finish_when_followed()

    def finish_when_followed(self) -> None:
        """Report and end the run once the recorder holds every step and, with a running
        fitness, once every step has reached it too (FOLLOW_GRACE at most)."""
        if self.recorded is None or self.ended:
            return
        if (self.running is not None and self.paired < self.finished_steps
                and time.monotonic() - self.recorded_at < FOLLOW_GRACE):
            return
        self.ended = True
        self.report(self.recorded)
        self.shut_down_all()

    def check_agreement(self, node: str, values: dict) -> None:
        """A parameter several nodes declare must have one value in all of them (a
        scenario that gives it under one node only would run two different trains)."""
        if self.failed:
            return
        for other, known in self.announced.items():
            for name in values:  # in schema order: a train preset before what it sets
                if name in known and values[name] != known[name]:
                    self.refuse(f"{name} is {known[name]!r} in {other} but {values[name]!r} in "
                                f"{node}; give shared parameters under /** in the parameter file")
                    return
        self.announced[node] = values

    def refuse(self, message: str) -> None:
        """End the run before it starts: one line, exit status 2. The nodes are told to
        shut down once each of them hears the run events (see on_tick)."""
        self.error(message)
        self.exit_status = 2
        self.failed = True

    def shut_down_when_heard(self) -> None:
        if (self.events_out.get_subscription_count() >= len(SUPERVISED_NODES) + 1 or
                time.monotonic() - self.created > self.values["supervisor.ready_timeout"]):
            self.shut_down_all()

    def shut_down_all(self) -> None:
        """Tell every node to exit, and see it delivered before this node goes (a
        transient-local message dies with its writer: nodes started without a launcher
        to stop them would wait for ever)."""
        self.announce("shutdown")
        self.events_out.wait_for_all_acked(Duration(seconds=SHUTDOWN_ACK_TIMEOUT))
        self.shut_down()

    def on_tick(self) -> None:
        now = time.monotonic()
        if self.failed:
            self.shut_down_when_heard()
            return
        if self.started is None:
            if now - self.created > self.values["supervisor.ready_timeout"]:
                self.not_ready()
            return
        if self.finished is not None:
            self.finish_when_followed()
            return
        sim_time = self.get_clock().now().nanoseconds * 1e-9
        done = sim_time / (self.total_steps * self.period)
        rate = sim_time / self.period / max(now - self.started, 1e-9)
        line = (f"t = {sim_time:8.1f} s of {self.total_steps * self.period:.0f} s "
                f"({100 * done:5.1f} %), {rate:7.0f} steps/s")
        if self.interactive:
            print("\r" + line, end="", file=sys.stderr, flush=True)
        elif now - self.last_line >= 5.0:
            self.last_line = now
            print(line, file=sys.stderr, flush=True)

    def not_ready(self) -> None:
        """The ready timeout passed: the run fails (exit status 1), naming the nodes that
        never announced 'ready' (to the launcher in its report, which it says in one line)."""
        waiting = sorted(self.waiting)
        message = (f"nodes not ready after {self.values['supervisor.ready_timeout']:g} s: "
                   + ", ".join(waiting))
        self.log.error(message)
        if self.values["supervisor.report"]:
            Path(self.values["supervisor.report"]).write_text(jsontext.dumps(
                {"steps": 0, "failed": message, "not_ready": waiting}, indent=2))
        self.exit_status = 1  # a run that never started is a failure
        self.failed = True
        self.shut_down_all()

    def report(self, recorded_steps: int, pruned: bool = False) -> None:
        if self.interactive:
            print(file=sys.stderr)
        loop_wall = (self.finished or time.monotonic()) - self.started
        done_steps = self.paired if pruned else self.finished_steps
        sim_time = done_steps * self.period
        report = {
            "steps": done_steps,
            "diverged": self.diverged,
            "ended": "pruned" if pruned else self.ending,
            "recorded_steps": recorded_steps,
            "sim_time": sim_time,
            "loop_wall_time": loop_wall,
            "steps_per_second": done_steps / loop_wall if loop_wall > 0 else None,
            "real_time_factor": sim_time / loop_wall if loop_wall > 0 else None,
            "startup_wall_time": self.started - self.created,
        }
        if self.running is not None:
            report.update(fitness=self.running.value, fitness_steps=self.paired, pruned=pruned)
        path = self.values["supervisor.report"]
        if path:
            Path(path).write_text(jsontext.dumps(report, indent=2))
        else:
            status = "pruned" if pruned else "diverged" if self.diverged else "completed"
            self.summarize({"status": status, **report}, score=True)

    def summarize(self, summary: dict, score: bool) -> None:
        """Without a launcher to take the report (`ros2 launch`, `ros2 run`), the run's
        summary.json goes into the bag directory, with the indices of the closed bag
        (`score`) printed as run_stack.py prints them."""
        bag = self.announced.get("recorder", {}).get("recorder.output")
        if not bag or not Path(bag).is_dir():
            return
        if score:
            summary.update(bag_contents(Path(bag)))
            if "indices" in summary:
                print(format_indices(summary["indices"]), flush=True)
        files = parameter_files()  # the scenario file a launch file or `ros2 run` gave
        problem = write_summary(Path(bag), {"scenario": files[0].stem if files else "",
                                            "bag": bag, "message": "", **summary})
        if problem:
            self.error(problem)

    def on_stop(self) -> None:
        """Interrupted (SIGINT, SIGTERM): a run without a launcher says so in its
        summary.json, with the step it had reached (the recorder is still closing the
        bag: scored later by score_bag.py)."""
        super().on_stop()
        if not self.values["supervisor.report"] and not self.ended:
            steps_done = round(self.get_clock().now().nanoseconds * 1e-9 / self.period)
            self.summarize({"status": "interrupted", "steps": steps_done,
                            "message": "interrupted by a signal"}, score=False)


def main() -> None:
    run_node(SupervisorNode)


if __name__ == "__main__":
    main()
