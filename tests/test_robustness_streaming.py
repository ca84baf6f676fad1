"""robustness.py as a streaming, resumable study: each sample drawn from the seed and its
number alone, its row in samples.csv as it finishes (a kill or a Ctrl-C keeps every
finished one), --resume running only the rest to the uninterrupted study's result, and
refusing a study whose settings changed."""

import json
import os
import signal
import subprocess
from pathlib import Path

import psutil
import pytest

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import load_scenario
from ato_nodes.studies.robustness import draw_train, study_columns
from ato_nodes.studies.samples import SampleFile, write_json_with_rows
from commands import invocation, one_line_exit_2, script
from progress_lines import read_progress_until

ROOT = Path(__file__).resolve().parents[1]
RANGES = {"plant.mass_factor": (0.85, 1.3), "plant.resistance_factor": (0.8, 1.2),
          "plant.lag_factor": (0.7, 1.3)}
STUDY = ["seed004-metro-ato", "--set", "run.duration=40", "--workers", "2"]


def test_a_sample_s_train_depends_on_the_seed_and_its_number_alone():
    first = [draw_train(RANGES, 7, number) for number in range(5)]
    assert [draw_train(RANGES, 7, number) for number in reversed(range(5))] == first[::-1]
    assert draw_train(RANGES, 8, 3) != first[3] and len({d["plant.noise_seed"]
                                                        for d in first}) == 5
    for draw in first:
        assert all(low <= draw[name] <= high for name, (low, high) in RANGES.items())


def rows_file(path: Path) -> SampleFile:
    return SampleFile(path, {"x": float, "seed": int})


def test_the_samples_file_gives_back_its_rows_bit_for_bit_in_sample_order(tmp_path):
    written = rows_file(tmp_path / "s.csv")
    written.start(resume=False)
    values = [0.1 + 0.2, float("nan"), 1e-300 / 3]
    for number in (2, 0, 1):  # as they finish
        written.append({"sample": number, "x": values[number], "seed": 2**31 - 1 - number})
    written.append({"sample": 3, "seed": 5})  # a sample without x
    written.close()
    read = rows_file(tmp_path / "s.csv")
    read.read(samples=4)
    assert read.done == {0, 1, 2, 3}
    rows = list(read.rows(*read.table()))
    assert [row["sample"] for row in rows] == [0, 1, 2, 3] and "x" not in rows[3]
    assert repr([row.get("x") for row in rows[:3]]) == repr(values)
    assert [row["seed"] for row in rows] == [2**31 - 1, 2**31 - 2, 2**31 - 3, 5]
    assert all(type(row["seed"]) is int for row in rows)


def test_a_row_cut_short_by_a_kill_runs_again_and_a_bad_row_is_refused(tmp_path, capsys):
    path = tmp_path / "s.csv"
    written = rows_file(path)
    written.start(resume=False)
    written.append({"sample": 0, "x": 1.5, "seed": 1})
    written.close()
    whole = path.read_text()
    path.write_text(whole + "1,2.5")  # killed while writing sample 1's row
    resumed = rows_file(path)
    resumed.read(samples=2)
    assert resumed.done == {0} and "line 3 is incomplete" in capsys.readouterr().err
    assert path.read_text() == whole + "1,2.5"  # reading changes nothing
    resumed.start(resume=True)
    resumed.append({"sample": 1, "x": 2.5, "seed": 2})
    resumed.close()
    assert path.read_text() == whole + "1,2.5,2\n"
    for bad in (whole + "1,2.5\n1,2.5,2\n", whole + "0,1.5,1\n", whole + "7,1.5,1\n"):
        path.write_text(bad)
        with pytest.raises(ScenarioError, match="line 3"):
            rows_file(path).read(samples=2)


def test_the_report_s_rows_are_strict_json_written_as_they_come(tmp_path):
    path = tmp_path / "r.json"
    write_json_with_rows(path, {"a": [1, 2], "b": float("inf")}, "samples",
                         iter([{"x": 1.0}, {"x": float("nan")}]))
    assert json.loads(path.read_text()) == {"a": [1, 2], "b": None,
                                            "samples": [{"x": 1.0}, {"x": None}]}
    assert not path.with_name("r.json.tmp").exists()


def study(out: Path, *extra, samples: int = 30) -> subprocess.CompletedProcess:
    return script("robustness.py", *STUDY, "--samples", samples, "--out", out, *extra)


def start_study(out: Path, samples: int) -> subprocess.Popen:
    return subprocess.Popen([*invocation("robustness.py"), *STUDY, "--samples", str(samples),
                             "--out", str(out)], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)


