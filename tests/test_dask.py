"""The Dask backend of the tuner: the same candidates give the same fitness as the local
worker processes, on a LocalCluster and on a scheduler and workers started as separate
processes with the README's commands, and a worker killed mid-tuning changes nothing."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("distributed")
pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
TUNING = ["--algorithm", "pso", "--scenario", "seed000", "--set", "run.duration=150",
          "--in-process", "--params", "adrc.mu1=600:60000,adrc.mu2=550:55000",
          "--population", "6", "--quiet"]


def tune(out: Path, *extra: str, evaluations: int = 36) -> dict:
    result = subprocess.run([sys.executable, str(ROOT / "scripts" / "tune.py"), *TUNING,
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


def test_separate_scheduler_and_workers_survive_a_killed_worker(tmp_path):
    reference = tune(tmp_path / "local", "--workers", "2", evaluations=60)
    address_file = tmp_path / "scheduler.json"
    processes = [subprocess.Popen([str(BIN / "dask"), "scheduler", "--scheduler-file",
                                   str(address_file), "--no-dashboard", "--port", "0"],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        deadline = time.monotonic() + 60
        while not address_file.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        address = json.loads(address_file.read_text())["address"]
        workers = [subprocess.Popen([str(BIN / "dask"), "worker", address, "--nthreads", "1",
                                     "--no-nanny", "--no-dashboard"], cwd=tmp_path,
                                    stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                   for _ in range(2)]
        processes += workers
        out = tmp_path / "cluster"
        tuner = subprocess.Popen([sys.executable, str(ROOT / "scripts" / "tune.py"), *TUNING,
                                  "--evaluations", "60", "--out", str(out), "--cluster",
                                  address], cwd=ROOT, stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, text=True)
        processes.append(tuner)
        log = out / "evaluations.jsonl"
        while time.monotonic() < deadline + 120 and tuner.poll() is None and (
                not log.exists() or len(log.read_text().splitlines()) < 12):
            time.sleep(0.02)
        assert tuner.poll() is None, "the tuning ended before a worker could be killed"
        os.kill(workers[0].pid, signal.SIGKILL)  # mid-tuning: its task goes to the other
        _, stderr = tuner.communicate(timeout=600)
        assert tuner.returncode == 0, stderr
        assert len(log.read_text().splitlines()) == 60
        assert best_and_evaluations(outcome(out)) == best_and_evaluations(reference)
    finally:
        for process in processes:
            if process.poll() is None:
                process.kill()
                process.wait()
