"""Runs on TTOBench's files: line.file takes a track file and plant.train a train file, by
path (relative to the scenario, else msg_config/), in-process and in the nodes alike; a
TTOBench train keeps its resistance in kN under a load (plant.davis_absolute), and its
maximum speed caps the line's limits for the plan and the scorer (plant.max_running_speed);
a bag's copy of a track re-reads as the same line."""

import base64
import shutil
import subprocess
import sys

import numpy as np
import pytest

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.base.paths import config_dir
from ato_nodes.core.base.units import KMH
from ato_nodes.core.config.context import RunContext, ato_train
from ato_nodes.core.config.scenario import load_scenario, prepare
from ato_nodes.core.config.schema import NodeValues
from ato_nodes.core.run.scoring import LINE_BASE64, encode_line, run_line
from ato_nodes.core.run.stages import PlantStage
from ato_nodes.core.train.lines import line_of
from ato_nodes.launcher.launch import node_environment
from commands import ROOT, one_line_exit_2, script

DATA = config_dir() / "ttobench"
TRAIN = "ttobench/trains/CN_Beijing_Subway.json"
TRACK = "ttobench/tracks/CN_Songjiazhuang_Yizhuang.json"
ON_TTOBENCH = [f"plant.train={TRAIN}", f"line.file={TRACK}"]


def kilonewtons(train, speed: float) -> float:
    """The train's basic resistance at `speed` (m/s) in kN: w0 (N/kN) times its weight."""
    return train.resistance(speed) * train.mass * train.gravity / 1000.0


def test_a_loaded_ttobench_train_keeps_its_resistance_in_kilonewtons():
    """CN_Beijing_Subway: r0 = 3.9476 kN, r1 = 0, r2 = 0.0022294 kN/(km/h)^2; at 80 km/h
    3.9476 + 0.0022294 x 80^2 = 3.9476 + 14.26816 = 18.21576 kN, whatever the load: the
    real train at plant.mass_factor 1.3 and the ATO's weighed train at a reading of 1.3
    alike. The project's own trains (davis_absolute false) keep N/kN: 1.3 times the kN."""
    values = prepare("seed004-metro", {**dict(item.split("=") for item in ON_TTOBENCH),
                                       "plant.mass_factor": 1.3, "train.mass_reading": 1.3})
    assert values["plant.davis_absolute"] is True
    real = PlantStage(NodeValues("plant", values)).params
    weighed = ato_train(NodeValues("profile", values))
    for train in (real, weighed):
        assert train.mass == pytest.approx(1.3 * 278.0)
        assert kilonewtons(train, 80 * KMH) == pytest.approx(18.21576, rel=1e-12)
    metro = prepare("seed004-metro", {"plant.mass_factor": 1.3})
    nominal = PlantStage(NodeValues("plant", {**metro, "plant.mass_factor": 1.0})).params
    assert kilonewtons(PlantStage(NodeValues("plant", metro)).params, 20.0) == pytest.approx(
        1.3 * kilonewtons(nominal, 20.0), rel=1e-12)


def test_the_train_file_and_the_track_file_are_read_by_path(tmp_path):
    """Relative to the scenario file, else msg_config/; plant.train keeps the resolved
    path; the line is the track's, every stop a station."""
    shutil.copy(DATA / "trains" / "CN_Beijing_Subway.json", tmp_path / "beijing.json")
    scenario = tmp_path / "run.yaml"
    scenario.write_text(f"base: seed004-metro\n/**:\n  ros__parameters:\n"
                        f"    plant.train: beijing.json\n    line.file: {TRACK}\n"
                        "    line.planned_run_time: 1500.0\n")
    values = load_scenario(str(scenario))
    assert values["plant.train"] == str(tmp_path / "beijing.json")
    assert values["plant.mass"] == 278.0 and values["plant.max_running_speed"] == 80 * KMH
    assert values["line.file"] == str((DATA / "tracks" / TRACK.split("/")[-1]).resolve())
    line = line_of(values)
    assert len(line.stations) == 14 and line.length == 22728.0


