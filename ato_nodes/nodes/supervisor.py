"""Run supervisor: readiness gate, start, progress, end of run, report.

It waits until every node reports its edges matched, starts the plant's
stepping, shows progress, and once the plant has finished and the recorder
holds every step, writes the run report and tells every node to shut down.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from ato_nodes.core.params import steps
from ato_nodes.nodes.base import AtoNode, run_node

PARTICIPANTS = ("profile", "plant", "controller", "recorder")
PROGRESS_PERIOD = 0.5  # s of wall time


class SupervisorNode(AtoNode):
    role = "supervisor"

    def __init__(self):
        super().__init__()
        self.waiting = set(PARTICIPANTS)
        self.total_steps = steps(self.values)
        self.period = self.values["run.period"]
        self.created = time.monotonic()
        self.started = self.finished = None
        self.finished_steps = 0
        self.diverged = False
        self.failed = False
        self.interactive = sys.stderr.isatty()
        self.last_line = 0.0
        self.create_timer(PROGRESS_PERIOD, self.on_tick, clock=self._wall_clock)

    def on_event(self, word: str, argument: str) -> None:
        if word == "ready":
            self.waiting.discard(argument)
            if not self.waiting and self.started is None:
                self.started = time.monotonic()
                self.announce("start")
        elif word == "finished":
            self.finished = time.monotonic()
            count, _, reason = argument.partition(" ")
            self.finished_steps, self.diverged = int(count), reason == "diverged"
        elif word == "recorded":
            self.report(int(argument))
            self.announce("shutdown")
            self.context.try_shutdown()

    def on_tick(self) -> None:
        now = time.monotonic()
        if self.started is None:
            if now - self.created > self.values["supervisor.ready_timeout"]:
                self.get_logger().error("nodes not ready after "
                                        f"{self.values['supervisor.ready_timeout']:g} s: "
                                        + ", ".join(sorted(self.waiting)))
                self.failed = True
                self.announce("shutdown")
                self.context.try_shutdown()
            return
        if self.finished is not None:
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

    def report(self, recorded_steps: int) -> None:
        if self.interactive:
            print(file=sys.stderr)
        loop_wall = (self.finished or time.monotonic()) - self.started
        sim_time = self.finished_steps * self.period
        report = {
            "steps": self.finished_steps,
            "diverged": self.diverged,
            "recorded_steps": recorded_steps,
            "sim_time": sim_time,
            "loop_wall_time": loop_wall,
            "steps_per_second": self.finished_steps / loop_wall if loop_wall > 0 else None,
            "real_time_factor": sim_time / loop_wall if loop_wall > 0 else None,
            "startup_wall_time": self.started - self.created,
        }
        path = self.values["supervisor.report"]
        if path:
            Path(path).write_text(json.dumps(report, indent=2))


def main() -> None:
    run_node(SupervisorNode)


if __name__ == "__main__":
    main()