def rows(out: Path) -> int:
    path = out / "samples.csv"
    return len(path.read_text().splitlines()) - 1 if path.exists() else 0


def stop_after(process: subprocess.Popen, out: Path, count: int, number: int
               ) -> tuple[str, list]:
    """Signal `number` to the study once its samples.csv has `count` rows (it prints a
    progress line after the row of each tenth of its samples: read, no fixed sleep); it
    must still be running then: SIGINT to its process group, as a terminal's Ctrl-C
    (its workers get it too), SIGKILL to its process alone. (Its stderr, the worker
    processes it had.)"""
    lines = read_progress_until(process, lambda: rows(out) >= count, 120)
    workers = psutil.Process(process.pid).children(recursive=True)
    if number == signal.SIGINT:
        os.killpg(process.pid, number)
    else:
        process.send_signal(number)
    _, rest = process.communicate(timeout=120)
    return "".join(lines) + rest, workers


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    """The 300-sample study's robustness.json, run in one go."""
    out = tmp_path_factory.mktemp("whole") / "r"
    result = study(out, samples=300)
    assert result.returncode == 0, result.stderr
    return (out / "robustness.json").read_text()


def messages(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if not line.startswith("samples ")]


@pytest.mark.slow
@pytest.mark.parametrize("number, status", [(signal.SIGKILL, -9), (signal.SIGINT, 130)])
def test_a_stopped_study_keeps_every_finished_sample_and_resumes_to_the_same_result(
        tmp_path, uninterrupted, number, status):
    out = tmp_path / "r"
    process = start_study(out, 300)
    stderr, workers = stop_after(process, out, 30, number)
    assert process.returncode == status, stderr
    if number == signal.SIGINT:
        assert messages(stderr) == [f"interrupted; every finished sample is in "
                                    f"{out / 'samples.csv'}; continue with --resume"]
    kept = rows(out)
    assert 30 <= kept < 300 and not (out / "robustness.json").exists()
    _, left = psutil.wait_procs(workers, timeout=60)  # none outlives the study: none
    assert left == []  # holds OUT's lock
    resumed = study(out, "--resume", samples=300)
    assert resumed.returncode == 0, resumed.stderr
    assert (out / "robustness.json").read_text() == uninterrupted
    report = json.loads(uninterrupted)
    assert [s["sample"] for s in report["samples"]] == list(range(300))
    assert set(report["samples"][0]) <= {"sample", *study_columns(load_scenario(STUDY[0]))}


@pytest.mark.slow
@pytest.mark.parametrize("changed", [
    [*STUDY, "--samples", "3", "--seed", "2"], [*STUDY, "--samples", "4"],
    [*STUDY, "--samples", "3", "--mass", "0.9:1.2"],
    [*STUDY, "--samples", "3", "--set", "profile.ato.start_speed=0.4"],
    ["seed004-metro", *STUDY[1:], "--samples", "3"]])
def test_a_resume_with_other_settings_is_refused_and_changes_nothing(tmp_path, changed):
    out = tmp_path / "r"
    assert study(out, samples=3).returncode == 0
    before = {path.name: path.read_bytes() for path in out.iterdir()}
    result = script("robustness.py", *changed, "--out", out, "--resume")
    one_line_exit_2(result, f"{out} holds a study with other settings")
    assert {path.name: path.read_bytes() for path in out.iterdir()} == before


def test_an_out_without_a_study_is_not_resumed_and_an_existing_one_not_overwritten(tmp_path):
    (tmp_path / "r").mkdir()
    (tmp_path / "r" / "notes.txt").write_text("mine")
    one_line_exit_2(study(tmp_path / "r", "--resume"), "holds no study to resume")
    one_line_exit_2(study(tmp_path / "r"), "exists already")
    assert [path.name for path in (tmp_path / "r").iterdir()] == ["notes.txt"]


@pytest.mark.parametrize("spec, words", [
    ("local:0", "needs a positive worker count"), ("local:x", "needs a positive worker count"),
    ("udp://127.0.0.1:1", "expects local:N or tcp://HOST:PORT")])
def test_a_bad_cluster_is_one_line_before_anything_is_written(tmp_path, spec, words):
    one_line_exit_2(study(tmp_path / "r", "--cluster", spec), words)
    assert not (tmp_path / "r").exists()


@pytest.mark.slow
def test_a_cluster_that_does_not_answer_is_one_line_before_anything_is_written(tmp_path):
    one_line_exit_2(study(tmp_path / "r", "--cluster", "tcp://127.0.0.1:9"),
                    "--cluster tcp://127.0.0.1:9: no scheduler answers")
    assert not (tmp_path / "r").exists()

