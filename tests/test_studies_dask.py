"""The study scripts on Dask (--cluster, as tune.py's): the same samples give the same
rows as the local pool, on a LocalCluster and on a scheduler and workers started as
separate processes; a worker killed mid-study changes nothing (its samples run again);
a scheduler that dies, or a Ctrl-C, ends the study in one line with its finished
samples kept for --resume; compare_scenarios.py's stack runs go on the workers."""

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("distributed")
import psutil  # noqa: E402  (a dependency of distributed)

from commands import invocation, script  # noqa: E402
from progress_lines import read_progress_until  # noqa: E402
from dask_cluster import scheduler_and_workers  # noqa: E402

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
STUDY = ["seed004-metro-ato", "--set", "run.duration=40"]


def study(out: Path, samples: int, *extra) -> str:
    """The study's robustness.json, run to its end."""
    result = script("robustness.py", *STUDY, "--samples", samples, "--out", out, *extra,
                    timeout=600)
    assert result.returncode == 0, result.stderr
    return (out / "robustness.json").read_text()


def start_study(out: Path, samples: int, *extra) -> subprocess.Popen:
    return subprocess.Popen([*invocation("robustness.py"), *STUDY, "--samples", str(samples),
                             "--out", str(out), *extra], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)


def wait_for_rows(process: subprocess.Popen, out: Path, count: int) -> None:
    """Until samples.csv has `count` rows, reading the progress line the study prints
    after each tenth of its samples (no fixed sleep); it must still be running then."""
    path = out / "samples.csv"
    read_progress_until(process, lambda: path.exists() and len(path.read_text().splitlines())
                        - 1 >= count)


def messages(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if not line.startswith("samples ")]


def test_a_local_cluster_gives_the_pool_s_rows(tmp_path):
    pool = study(tmp_path / "pool", 20, "--workers", "2")
    assert study(tmp_path / "cluster", 20, "--cluster", "local:2") == pool
    rows = [sorted((tmp_path / name / "samples.csv").read_text().splitlines())
            for name in ("pool", "cluster")]
    assert rows[0] == rows[1] and len(rows[0]) == 21


def test_a_worker_killed_mid_study_changes_nothing(tmp_path):
    reference = study(tmp_path / "pool", 400, "--workers", "2")
    out = tmp_path / "cluster"
    with scheduler_and_workers(tmp_path) as (address, _, workers):
        process = start_study(out, 400, "--cluster", address)
        wait_for_rows(process, out, 40)
        workers[0].kill()  # mid-study: its samples go to the other worker
        _, stderr = process.communicate(timeout=600)
    assert process.returncode == 0, stderr
    assert (out / "robustness.json").read_text() == reference


def test_a_scheduler_that_dies_mid_study_is_one_line_and_the_study_resumes(tmp_path):
    reference = study(tmp_path / "pool", 400, "--workers", "2")
    out = tmp_path / "cluster"
    with scheduler_and_workers(tmp_path) as (address, scheduler, _):
        process = start_study(out, 400, "--cluster", address)
        wait_for_rows(process, out, 40)
        scheduler.kill()
        _, stderr = process.communicate(timeout=300)
    assert process.returncode == 1, stderr
    assert messages(stderr) == [f"error: the Dask scheduler {address} stopped answering "
                                f"mid-study; every finished sample is in "
                                f"{out / 'samples.csv'}; continue with --resume"], stderr
    assert not (out / "robustness.json").exists()
    assert study(out, 400, "--workers", "2", "--resume") == reference


def test_ctrl_c_of_a_local_cluster_study_is_one_line_exit_130_and_no_process_left(tmp_path):
    out = tmp_path / "cluster"
    process = start_study(out, 2000, "--cluster", "local:2")
    try:
        wait_for_rows(process, out, 200)
        started = psutil.Process(process.pid).children(recursive=True)
        assert len(started) >= 2  # the cluster's worker processes, at least
        os.killpg(process.pid, signal.SIGINT)  # as a terminal's Ctrl-C: its workers too
        _, stderr = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert process.returncode == 130, stderr
    assert messages(stderr) == [f"interrupted; every finished sample is in "
                                f"{out / 'samples.csv'}; continue with --resume"], stderr
    _, left = psutil.wait_procs(started, timeout=60)
    assert left == []
    assert 200 <= len((out / "samples.csv").read_text().splitlines()) - 1 < 2000


def test_compare_scenarios_runs_its_stack_runs_on_a_cluster_as_here(tmp_path):
    runs = ["seed004-metro-ato:run.duration=15", "hsr-neutral-ato:run.duration=10"]
    here = script("compare_scenarios.py", *runs, "--out", tmp_path / "here")
    assert here.returncode == 0, here.stderr
    cluster = script("compare_scenarios.py", *runs, "--cluster", "local:2",
                     "--out", tmp_path / "cluster")
    assert cluster.returncode == 0, cluster.stderr
    report = json.loads((tmp_path / "cluster" / "comparison.json").read_text())
    assert report == json.loads((tmp_path / "here" / "comparison.json").read_text())
    assert list(report) == runs and all(report[text]["bit_identical"] for text in runs)
