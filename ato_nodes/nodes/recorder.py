"""Recorder node: writes every per-step topic of the topic map to a rosbag2
MCAP bag, as the raw CDR bytes received, the controller's live parameter
changes and a journey's re-plans (each stamped with the step it took effect at).

Each message is stamped with the simulated time of its step (the k-th message
of a topic belongs to step k), so a run's bag is identical however the
messages interleaved. At the end of a run the bag is closed once it holds every step
of every topic and as many re-plans as the profile says the run made (a re-plan travels
on a topic of its own and may come after the last step's messages). The bag is closed
in every exit path (end of run, SIGINT, SIGTERM, a failing node): on a signal it first
takes what DDS still delivers (the other nodes flush their data to it as they stop),
then closes. The bag's metadata keeps the parameters the loop's nodes announced (each
its own, with the line's text), so it can be scored and re-run alone; they are also
written to parameters.json in the bag as soon as they are known.

Against a hard kill (SIGKILL, power loss) the MCAP chunk is closed and handed to
the operating system every half run.record_lag of simulated time (0.5 s), and
the plant never runs more than run.record_lag (1 s) ahead of what is on disk, so
a killed recorder loses at most that, however loaded the machine; ato_nodes.bags.bagrepair
makes what is on disk a complete bag again (the launcher runs it; scripts/repair_bag.py
for a bag left by anything else).
A write that fails (a full disk) ends the recording with one line and exit
status 1; what was written before stays readable after the repair.
"""

from __future__ import annotations

import json
import signal
from pathlib import Path

from rclpy.serialization import deserialize_message
from std_msgs.msg import String, UInt64

from rosbags.interfaces import Qos
from rosbags.typesys import Stores, get_typestore

from ato_nodes.bags.bagio import PARAMETERS_KEY
from ato_nodes.bags.bagwrite import close_writer, open_writer, qos
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.schema import LOOP_NODES, recording_steps
from ato_nodes.core.base.topics import Topic, step_topics
from ato_nodes.nodes.base import QOS, AtoNode, LockstepInputs, run_node, take_queued


def offered_qos(topic: Topic) -> list[Qos]:
    """The QoS the topic's publishers offer (the topic map's), as the bag keeps it."""
    profile = QOS[topic.qos]
    return [qos(profile.history.name, profile.depth, profile.reliability.name,
                profile.durability.name)]


