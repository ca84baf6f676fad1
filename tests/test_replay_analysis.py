"""Replay onto a live graph, re-recording, reports, and bags that are not ours."""

import json
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from ato_nodes.core.base.topics import step_topics
from ato_nodes.launcher.launch import node_environment
from commands import invocation

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[1]
PYTHON = sys.executable
STEP_TOPICS = {topic.name: topic.type for topic in step_topics()}


def script(name, *args, timeout=120, **popen):
    return subprocess.run([*invocation(name), *map(str, args)],
                          capture_output=True, text=True, timeout=timeout, cwd=ROOT, **popen)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    bag = tmp_path_factory.mktemp("recorded") / "run"
    result = script("run_stack.py", "--duration", "5", "--out", bag, "--quiet")
    assert result.returncode == 0, result.stderr
    return bag


def bag_messages(bag):
    with AnyReader([Path(bag)]) as reader:
        return [(c.topic, t, bytes(d)) for c, t, d in reader.messages()]


def by_topic(messages):
    topics = {}
    for topic, stamp, data in messages:
        topics.setdefault(topic, []).append((stamp, data))
    return topics


def stopped(process):
    """A process this test started does not outlive it, whatever the test's outcome."""
    if process.poll() is None:
        process.kill()
        process.communicate()


def replay_into(domain, bag):
    """replay_bag.py into the test's domain, handed the test's lock (replay_bag.py refuses
    a domain held by a lock it was not given): the domain stays held throughout, for the
    test's own participants before the replay starts and after it ends."""
    return script("replay_bag.py", bag, "--rate", "0", "--wait-subscribers", "1",
                  "--domain-id", domain.domain_id, **domain.handed_down())


