"""What a bag says it holds: gaps are never filled, a killed writer's file is repaired
(ROS-free: bags written here with rosbags)."""

import json
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from ato_nodes.bagio import PARAMETERS_KEY, read_parameters, read_run
from ato_nodes.bagrepair import needs_repair, repair

ROOT = Path(__file__).resolve().parents[1]
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
PERIOD_NS = 50_000_000


def float64(value: float) -> bytes:
    return b"\x00\x01\x00\x00" + struct.pack("<d", value)  # CDR little endian


def write(bag: Path, steps: int, gaps: dict[str, set[int]] = {}, close: bool = True,
          flush_every: int = 0):
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
    result = subprocess.run([sys.executable, str(ROOT / "scripts" / "repair_bag.py"),
                             str(tmp_path / "nothing")], capture_output=True, text=True)
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1
    (tmp_path / "empty.mcap").mkdir()
    bag = tmp_path / "junk"
    bag.mkdir()
    (bag / "junk.mcap").write_bytes(b"not an mcap file at all")
    result = subprocess.run([sys.executable, str(ROOT / "scripts" / "repair_bag.py"), str(bag)],
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
    result = subprocess.run([sys.executable, str(ROOT / "scripts" / "score_bag.py"), str(bag)],
                            capture_output=True, text=True)
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1
    assert "line kept in the bag is unreadable" in result.stderr
