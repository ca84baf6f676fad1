"""The Dask backend of the tuner: the same candidates give the same fitness as the local
worker processes, on a LocalCluster and on a scheduler and workers started as separate
processes with the README's commands, and a worker killed mid-tuning changes nothing;
Ctrl-C and a scheduler that dies end the tuning in one line, the log kept for --resume."""

import contextlib
import json
import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import NamedTuple

import pytest

pytest.importorskip("distributed")
import psutil  # noqa: E402  (a dependency of distributed)

from ato_nodes.core.base.kernels import COMPILING  # noqa: E402
from commands import invocation
from progress_lines import read_progress_until
from dask_cluster import scheduler_and_workers

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
TUNING = ["--algorithm", "pso", "--scenario", "seed000", "--set", "run.duration=150",
          "--in-process", "--params", "adrc.mu1=600:60000,adrc.mu2=550:55000",
          "--population", "6", "--quiet"]


def tune(out: Path, *extra: str, evaluations: int = 36) -> dict:
    result = subprocess.run([*invocation("tune"), *TUNING,
                             "--evaluations", str(evaluations), "--out", str(out), *extra],
                            capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert result.returncode == 0, result.stderr
    return outcome(out)


def outcome(out: Path) -> dict:
    records = [json.loads(line) for line in (out / "evaluations.jsonl").read_text().splitlines()]
    summary = json.loads((out / "summary.json").read_text())
    return {"best": (summary["best_fitness"], summary["best_params"]),
            "evaluations": sorted((r["index"], json.dumps(r["params"]), r["fitness"], r["status"])
                                  for r in records),
            "history": (out / "history.csv").read_text().splitlines()}


def best_and_evaluations(result: dict) -> tuple:
    """What must not depend on the backend (history's mean column averages lower bounds
    of pruned candidates, the same ones either way: compared too)."""
    return result["best"], result["evaluations"], result["history"]


def test_a_local_cluster_gives_the_local_backends_result(tmp_path):
    local = tune(tmp_path / "local", "--workers", "2")
    cluster = tune(tmp_path / "cluster", "--cluster", "local:2")
    assert best_and_evaluations(local) == best_and_evaluations(cluster)


class ClusterTuning(NamedTuple):
    address: str
    scheduler: subprocess.Popen
    workers: list
    tuner: subprocess.Popen


@contextlib.contextmanager
def cluster_tuning(directory: Path, out: Path):
    """A scheduler (on loopback) and two workers as separate processes, as the README
    starts them, and a 60-evaluation tuning on them into `out`, 12 evaluations in;
    every one of these processes still running at the end is killed."""
    with scheduler_and_workers(directory) as (address, scheduler, workers):
        tuning = start_tuning(out, "--cluster", address)
        try:
            wait_for_evaluations(tuning, out, 12)
            yield ClusterTuning(address, scheduler, workers, tuning)
        finally:
            if tuning.poll() is None:
                tuning.kill()
                tuning.wait()


def start_tuning(out: Path, *extra: str, evaluations: int = 60) -> subprocess.Popen:
    """tune.py with its progress lines (one per finished evaluation) on stderr."""
    return subprocess.Popen([*invocation("tune"),
                             *[a for a in TUNING if a != "--quiet"], "--evaluations",
                             str(evaluations), "--out", str(out), *extra], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def wait_for_evaluations(tuner: subprocess.Popen, out: Path, count: int) -> None:
    """Until evaluations.jsonl has `count` lines, reading the progress line the tuner
    prints after each one it logs (no fixed sleep); it must still be running then."""
    log = out / "evaluations.jsonl"
    read_progress_until(tuner, lambda: log.exists() and len(log.read_text().splitlines())
                        >= count)


def messages(stderr: str) -> list[str]:
    """stderr without the progress lines (and the note of a compilation)."""
    return [line for line in stderr.splitlines()
            if not line.startswith(("iteration ", COMPILING))]


def test_separate_scheduler_and_workers_survive_a_killed_worker(tmp_path):
    reference = tune(tmp_path / "local", "--workers", "2", evaluations=60)
    out = tmp_path / "cluster"
    with cluster_tuning(tmp_path, out) as cluster:
        os.kill(cluster.workers[0].pid, signal.SIGKILL)  # mid-tuning: its task goes elsewhere
        _, stderr = cluster.tuner.communicate(timeout=600)
    assert cluster.tuner.returncode == 0, stderr
    assert len((out / "evaluations.jsonl").read_text().splitlines()) == 60
    assert best_and_evaluations(outcome(out)) == best_and_evaluations(reference)


def test_ctrl_c_of_a_local_cluster_tuning_is_one_line_exit_130_and_no_process_left(tmp_path):
    out = tmp_path / "cluster"
    tuner = start_tuning(out, "--cluster", "local:2", evaluations=600)
    try:
        wait_for_evaluations(tuner, out, 6)
        started = psutil.Process(tuner.pid).children(recursive=True)
        assert len(started) >= 2  # the cluster's worker processes, at least
        tuner.send_signal(signal.SIGINT)
        _, stderr = tuner.communicate(timeout=120)
    finally:
        if tuner.poll() is None:
            tuner.kill()
            tuner.wait()
    log = out / "evaluations.jsonl"
    assert tuner.returncode == 130, stderr
    assert messages(stderr) == [f"interrupted; every finished evaluation is in {log}; "
                                "continue with --resume"]
    _, left = psutil.wait_procs(started, timeout=60)
    assert left == []
    assert 6 <= len(log.read_text().splitlines()) < 600


def test_a_scheduler_that_dies_mid_tuning_is_one_line_and_the_log_resumes(tmp_path):
    reference = tune(tmp_path / "local", "--workers", "2", evaluations=60)
    out = tmp_path / "cluster"
    with cluster_tuning(tmp_path, out) as cluster:
        cluster.scheduler.kill()
        _, stderr = cluster.tuner.communicate(timeout=300)
    log = out / "evaluations.jsonl"
    assert cluster.tuner.returncode == 1, stderr
    assert messages(stderr) == [f"error: the Dask scheduler {cluster.address} stopped answering "
                                f"mid-tuning; every finished evaluation is in {log}; continue "
                                "with --resume"]
    assert 12 <= len(log.read_text().splitlines()) < 60
    resumed = tune(out, "--workers", "2", "--resume", evaluations=60)
    assert best_and_evaluations(resumed) == best_and_evaluations(reference)
