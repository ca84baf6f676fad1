"""Recorder node: writes every per-step topic of the topic map to a rosbag2
MCAP bag, as the raw CDR bytes received.

Each message is stamped with the simulated time of its step (the k-th message
of a topic belongs to step k), so a run's bag is identical however the
messages interleaved. The bag is closed in every exit path (end of run,
SIGINT, SIGTERM, a failing node), so it stays readable up to the last step
received. The bag's metadata keeps the parameters the loop's nodes announced
(each its own, with the line's text), so it can be scored and re-run alone.
"""

from __future__ import annotations

import json
from pathlib import Path

from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from ato_nodes.core.errors import ScenarioError
from ato_nodes.core.topics import step_topics
from ato_nodes.bagio import PARAMETERS_KEY
from ato_nodes.nodes.base import AtoNode, run_node


RUN_NODES = ("profile", "plant", "controller")  # whose parameters describe the run


class RecorderNode(AtoNode):
    role = "recorder"

    def __init__(self):
        super().__init__()
        output = self.values["recorder.output"]
        if not output:
            raise ScenarioError("recorder.output is empty: give the bag directory to create")
        if Path(output).exists():
            raise ScenarioError(f"recorder.output {output} exists already")
        self.period_ns = self.values["run.period"] * 1e9
        self.expected = None
        self.writer = Writer(output, version=9, storage_plugin=StoragePlugin.MCAP)
        self.writer.open()
        self.run_parameters: dict[str, dict] = {}  # node -> the values it announced
        typestore = get_typestore(Stores.ROS2_JAZZY)
        self.counts: dict[str, int] = {}
        for topic in step_topics():
            connection = self.writer.add_connection(topic.name, topic.type, typestore=typestore)
            self.counts[topic.name] = 0
            self.subscription(topic.key, self._make_callback(topic.name, connection), raw=True)
        self.ready_when_matched()

    def _make_callback(self, name, connection):
        counts, period_ns = self.counts, self.period_ns

        def record(data: bytes) -> None:
            if self.writer is None:  # closed: the run is complete or ending
                return
            k = counts[name]
            self.inject_fault(k)
            self.writer.write(connection, round(k * period_ns), data)
            counts[name] = k + 1
            if self.expected is not None:
                self._check_complete()
        return record

    def on_event(self, word: str, argument: str) -> None:
        if word == "parameters":
            node, _, values = argument.partition(" ")
            if node in RUN_NODES:
                self.run_parameters[node] = json.loads(values)
        elif word == "finished":
            self.expected = int(argument.split()[0])
            self._check_complete()

    def _check_complete(self) -> None:
        if self.writer is not None and min(self.counts.values()) >= self.expected:
            self.close()
            self.announce(f"recorded {self.expected}")

    def close(self) -> None:
        if self.writer is not None:
            writer, self.writer = self.writer, None
            if self.run_parameters:  # what the loop's nodes ran with: the bag explains itself
                merged = {name: value for node in RUN_NODES
                          for name, value in self.run_parameters.get(node, {}).items()}
                writer.set_custom_data(PARAMETERS_KEY, json.dumps(merged))
            writer.close()


def main() -> None:
    run_node(RecorderNode)


if __name__ == "__main__":
    main()
