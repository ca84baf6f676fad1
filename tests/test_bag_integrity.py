"""What a bag says it holds: gaps are never filled, a partial run says where it stopped,
a killed writer's file is repaired and a directory that is not a bag is named so
(ROS-free: bags written here with rosbags)."""

import json
import struct
import subprocess
import warnings
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from ato_nodes.bags.bagio import PARAMETERS_KEY, read_frame, read_parameters, read_run
from ato_nodes.bags.bagrepair import RepairError, needs_repair, repair
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.config.scenario import apply_overrides, load_scenario
from ato_nodes.bags.summary import bag_contents
from bagfile import write_run_bag
from commands import invocation

ROOT = Path(__file__).resolve().parents[1]
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
PERIOD_NS = 50_000_000


def float64(value: float) -> bytes:
    return b"\x00\x01\x00\x00" + struct.pack("<d", value)  # CDR little endian


def write(bag: Path, steps: int, gaps: dict[str, set[int]] | None = None, close: bool = True,
          flush_every: int = 0):
    gaps = gaps or {}
    writer = Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    topics = ("/ato/target_speed", "/train/measured_speed", "/ato/traction_command")
    connections = {t: writer.add_connection(t, "std_msgs/msg/Float64", typestore=TYPESTORE)
                   for t in topics}
    for k in range(steps):
        for topic, connection in connections.items():
            if k not in gaps.get(topic, ()):
                writer.write(connection, k * PERIOD_NS, float64(float(k)))
        if flush_every and k % flush_every == flush_every - 1:
            writer.storage.close_chunk()  # as the recorder does every second
            writer.storage.bio.flush()
    if close:
        writer.close()
    return writer


def test_a_step_missing_on_one_topic_is_left_out_and_said():
    bag = Path(pytest.importorskip("tempfile").mkdtemp()) / "gappy"
    write(bag, 100, {"/ato/traction_command": set(range(40, 60))})
    run = read_run(bag)
    assert len(run.series["t"]) == 80  # not 100 with 20 stale commands held over the gap
    np.testing.assert_array_equal(run.series["command"], run.series["target"])
    assert any("20 of 100 steps" in note and "/ato/traction_command" in note
               for note in run.notes)


def test_a_killed_writer_leaves_a_file_that_repair_makes_a_complete_bag(tmp_path):
    bag = tmp_path / "killed"
    writer = write(bag, 200, close=False, flush_every=20)
    (bag / "parameters.json").write_text(json.dumps({"run.period": 0.05}))
    writer.storage.bio.close()  # what a SIGKILL leaves: no summary, no metadata.yaml
    assert needs_repair(bag) and not (bag / "metadata.yaml").exists()
    report = repair(bag)
    assert report.repaired and set(report.messages.values()) == {200}
    assert not needs_repair(bag)
    with AnyReader([bag]) as reader:
        assert sum(1 for _ in reader.messages()) == 600
    (mcap_file,) = bag.glob("*.mcap")
    with mcap_file.open("rb") as handle:
        assert sum(1 for _ in make_reader(handle).iter_messages()) == 600
    assert read_parameters(bag) == {"run.period": 0.05}
    assert not repair(bag).repaired  # a complete bag is left as it is


def test_repair_keeps_what_was_flushed_before_a_cut_mid_chunk(tmp_path):
    bag = tmp_path / "cut"
    writer = write(bag, 130, close=False, flush_every=20)  # 10 steps still in memory
    writer.storage.bio.close()
    (mcap_file,) = bag.glob("*.mcap")
    data = mcap_file.read_bytes()
    mcap_file.write_bytes(data[:-7])  # and the last record (an index) torn
    report = repair(bag)
    assert set(report.messages.values()) == {120}  # every chunk closed before the cut
    assert len(read_run(bag).series["t"]) == min(report.messages.values())


def test_repair_script_is_one_line_and_exit_2_for_a_non_bag(tmp_path):
    result = subprocess.run([*invocation("repair_bag"),
                             str(tmp_path / "nothing")], capture_output=True, text=True)
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1
    (tmp_path / "empty.mcap").mkdir()
    bag = tmp_path / "junk"
    bag.mkdir()
    (bag / "junk.mcap").write_bytes(b"not an mcap file at all")
    result = subprocess.run([*invocation("repair_bag"), str(bag)],
                            capture_output=True, text=True)
    assert result.returncode == 2 and "no readable channel" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_a_bag_whose_kept_line_is_broken_is_one_line_and_exit_2(tmp_path):
    bag = tmp_path / "badline"
    writer = Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    writer.set_custom_data(PARAMETERS_KEY, json.dumps({"line.base64": "bm90IGEgbGluZQ==",
                                                       "line.file": "elsewhere.yaml"}))
    for topic in ("/ato/target_speed", "/train/measured_speed"):
        connection = writer.add_connection(topic, "std_msgs/msg/Float64", typestore=TYPESTORE)
        writer.write(connection, 0, float64(1.0))
    writer.close()
    result = subprocess.run([*invocation("score_bag"), str(bag)],
                            capture_output=True, text=True)
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1
    assert "line kept in the bag is unreadable" in result.stderr


