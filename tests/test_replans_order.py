"""A journey's re-plans are in its bag however late they reach the recorder: the profile
says how many it made once it has handled the run's last step, and the recorder closes
the bag only once it holds that many (or, after nodes/recorder.REPLANS_LIMIT, with a
warning naming what is missing). No node waits for DDS acknowledgements for it."""

import json
import subprocess
import sys

import pytest
from rosbags.highlevel import AnyReader

from ato_nodes.bags.bagio import read_run
from ato_nodes.core.base.topics import step_topics, topic_map
from ato_nodes.core.config.context import RunContext
from ato_nodes.core.config.scenario import prepare
from ato_nodes.core.config.schema import SPEC_BY_NAME, recording_steps
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.targets.served import replans
from ato_nodes.launcher.launch import node_environment
from commands import ROOT
from test_stack import start_stack

pytestmark = pytest.mark.integration
SCENARIO = "seed004-metro-line"
DELAYED = "profile.journey.dwell_extension=2:30"  # four re-plans, the second at step 3315
REPLANS = topic_map()["replans"].name

# Plays the plant and the profile for a recorder started alone: every per-step topic for
# STEPS steps, then, once the recorder has flushed the last of them (its /ato/run/recorded:
# it holds every step), the profile's count of re-plans ('said': 'replans 1'; 'late': that
# and the re-plan after it; 'unsaid': neither) and waits for the recorder's 'recorded'.
# Prints what it saw as JSON.
PROBE = """
import json, sys, time
sys.path.insert(0, sys.argv[3])
import rclpy
from rclpy.duration import Duration
from std_msgs.msg import String, UInt64
from ato_nodes.core.base.topics import step_topics, topic_map
from ato_nodes.nodes.base import QOS, message_class
from ato_nodes.nodes.recorder import STEP_STAMPED
from probes import init_in_held_domain

mode, steps = sys.argv[1], int(sys.argv[2])
init_in_held_domain()
node = rclpy.create_node("replans_probe")
topics = topic_map()
per_step = [(node.create_publisher(message_class(t.type), t.name, QOS[t.qos]),
             message_class(t.type)()) for t in step_topics()]
stamped = {key: node.create_publisher(String, topics[key].name, QOS["events"])
           for key in STEP_STAMPED}
events = node.create_publisher(String, topics["events"].name, QOS["events"])
heard, flushed = [], [0]
node.create_subscription(String, topics["events"].name, lambda m: heard.append(m.data),
                         QOS["events"])
node.create_subscription(UInt64, topics["recorded"].name,
                         lambda m: flushed.__setitem__(0, m.data), QOS["data"])
publishers = [p for p, _ in per_step] + list(stamped.values())


def spin_until(done):
    deadline = time.monotonic() + 60.0
    while not done():
        if time.monotonic() > deadline:
            print(json.dumps({"timed_out": True, "heard": heard}))
            sys.exit(1)
        rclpy.spin_once(node, timeout_sec=0.05)


spin_until(lambda: "ready recorder" in heard and all(p.get_subscription_count()
                                                     for p in publishers))
events.publish(String(data=f"finished {steps}"))
for _ in range(steps):
    for publisher, message in per_step:
        publisher.publish(message)
spin_until(lambda: flushed[0] >= steps)
closed_before = f"recorded {steps}" in heard
if mode != "unsaid":
    events.publish(String(data="replans 1"))
if mode == "late":
    stamped["replans"].publish(String(data=json.dumps({"step": steps - 1, "origin": "A"})))
spin_until(lambda: f"recorded {steps}" in heard)
print(json.dumps({"closed_before_the_replan": closed_before}))
events.publish(String(data="shutdown"))
events.wait_for_all_acked(Duration(seconds=2.0))
"""


def recorded_replans(bag) -> list[tuple[int, dict]]:
    """The bag's re-plans: (stamp, message) in the bag's order."""
    with AnyReader([bag]) as reader:
        connections = [c for c in reader.connections if c.topic == REPLANS]
        if not connections:  # (none given, rosbags reads every topic)
            return []
        return [(stamp, json.loads(reader.deserialize(raw, connection.msgtype).data))
                for connection, stamp, raw in reader.messages(connections=connections)]