def test_the_trains_maximum_speed_caps_the_line_for_the_plan_and_the_scorer():
    """The track's 84 km/h limits are above the Beijing train's 80 km/h: every reader of
    the run's line (the plan, the scorer's limits, a bag's copy) sees 80."""
    values = prepare("seed004-metro", [*ON_TTOBENCH, "line.planned_run_time=1500"])
    line = line_of(values)
    assert max(section.value for section in line.speed_limits) == pytest.approx(80 * KMH)
    assert min(section.value for section in line.speed_limits) == pytest.approx(50 * KMH)
    plan = RunContext(NodeValues("profile", values)).plan
    positions = np.linspace(0.0, line.length, 2000)
    assert max(plan.speed(0.0, position) for position in positions) <= 80 * KMH
    kept = {**values, LINE_BASE64: encode_line((config_dir() / TRACK).read_text())}
    assert run_line(kept) == line
    assert run_line({**kept, "plant.max_running_speed": 0.0}) != line


def test_a_bags_copy_of_a_track_reads_by_the_name_it_kept():
    text = (config_dir() / TRACK).read_text()
    kept = {"line.file": "/elsewhere/CN_Songjiazhuang_Yizhuang.json",
            LINE_BASE64: base64.b64encode(text.encode()).decode()}
    assert len(run_line(kept).stations) == 14
    with pytest.raises(ScenarioError, match="elsewhere/bad.json: missing field 'stops'"):
        run_line({**kept, "line.file": "/elsewhere/bad.json",
                  LINE_BASE64: encode_line('{"metadata": {}}')})


@pytest.mark.parametrize("train, words", [
    ("missing.json", ["cannot read TTOBench train", "missing.json"]),
    ("bad.json", ["bad.json", "max speed"]),
])
def test_a_missing_or_bad_train_file_is_one_line_and_exit_2(tmp_path, train, words):
    bad = (DATA / "trains" / "CN_Beijing_Subway.json").read_text().replace(
        '"max speed"', '"max speeds"')
    (tmp_path / "bad.json").write_text(bad)
    with pytest.raises(ScenarioError) as refused:
        prepare("seed004-metro", [f"plant.train={tmp_path / train}"])
    assert all(word in str(refused.value) for word in words)
    one_line_exit_2(script("run_stack", "--scenario", "seed004-metro", "--set",
                           f"plant.train={tmp_path / train}", "--out", tmp_path / "bag"),
                    *words)
    assert not (tmp_path / "bag").exists()


@pytest.mark.integration
def test_a_node_refuses_a_bad_train_file_as_in_process(tmp_path, ros_domain):
    """A node started from a scenario file naming a train file it cannot read: the same
    one line (exit 2) as prepare() gives."""
    scenario = tmp_path / "run.yaml"
    scenario.write_text("/**:\n  ros__parameters:\n    plant.train: missing.json\n")
    result = subprocess.run([sys.executable, "-m", "ato_nodes.nodes.plant", "--ros-args",
                             "--params-file", str(scenario)], capture_output=True, text=True,
                            timeout=60, cwd=ROOT, env=node_environment(ros_domain.domain_id))
    assert result.returncode == 2 and "Traceback" not in result.stderr
    (line,) = [line for line in result.stderr.splitlines() if "INFO" not in line]
    assert line.startswith("plant: error: cannot read TTOBench train ")
    assert line.endswith("missing.json: No such file or directory")


def test_line_end_makes_a_tracks_first_interstation_for_every_reader():
    """seed004-yizhuang: the Yizhuang track ended at its second stop, 2,631 m: two
    stations, every section cut there; a bag's copy of the whole track with the run's
    parameters reads the same line; an end beyond the track is one line."""
    values = load_scenario("seed004-yizhuang")
    line = line_of(values)
    assert line.length == 2631.0 and [s.position for s in line.stations] == [0.0, 2631.0]
    assert all(s.end <= 2631.0 for kind in (line.gradients, line.speed_limits) for s in kind)
    assert line.speed_limits[-1].end == line.gradients[-1].end == 2631.0
    assert line.planned_run_time == 180.0
    kept = {**values, LINE_BASE64: encode_line((config_dir() / TRACK).read_text())}
    assert run_line(kept) == line
    with pytest.raises(ScenarioError, match="line.end 30000 m is beyond the end of line "
                       "'CN_Songjiazhuang_Yizhuang' \\(22728 m\\)"):
        prepare("seed004-yizhuang", ["line.end=30000"])