def score_bag(bag: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([*invocation("score_bag"), str(bag),
                           *args], capture_output=True, text=True, timeout=120)


@pytest.fixture(scope="module")
def metro_run():
    values = load_scenario("seed004-metro")
    return simulate(values), values


@pytest.mark.slow
def test_an_interrupted_run_is_scored_as_partial_and_says_where_it_stopped(metro_run,
                                                                             tmp_path):
    series, values = metro_run
    launched = write_run_bag(tmp_path / "launched", series, values, steps=99)  # no summary
    run = read_run(launched)
    assert (run.recorded_steps, run.planned_steps) == (99, 2000)
    assert run.partial == "interrupted at step 99 of 2000"
    result = score_bag(launched)
    assert result.returncode == 0, result.stderr
    first = result.stdout.splitlines()[0]
    assert first == "partial: interrupted at step 99 of 2000; the indices cover the steps recorded"
    assert json.loads(score_bag(launched, "--json").stdout)["partial"] == \
        "interrupted at step 99 of 2000"
    stopped = write_run_bag(tmp_path / "stopped", series, values, steps=99, status="diverged")
    assert read_run(stopped).partial == "diverged at step 99 of 2000"
    whole = write_run_bag(tmp_path / "whole", series, values, status="completed")
    assert read_run(whole).partial is None
    assert "partial" not in score_bag(whole).stdout


def test_a_bag_with_no_message_says_so(metro_run, tmp_path):
    series, values = metro_run
    bag = write_run_bag(tmp_path / "empty", series, values, steps=0, status="interrupted")
    result = score_bag(bag)
    assert result.returncode == 2
    assert result.stderr == f"error: {bag}: 0 messages recorded (interrupted before its first " \
                            "step); nothing to score\n"


def test_a_bag_stopped_before_its_first_complete_step_says_so(metro_run, tmp_path):
    """The plant's step 0 recorded, nothing from the profile or the controller yet."""
    series, values = metro_run
    bag = write_run_bag(tmp_path / "first", series, values, steps=1, silent=(
        "target_speed", "command", "controller_state"))
    result = score_bag(bag)
    assert result.returncode == 2 and len(result.stderr.splitlines()) == 1
    assert "no complete step: /ato/target_speed recorded no message" in result.stderr
    contents = bag_contents(bag)  # what run_stack.py's summary.json then says
    assert contents["scored_steps"] == 0 and "bag_error" not in contents
    assert "/ato/target_speed" in contents["notes"][0]


@pytest.mark.slow
def test_an_open_track_run_reads_into_a_frame_without_an_infinite_column(tmp_path):
    values = apply_overrides(load_scenario("seed000-step"), ["run.duration=2"])
    series = simulate(values)
    assert np.all(np.isinf(series["speed_limit"]))  # no line: no limit anywhere
    frame = read_frame(write_run_bag(tmp_path / "step", series, values))
    assert "speed_limit" not in frame.columns and "target" in frame.columns
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # describe() warned twice on the infinite column
        frame.describe()


def test_a_line_run_keeps_its_speed_limit_column(metro_run, tmp_path):
    series, values = metro_run
    frame = read_frame(write_run_bag(tmp_path / "metro", series, values, steps=20))
    np.testing.assert_array_equal(frame["speed_limit"], series["speed_limit"][:20])


@pytest.mark.parametrize("holds, words", [
    ("nothing", ["not a bag: an empty directory"]),
    ("metadata", ["not a bag: no .mcap file, and its metadata.yaml is not rosbag2 metadata"]),
    ("/proc", ["/proc: not a bag: no .mcap file and no metadata.yaml"]),
])
def test_repair_says_what_a_directory_that_is_not_a_bag_holds(tmp_path, holds, words):
    directory = Path(holds) if holds.startswith("/") else tmp_path
    if holds == "metadata":
        (tmp_path / "metadata.yaml").write_text("hello: [1, 2]\n")
    result = subprocess.run([*invocation("repair_bag"),
                             str(directory)], capture_output=True, text=True)
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1
    assert "nothing to repair" not in result.stdout + result.stderr
    for word in words:
        assert word in result.stderr, result.stderr


def test_repair_names_a_sqlite_bag_it_does_not_repair(tmp_path):
    (tmp_path / "metadata.yaml").write_text(
        "rosbag2_bagfile_information:\n  version: 9\n  storage_identifier: sqlite3\n")
    with pytest.raises(RepairError, match=r"rosbag2 bag in sqlite3 storage, and only MCAP "):
        repair(tmp_path)