def per_step_counts(bag) -> set[int]:
    """The numbers of messages the bag's per-step topics hold."""
    names = {topic.name for topic in step_topics()}
    with AnyReader([bag]) as reader:
        return {connection.msgcount for connection in reader.connections
                if connection.topic in names}


def recorder_against_probe(bag, mode: str, ros_domain) -> tuple[dict, str]:
    """A recorder alone, fed by PROBE in `mode`: what the probe saw, the recorder's
    stderr."""
    env = node_environment(ros_domain.domain_id)
    period = SPEC_BY_NAME["run.period"].default
    block, _ = recording_steps({"run.period": period,
                                "run.record_lag": SPEC_BY_NAME["run.record_lag"].default})
    steps = 2 * block  # a whole number of flushed blocks: its flush says the last step is in
    recorder = subprocess.Popen([sys.executable, "-m", "ato_nodes.nodes.recorder", "--ros-args",
                                 "-p", f"recorder.output:={bag}", "--disable-stdout-logs"],
                                env=env, cwd=ROOT, stderr=subprocess.PIPE, text=True)
    try:
        probe = subprocess.run([sys.executable, "-c", PROBE, mode, str(steps),
                                str(ROOT / "tests")], env=env, cwd=ROOT,
                               capture_output=True, text=True, timeout=120)
        _, stderr = recorder.communicate(timeout=30)
    finally:
        recorder.kill()
        recorder.wait()
    assert probe.returncode == 0, probe.stdout + probe.stderr
    assert recorder.returncode == 0, stderr
    seen = json.loads(probe.stdout.splitlines()[-1])
    return {"steps": steps, "period": period, **seen}, stderr


def test_a_replan_that_reaches_the_recorder_after_the_last_step_is_in_the_bag(
        tmp_path, ros_domain):
    """The re-plan is sent only once the recorder holds every step of the run and has
    heard the count: the bag waited for it."""
    bag = tmp_path / "bag"
    seen, stderr = recorder_against_probe(bag, "late", ros_domain)
    assert not seen["closed_before_the_replan"]
    last = seen["steps"] - 1
    assert recorded_replans(bag) == [(round(last * seen["period"] * 1e9),
                                      {"step": last, "origin": "A"})]
    assert "warning" not in stderr


@pytest.mark.parametrize("mode,said", [
    ("said", "1 of the 1 re-plans the profile made did not arrive"),
    ("unsaid", "the profile did not say how many re-plans it made"),
])
def test_a_replan_that_never_comes_closes_the_bag_with_one_warning(tmp_path, ros_domain, mode,
                                                                   said):
    bag = tmp_path / "bag"
    seen, stderr = recorder_against_probe(bag, mode, ros_domain)
    assert recorded_replans(bag) == []
    assert per_step_counts(bag) == {seen["steps"]}
    (line,) = [line for line in stderr.splitlines() if "warning" in line]
    assert line.startswith(f"recorder: warning: {said} within ")
    assert line.endswith("of the run's last step; the bag is closed with the 0 it holds")


def test_a_run_ending_at_its_replan_step_records_every_replan_in_order(tmp_path, ros_domain):
    full = prepare(SCENARIO, [DELAYED])
    period = full["run.period"]
    second = replans(RunContext(full).plan, period, simulate(full)["position"])[1]
    last = round(second.time / period)
    overrides = [DELAYED, f"run.duration={(last + 1) * period!r}"]  # the re-plan's step last
    bag = tmp_path / "bag"
    process = start_stack("--scenario", SCENARIO, "--out", str(bag), "--quiet",
                          *(f"--set={item}" for item in overrides), domain=ros_domain)
    _, stderr = process.communicate(timeout=600)
    assert process.returncode == 0, stderr
    values = prepare(SCENARIO, overrides)
    made = replans(RunContext(values).plan, period, simulate(values)["position"])
    assert [round(replan.time / period) for replan in made] == [
        round(made[0].time / period), last]
    assert read_run(bag).replans == [{"step": round(replan.time / period), **replan._asdict()}
                                     for replan in made]