def test_a_timetable_names_a_track_and_a_train_file_relative_to_itself():
    """yizhuang-line's timetable: `line:` the track, `train:` the train file, each by a
    path relative to the timetable; the run's plant.train (the same file, absolute) and
    its capped line are the timetable's, so the journey plans."""
    from ato_nodes.core.targets.timetable import load_timetable
    values = load_scenario("yizhuang-line")
    timetable = load_timetable(values["profile.journey.timetable"])
    assert timetable.train == values["plant.train"] == str(
        (DATA / "trains" / "CN_Beijing_Subway.json").resolve())
    assert timetable.line == line_of({**values, "plant.max_running_speed": 0.0})
    assert len(timetable.sections) == 13
    plan = RunContext(NodeValues("profile", values)).plan
    assert plan.journey_end == 22728.0 - values["profile.journey.berth"]


def test_a_timetables_train_is_the_files_contents_at_any_path(tmp_path):
    """yizhuang-line's timetable names the repository's Beijing train: a copy elsewhere
    (under any name) is the same train and runs with the same values; a copy of other
    contents (a tonne heavier) is refused in one line, in-process and by run_stack.py."""
    shutil.copy(DATA / "trains" / "CN_Beijing_Subway.json", tmp_path / "beijing.json")
    values = prepare("yizhuang-line", [f"plant.train={tmp_path / 'beijing.json'}"])
    assert values == {**prepare("yizhuang-line"), "plant.train": str(tmp_path / "beijing.json")}
    heavier = (tmp_path / "beijing.json").read_text().replace('"value": 278000',
                                                              '"value": 279000')
    (tmp_path / "heavier.json").write_text(heavier)
    words = ["is planned for train", "CN_Beijing_Subway.json", "heavier.json"]
    with pytest.raises(ScenarioError) as refused:
        prepare("yizhuang-line", [f"plant.train={tmp_path / 'heavier.json'}"])
    assert all(word in str(refused.value) for word in words)
    one_line_exit_2(script("run_stack", "--scenario", "yizhuang-line", "--set",
                           f"plant.train={tmp_path / 'heavier.json'}", "--out",
                           tmp_path / "bag"), *words)
    assert not (tmp_path / "bag").exists()


def test_a_bag_recorded_in_another_checkout_runs_again_bit_for_bit(tmp_path):
    """A yizhuang-line run whose plant.train is another checkout's copy of the train:
    its bag re-runs here (its timetable's copy names the train relative to msg_config/,
    this checkout's file) to the bits of a run on this checkout's file, and still with
    that checkout gone: the bag keeps the train file."""
    from bagfile import write_run_bag

    from ato_nodes.bags.bagio import read_run, resimulate
    from ato_nodes.core.config.scenario import apply_overrides
    from ato_nodes.core.run.loop import simulate
    from ato_nodes.core.run.scoring import kept_files
    elsewhere = tmp_path / "checkout" / "msg_config" / TRAIN
    elsewhere.parent.mkdir(parents=True)
    shutil.copy(DATA / "trains" / "CN_Beijing_Subway.json", elsewhere)
    here = apply_overrides(load_scenario("yizhuang-line"), ["run.duration=120"])
    values = apply_overrides(here, {"plant.train": str(elsewhere)})
    bag = write_run_bag(tmp_path / "bag", simulate(values),
                        {**values, **kept_files(values)}, status="completed")
    series, differ = resimulate(read_run(bag))
    assert differ == []
    assert all(np.array_equal(series[name], ours, equal_nan=True)  # the located series' NaN
               for name, ours in simulate(here).items())
    shutil.rmtree(tmp_path / "checkout")
    assert resimulate(read_run(bag))[1] == []


@pytest.mark.parametrize("scenario", ["seed004-yizhuang", "yizhuang-line"])
def test_a_bag_of_a_run_on_ttobench_files_runs_again_bit_for_bit(scenario, tmp_path):
    """From the bag alone: its copies of the track (re-read as JSON by the name it kept)
    and of the timetable (whose train file, named relative to msg_config/, is the run's)."""
    from bagfile import write_run_bag

    from ato_nodes.bags.bagio import read_run, resimulate
    from ato_nodes.core.config.scenario import apply_overrides
    from ato_nodes.core.run.loop import simulate
    from ato_nodes.core.run.scoring import kept_files
    values = apply_overrides(load_scenario(scenario), ["run.duration=120"])
    bag = write_run_bag(tmp_path / "bag", simulate(values),
                        {**values, **kept_files(values)}, status="completed")
    assert resimulate(read_run(bag))[1] == []
