"""Where a node's time goes, part by part: off unless $ATO_NODE_TIMING names a folder.

With it, each node writes FOLDER/ROLE.json as it exits: for each part of its loop (the
lockstep wait, the takes, the handling of each per-step input, each topic's publishes,
the bag writes, the executor's housekeeping passes) the wall and thread-CPU nanoseconds
summed and the count, and the CPU time of the whole process (DDS's threads included),
from the run's 'start' (or the node's first per-step input, if that comes first) to its
'finished' as the node hears them (another node than the plant may hear 'start' a few
steps late: over a long run, the figures per step are what a step costs).
`benchmarks/benchmark.py --profile` prints them per step. The parts are wrapped in
place before the node spins, so a node without the variable runs exactly its usual code.
"""

from __future__ import annotations

import atexit
import json
import os
import time
from pathlib import Path
from typing import Callable

VARIABLE = "ATO_NODE_TIMING"


def _timing(function: Callable, totals: list[int]) -> Callable:
    """`function`, adding its wall and CPU time and one call to `totals`."""
    def timed(*args, **kwargs):
        wall, cpu = time.perf_counter_ns(), time.thread_time_ns()
        try:
            return function(*args, **kwargs)
        finally:
            totals[0] += time.perf_counter_ns() - wall
            totals[1] += time.thread_time_ns() - cpu
            totals[2] += 1
    return timed


class _NodeTiming:
    """A node's parts' totals (wall ns, CPU ns, calls), and the totals and the process
    CPU as the handling of 'start' and of 'finished' begins: the loop is what comes
    between, in the parts and the process CPU alike ('start' logged, and the plant's
    step 0, in; 'finished' out)."""

    def __init__(self, role: str, folder: str):
        self.role, self.folder = role, folder
        self.parts: dict[str, list[int]] = {}
        self.loop: dict[str, tuple] = {}  # 'start', 'finished': (CPU ns, steps, parts)

    def part(self, name: str) -> list[int]:
        return self.parts.setdefault(name, [0, 0, 0])

    def wrap(self, owner, attribute: str, name: str) -> None:
        setattr(owner, attribute, _timing(getattr(owner, attribute), self.part(name)))

    def _note(self, word: str, steps: int = 0) -> None:
        """The totals as the loop's `word` ('start', 'finished') is first met."""
        if word not in self.loop:
            self.loop[word] = (time.process_time_ns(), steps,
                               {name: list(totals) for name, totals in self.parts.items()})

    def noting_the_loop(self, handle: Callable) -> Callable:
        """The run events' handler `handle`, noting the totals at 'start' and 'finished'
        (the first of each only: a 'start' noted again after 'finished' would turn the
        loop inside out)."""
        def handling(msg) -> None:
            word, _, argument = msg.data.partition(" ")
            if word in ("start", "finished"):
                self._note(word, int(argument.split()[0]) if word == "finished" else 0)
            handle(msg)
        return handling

    def noting_a_step(self, handle: Callable) -> Callable:
        """A per-step input's handler `handle`, noting the loop's start at its first
        message if the node has not heard 'start' yet: run events of different nodes
        arrive in no fixed order, and a 'start' delivered late (seen: a recorder's after
        the plant's 'finished', its loop CPU negative) would leave the loop unbounded."""
        def handling(msg) -> None:
            self._note("start")
            handle(msg)
        return handling

    def write(self) -> None:
        """The loop's share (from 'start' to 'finished'), if the node heard both."""
        if len(self.loop) < 2:
            return
        (cpu_start, _, start), (cpu_end, steps, end) = self.loop["start"], self.loop["finished"]
        Path(self.folder, f"{self.role}.json").write_text(json.dumps({
            "steps": steps, "process_cpu_ns": cpu_end - cpu_start,
            "parts": {name: [a - b for a, b in zip(end[name], start[name], strict=True)]
                      for name in self.parts}}))


def install(node, shared: dict[str, tuple[object, str]]) -> None:
    """Time `node`'s parts (an AtoNode's, before it spins) if $ATO_NODE_TIMING is set:
    its publishers, lockstep handlers and bag writer, and the `shared` parts (name ->
    the object and attribute to wrap: the wait set's wait and take, the housekeeping),
    which nodes/base.py hands in (this module imports nothing of it)."""
    folder = os.environ.get(VARIABLE)
    if not folder:
        return
    timing = _NodeTiming(node.role, folder)
    for name, (owner, attribute) in shared.items():
        timing.wrap(owner, attribute, name)
    for publisher, topic in node._outgoing:
        timing.wrap(publisher, "publish", f"publish {topic.name}")
    names = {subscription: topic.name for subscription, topic in node._incoming}
    names[node.events_in] = node.topics["events"].name
    node.lockstep_inputs[:] = [
        (subscription, _timing(callback if subscription is node.events_in
                               else timing.noting_a_step(callback),
                               timing.part(f"handle {names[subscription]}")), wakes)
        for subscription, callback, wakes in node.lockstep_inputs]
    events = next(index for index, (subscription, _, _) in enumerate(node.lockstep_inputs)
                  if subscription is node.events_in)
    subscription, handle, wakes = node.lockstep_inputs[events]
    node.lockstep_inputs[events] = (subscription, timing.noting_the_loop(handle), wakes)
    # where the standard executor serves the inputs (no fast path): its callback
    node.events_in.callback = timing.noting_the_loop(node.events_in.callback)
    if getattr(node, "writer", None) is not None:  # the recorder's bag
        timing.wrap(node.writer, "write", "bag write")
    atexit.register(timing.write)