def test_replay_delivers_every_message_in_order_with_identical_values(recorded, ros_domain):
    env = node_environment(ros_domain.domain_id)
    recorded_topics = by_topic(bag_messages(recorded))
    probe = subprocess.Popen([PYTHON, str(ROOT / "tests" / "capture_probe.py"), "60",
                              *(f"{t}:{ty}:{len(recorded_topics[t])}"
                                for t, ty in STEP_TOPICS.items())],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        replay = replay_into(ros_domain, recorded)
        assert replay.returncode == 0, replay.stderr
        out, err = probe.communicate(timeout=90)
    finally:
        stopped(probe)
    assert probe.returncode == 0, err
    received = json.loads(out)
    assert set(received) == set(recorded_topics)
    for topic, messages in recorded_topics.items():
        assert received[topic] == [data.hex() for _, data in messages], topic


def test_a_replay_re_recorded_gives_the_same_bag_data(recorded, tmp_path, ros_domain):
    env = node_environment(ros_domain.domain_id)
    copy = tmp_path / "rerecorded"
    recorder = subprocess.Popen(
        [PYTHON, "-m", "ato_nodes.nodes.recorder", "--ros-args", "-p",
         f"recorder.output:={copy}", "-p", "run.period:=0.05", "-p", "use_sim_time:=true"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=ROOT)
    try:
        # the replay exits once the recorder has acknowledged every message; on SIGINT
        # the recorder writes what it holds, then closes the bag
        replay = replay_into(ros_domain, recorded)
        assert replay.returncode == 0, replay.stderr
        recorder.send_signal(signal.SIGINT)
        recorder.communicate(timeout=30)
    finally:
        stopped(recorder)
    assert recorder.returncode == 0
    assert sorted(bag_messages(copy)) == sorted(bag_messages(recorded))


def test_analyze_reports_the_same_indices_as_score_bag(recorded, tmp_path):
    second = tmp_path / "second"
    assert script("run_stack.py", "--duration", "5", "--set", "adrc.mu1=8000", "--out", second,
                  "--quiet").returncode == 0
    result = script("analyze.py", recorded, second, "--out", tmp_path / "report")
    assert result.returncode == 0, result.stderr
    report = tmp_path / "report"
    for name in ("report.md", "report.html", "speed_time.png", "speed_distance.png",
                 "error.png", "command.png", "observer_1.png", "observer_2.png"):
        assert (report / name).stat().st_size > 0, name
    assert 'class="plotly-graph-div"' in (report / "report.html").read_text()
    indices = json.loads((report / "indices.json").read_text())
    for bag in (recorded, second):
        scored = json.loads(script("score_bag.py", bag, "--json").stdout)
        reported = {k: v for k, v in indices[bag.name].items() if k != "skipped"}
        assert reported == scored


def test_lone_mcap_and_renamed_topics_read_like_the_bag(recorded, tmp_path):
    (mcap,) = recorded.glob("*.mcap")
    lone = tmp_path / "lone.mcap"
    shutil.copy(mcap, lone)
    expected = json.loads(script("score_bag.py", recorded, "--json").stdout)
    lone_scores = json.loads(script("score_bag.py", lone, "--json").stdout)
    assert lone_scores["itae"] == expected["itae"]

    renamed = tmp_path / "renamed"
    write_bag(renamed, [(f"/other{topic}", STEP_TOPICS[topic], stamp, data)
                        for topic, stamp, data in bag_messages(recorded)])
    mapping = ["--map", "target_speed=/other/ato/target_speed",
               "--map", "state=/other/train/state",
               "--map", "command=/other/ato/traction_command"]
    result = script("analyze.py", renamed, "--out", tmp_path / "report", *mapping)
    assert result.returncode == 0, result.stderr
    indices = json.loads((tmp_path / "report" / "indices.json").read_text())["renamed"]
    assert indices["itae"] == expected["itae"]


def write_bag(path, messages):
    typestore = get_typestore(Stores.ROS2_JAZZY)
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connections = {}
        for topic, type_name, stamp, data in messages:
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, type_name, typestore=typestore)
            writer.write(connections[topic], stamp, data)


def test_a_bag_missing_some_topics_gives_what_it_can(recorded, tmp_path):
    partial = tmp_path / "partial"
    keep = {"/ato/target_speed", "/train/measured_speed"}
    write_bag(partial, [(t, STEP_TOPICS[t], s, d) for t, s, d in bag_messages(recorded)
                        if t in keep])
    result = script("analyze.py", partial, "--out", tmp_path / "report")
    assert result.returncode == 0, result.stderr
    assert "no state, speed_limit, command, controller_state, target_preview, position " \
        "topic" in result.stdout
    indices = json.loads((tmp_path / "report" / "indices.json").read_text())["partial"]
    assert indices["steps"] == 100 and "itae" in indices and "j_seed004" not in indices


@pytest.mark.parametrize("kind", ["truncated", "empty", "foreign", "text"])
def test_unusable_inputs_are_one_line_and_exit_2(recorded, tmp_path, kind):
    if kind == "truncated":
        (mcap,) = recorded.glob("*.mcap")
        target = tmp_path / "cut.mcap"
        target.write_bytes(mcap.read_bytes()[: mcap.stat().st_size // 2])
        problem = "cut.mcap"
    elif kind == "empty":
        target = tmp_path / "empty"
        target.mkdir()
        problem = "no rosbag2 metadata.yaml"
    elif kind == "foreign":
        target = tmp_path / "foreign"
        write_bag(target, [("/chatter", "std_msgs/msg/String", 1, bytes.fromhex(
            "00010000060000006869686921000000"))])
        problem = "needs a target speed and a speed topic; topics in the bag: /chatter"
    else:
        target = tmp_path / "notes.txt"
        target.write_text("not a bag\n")
        problem = "not a readable rosbag2 bag or MCAP file"
    for name in ("analyze.py", "score_bag.py"):
        args = [target, "--out", tmp_path / "report"] if name == "analyze.py" else [target]
        result = script(name, *args)
        assert result.returncode == 2, (name, result.stderr)
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: ") and problem in lines[0], lines


def test_an_exported_run_reads_back_as_numbers_into_pandas(recorded, tmp_path):
    import numpy as np
    import pandas

    from ato_nodes.bags.bagio import read_frame, read_run
    result = script("export.py", recorded, "--csv", tmp_path / "run.csv")
    assert result.returncode == 0, result.stderr
    table = pandas.read_csv(tmp_path / "run.csv")
    assert all(dtype.kind == "f" for dtype in table.dtypes)
    run = read_run(recorded)
    np.testing.assert_array_equal(table["speed"], run.series["speed"])  # digits kept
    np.testing.assert_array_equal(table["preview_0"], run.series["preview"][:, 0])
    assert script("export.py", recorded, "--parquet", tmp_path / "run.parquet").returncode == 0
    pandas.testing.assert_frame_equal(pandas.read_parquet(tmp_path / "run.parquet"),
                                      read_frame(recorded))
    again = script("export.py", recorded, "--csv", tmp_path / "run.csv")
    assert again.returncode == 2 and "exists already" in again.stderr
