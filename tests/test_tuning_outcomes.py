"""What tune.py promises at each of its ends, in-process: a refused resume changes
nothing, no best.yaml without a best, --timeout honoured on the compiled loop, the
compile step announced (only when it happens), a finished tuning resumed returns at
once, and every JSON it writes is strict and read back by --resume."""

import json
import os
import subprocess
from pathlib import Path

import pytest

from ato_nodes.core.base import kernels
from commands import invocation

ROOT = Path(__file__).resolve().parents[1]
TUNE = [*invocation("tune")]
SMALL = ["--algorithm", "pso", "--scenario", "seed000-step", "--params", "adrc.mu1=600:60000",
         "--evaluations", "4", "--population", "2", "--in-process", "--set", "run.duration=20"]


def tune(*args, env=None) -> subprocess.CompletedProcess:
    return subprocess.run([*TUNE, *map(str, args)], capture_output=True, text=True, cwd=ROOT,
                          timeout=300, env=env)


def files(directory: Path) -> dict:
    """Every file of a directory: its bytes and its modification time."""
    return {path.name: (path.read_bytes(), path.stat().st_mtime_ns)
            for path in sorted(directory.iterdir())}


def refuse(constant: str):
    raise ValueError(f"bare {constant} in JSON")


def strict(text: str):
    return json.loads(text, parse_constant=refuse)


@pytest.mark.slow
def test_a_refused_resume_changes_nothing_and_the_right_one_still_resumes(tmp_path):
    whole, out = tmp_path / "whole", tmp_path / "out"
    assert tune(*SMALL, "--quiet", "--out", whole).returncode == 0
    assert tune(*SMALL, "--quiet", "--out", out).returncode == 0
    log = out / "evaluations.jsonl"
    log.write_text("".join(log.read_text().splitlines(keepends=True)[:2]))  # as if stopped
    for name in ("tuning.json", "summary.json", "best.yaml"):
        (out / name).unlink()
    before = files(out)
    refused = tune(*SMALL, "--quiet", "--set", "plant.substeps=2", "--out", out, "--resume")
    assert refused.returncode == 2 and refused.stderr.count("\n") == 1
    assert "other conditions" in refused.stderr
    assert files(out) == before
    resumed = tune(*SMALL, "--quiet", "--out", out, "--resume")
    assert resumed.returncode == 0, resumed.stderr
    assert len(log.read_text().splitlines()) == 4
    assert (json.loads((out / "summary.json").read_text())["best_params"]
            == json.loads((whole / "summary.json").read_text())["best_params"])


@pytest.mark.slow
def test_when_every_candidate_fails_there_is_no_best_yaml(tmp_path):
    out = tmp_path / "out"
    result = tune("--scenario", "seed000", "--params", "adrc.b0=0.0001:0.001", "--evaluations",
                  "2", "--population", "2", "--in-process", "--set", "run.duration=20",
                  "--quiet", "--out", out)
    assert result.returncode == 1
    assert result.stderr.count("\n") == 1 and "no best.yaml" in result.stderr
    assert "{'diverged': 2}" in result.stderr
    assert not (out / "best.yaml").exists()
    assert strict((out / "summary.json").read_text())["failed_evaluations"] == {"diverged": 2}


@pytest.mark.slow
def test_in_process_candidates_end_at_their_timeout_on_the_compiled_loop(tmp_path):
    """Each candidate takes about a minute at 10000 RK4 sub-steps per step."""
    out = tmp_path / "out"
    result = tune("--in-process", "--params", "adrc.mu1=600:60000", "--population", "2",
                  "--evaluations", "2", "--set", "plant.substeps=10000", "--timeout", "1",
                  "--workers", "2", "--quiet", "--out", out)
    assert result.returncode == 1 and "{'timeout': 2}" in result.stderr, result.stderr
    records = [json.loads(line) for line in (out / "evaluations.jsonl").read_text().splitlines()]
    assert [record["status"] for record in records] == ["timeout", "timeout"]
    assert all("passed its deadline" in record["message"] for record in records)
    assert not (out / "best.yaml").exists()


@pytest.mark.slow
@pytest.mark.skipif(not kernels.AVAILABLE, reason="numba is not installed")
def test_the_compile_step_is_announced_when_the_cache_is_cold_only(tmp_path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}  # cold: an empty cache
    cold = tune(*SMALL, "--out", tmp_path / "cold", env=env)
    warm = tune(*SMALL, "--out", tmp_path / "warm", env=env)
    assert cold.returncode == warm.returncode == 0, cold.stderr + warm.stderr
    assert cold.stderr.startswith(kernels.COMPILING)
    assert "the loop for controller han_adrc, nladrc (not in the cache) ..." in cold.stderr
    assert kernels.COMPILING not in warm.stderr


@pytest.mark.slow
def test_resuming_a_finished_tuning_runs_nothing_and_prints_its_result(tmp_path):
    out = tmp_path / "out"
    finished = tune(*SMALL, "--quiet", "--out", out)
    assert finished.returncode == 0, finished.stderr
    before = files(out)
    again = tune(*SMALL, "--quiet", "--out", out, "--resume")
    assert again.returncode == 0, again.stderr
    assert again.stdout == f"the tuning in {out} is finished; nothing to run\n" + finished.stdout
    assert files(out) == before


@pytest.mark.slow
def test_the_logs_json_is_strict_and_a_resume_reads_it_back(tmp_path):
    """Candidates whose runs do not arrive (arrival_time not measured: null) and some
    that diverge; the resumed tuning ends where the uninterrupted one does."""
    common = ["--algorithm", "pso", "--scenario", "seed000-step", "--params",
              "adrc.b0=0.0005:0.005", "--evaluations", "12", "--population", "4", "--seed", "2",
              "--in-process", "--set", "run.duration=20", "--quiet"]
    whole, out = tmp_path / "whole", tmp_path / "out"
    assert tune(*common, "--out", whole).returncode == 0
    lines = (whole / "evaluations.jsonl").read_text().splitlines()
    records = [strict(line) for line in lines]
    assert {"ok", "diverged"} <= {record["status"] for record in records}
    assert any(record["indices"] and record["indices"]["arrival_time"] is None
               for record in records)
    strict((whole / "summary.json").read_text())
    strict((whole / "tuning.json").read_text())

    out.mkdir()
    for name in ("tuning.json", ".lock"):
        (out / name).write_bytes((whole / name).read_bytes())
    (out / "evaluations.jsonl").write_text("\n".join(lines[:6]) + "\n")  # interrupted
    resumed = tune(*common, "--out", out, "--resume")
    assert resumed.returncode == 0, resumed.stderr
    assert (out / "history.csv").read_text() == (whole / "history.csv").read_text()
    first, second = (strict((d / "summary.json").read_text()) for d in (whole, out))
    assert (second["best_fitness"], second["best_params"]) == (first["best_fitness"],
                                                               first["best_params"])