RUN_NODES = LOOP_NODES  # whose parameters describe the run
DRAIN_QUIET = 0.5   # s: after a signal, record until nothing has arrived for this long
DRAIN_LIMIT = 4.0   # s at most (the launcher escalates to SIGTERM after 5 s)
SIDECAR = "parameters.json"
# During the run the recorder wakes for this topic's messages only (one a step) and takes
# every other topic's then: once a step instead of once per message (nine a step), off
# the loop's critical path and out of its way on a shared CPU. A message that arrives
# after its step's /clock waits in its reliable keep-all reader for the next one.
WAKING_TOPIC = "clock"
# Topics of what happened at a step (not one message a step): the controller's live gain
# changes and a journey's re-plans, recorded as they come
STEP_STAMPED = ("parameter_changes", "replans")
# s of wall time a bag that holds every step waits for the re-plans the profile says it
# made (they come within milliseconds of the last step's messages); then it closes with
# what it holds, and says what is missing
REPLANS_LIMIT = 5.0


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
        self.flush_steps, _ = recording_steps(self.values)
        self.flushed_pub = self.publisher("recorded")
        self.flushed_msg = UInt64()
        self.output = Path(output)
        self.expected = None
        self.writer = open_writer(self.output)
        self.run_parameters: dict[str, dict] = {}  # node -> the values it announced
        typestore = get_typestore(Stores.ROS2_JAZZY)
        self.counts: dict[str, int] = {}
        for topic in step_topics(self.values):
            connection = self.writer.add_connection(topic.name, topic.type, typestore=typestore,
                                                    offered_qos_profiles=offered_qos(topic))
            self.counts[topic.name] = 0
            self.subscription(topic.key, self._make_callback(topic.name, connection), raw=True,
                              wakes=None if topic.key == WAKING_TOPIC else self._ending)
        self.typestore = typestore
        self.event_connections: dict[str, object] = {}  # added with the first: most runs have none
        self.step_stamped = []  # (subscription, its callback): taken once more at the end
        self.stamped_counts = dict.fromkeys(STEP_STAMPED, 0)
        for key in STEP_STAMPED:
            record = self._stamped_recorder(key)
            self.step_stamped.append((self.subscription(key, self._then_check(record),
                                                        raw=True), record))
        self.replans_made = None  # the profile's 'replans N', said after the run's last step
        self.replans_timer = None  # REPLANS_LIMIT, from when the bag holds every step
        self.replans_overdue = False
        self.flush(0)  # the topics are on disk before any step: a kill leaves a bag to repair
        self.ready_when_matched()

    def _ending(self) -> bool:
        """Every topic wakes the recorder once the run ends (its last messages complete
        the bag) or a signal stops it (it drains what still arrives)."""
        return self.expected is not None or self.stop_requested

    def _make_callback(self, name, connection):
        counts, period_ns, flush_steps = self.counts, self.period_ns, self.flush_steps

        def record(data: bytes) -> None:
            if self.writer is None:  # closed: the run is complete or ending
                return
            k = counts[name]
            if name == "/clock":
                self.inject_fault(k)
            try:
                self.writer.write(connection, round(k * period_ns), data)
                counts[name] = k + 1
                # the last topic to complete a block of steps flushes it
                if (k + 1) % flush_steps == 0 and min(counts.values()) == k + 1:
                    self.flush(k + 1)
            except OSError as exc:
                self.write_failed(exc)
                return
            if self.expected is not None:
                self._check_complete()
        return record

    def _stamped_recorder(self, key: str):
        """A callback recording topic `key`'s messages (JSON with a "step"), each stamped
        with the time of the step it took effect at."""
        def record(data: bytes) -> None:
            if self.writer is None:
                return
            step = json.loads(deserialize_message(data, String).data)["step"]
            try:
                if key not in self.event_connections:
                    topic = self.topics[key]
                    self.event_connections[key] = self.writer.add_connection(
                        topic.name, topic.type, typestore=self.typestore,
                        offered_qos_profiles=offered_qos(topic))
                self.writer.write(self.event_connections[key], round(step * self.period_ns), data)
                self.stamped_counts[key] += 1
            except OSError as exc:
                self.write_failed(exc)
        return record

    def _then_check(self, record):
        """`record`, then whether the bag is complete now (a re-plan may complete it)."""
        def record_and_check(data: bytes) -> None:
            record(data)
            self._check_complete()
        return record_and_check

    def flush(self, steps: int) -> None:
        """Close the MCAP chunk being filled and hand it to the operating system, then
        tell the plant how many steps are on disk (it runs at most run.record_lag
        ahead), so a hard kill loses at most that. (rosbags 0.11's MCAP writer closes
        chunks only at 1 MiB; its close_chunk() and file are used here.)"""
        storage = self.writer.storage
        if storage.chunk.bio.tell():
            storage.close_chunk()
        storage.bio.flush()
        self.flushed_msg.data = steps
        self.flushed_pub.publish(self.flushed_msg)

    def write_failed(self, exc: OSError) -> None:
        """A full disk (or any failed write): stop recording, keep what is on disk."""
        self.error(f"cannot write the bag {self.output}: {exc.strerror or exc}; recording "
                   f"stopped at {min(self.counts.values())} steps")
        writer, self.writer = self.writer, None
        try:
            writer.abort()
        except OSError:
            pass
        self.exit_status = 1
        self.stop_requested = True

    def on_event(self, word: str, argument: str) -> None:
        if word == "parameters":
            node, _, values = argument.partition(" ")
            if node in RUN_NODES:
                self.run_parameters[node] = json.loads(values)
                if self.run_parameters.keys() == set(RUN_NODES):
                    self._write_sidecar()
        elif word == "finished":
            self.expected = int(argument.split()[0])
            self._check_complete()
        elif word == "replans":
            self.replans_made = int(argument)
            self._check_complete()

    def _check_complete(self) -> None:
        if self.writer is None or self.expected is None or \
                min(self.counts.values()) < self.expected:
            return
        # what happened at a step is on its way apart from the step's messages and may be
        # queued still (a live gain change, a re-plan at the last step)
        for subscription, record in self.step_stamped:
            for message in take_queued(subscription):
                record(message)
        if not self._holds_every_replan():
            return
        self.close()
        self.announce(f"recorded {self.expected}")

    def _holds_every_replan(self) -> bool:
        """Whether the bag holds as many re-plans as the profile said it made, or
        REPLANS_LIMIT has passed since it held every step; until then it waits."""
        made = self.replans_made
        if self.replans_overdue or made is not None and self.stamped_counts["replans"] >= made:
            if self.replans_timer is not None:
                self.replans_timer.cancel()
            return True
        if self.replans_timer is None:
            self.replans_timer = self.create_timer(REPLANS_LIMIT, self._replans_overdue,
                                                   clock=self._wall_clock)
        return False

    def _replans_overdue(self) -> None:
        self.replans_timer.cancel()
        self.replans_overdue = True
        held = self.stamped_counts["replans"]
        missing = ("the profile did not say how many re-plans it made" if self.replans_made
                   is None else f"{self.replans_made - held} of the {self.replans_made} "
                   "re-plans the profile made did not arrive")
        self.warn(f"{missing} within {REPLANS_LIMIT:g} s of the run's last step; the bag is "
                  f"closed with the {held} it holds")
        self._check_complete()

    def merged_parameters(self) -> dict:
        return {name: value for node in RUN_NODES
                for name, value in self.run_parameters.get(node, {}).items()}

    def _write_sidecar(self) -> None:
        temporary = self.output / (SIDECAR + ".tmp")
        try:
            temporary.write_text(json.dumps(self.merged_parameters()))
            temporary.replace(self.output / SIDECAR)
        except OSError as exc:
            self.write_failed(exc)

    def on_stop(self) -> None:
        """A signal: record what is still on its way, then close (in close())."""
        LockstepInputs(self).drain(DRAIN_QUIET, DRAIN_LIMIT)

    def close(self) -> None:
        """Close the bag; signals wait until it is closed (a bag half-closed is lost)."""
        if self.writer is None:
            return
        blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
        try:
            if self.run_parameters:  # what the loop's nodes ran with: the bag explains itself
                self.writer.set_custom_data(PARAMETERS_KEY, json.dumps(self.merged_parameters()))
            close_writer(self.writer, self.output)
            self.writer = None
        except OSError as exc:
            self.write_failed(exc)
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, blocked)


def main() -> None:
    run_node(RecorderNode)


if __name__ == "__main__":
    main()
