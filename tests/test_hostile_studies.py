"""Careless or hostile input to the study tools (fingerprint.py, robustness.py and the
studies sharing their counts) and to what prepare() derives or checks for them: one line
and exit 2 before anything runs, the stack and in-process alike, and nothing computed
lost (no ROS graph is started here)."""

import json
import subprocess
import sys
from pathlib import Path

import pytest
from commands import one_line_exit_2, script

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import prepare
from ato_nodes.studies.runner import MAX_SAMPLES, MAX_SEED, MAX_WORKERS

ROOT = Path(__file__).resolve().parents[1]
DIGEST = "0" * 64
HUGE = "99999999999999999999"




def fingerprint(*args):
    return script("fingerprint.py", "seed000-step", "--duration", "5", *args)


@pytest.mark.parametrize("saved, words", [
    ({"seed000-step": {}}, ["'seed000-step' is an empty mapping"]),
    ([1], ["not a list"]),
    ({}, ["not an empty mapping"]),
    ({"seed000-step": 5}, ["'seed000-step' is a number"]),
    ({"seed000-step": {"speed": 1}}, ["'speed' is not a sha256"]),
    ({"seed000-step": {"speed": "abc"}}, ["'speed' is not a sha256"]),
    ({"seed004-metro": {"speed": DIGEST}}, ["none of the scenarios run"]),
])
def test_a_saved_set_that_is_not_one_is_refused_before_any_run(tmp_path, saved, words):
    compare = tmp_path / "saved.json"
    compare.write_text(json.dumps(saved))
    result = fingerprint("--compare", compare)
    one_line_exit_2(result, str(compare), *words)
    assert result.stdout == ""  # nothing ran


def test_a_saved_set_that_is_not_json_is_one_line(tmp_path):
    compare = tmp_path / "saved.json"
    compare.write_text("{")
    one_line_exit_2(fingerprint("--compare", compare), str(compare), "not JSON")


def test_a_saved_set_is_read_bounded():
    one_line_exit_2(fingerprint("--compare", "/dev/zero"), "not a regular file")


@pytest.mark.slow
def test_a_series_changed_or_gone_is_not_identical(tmp_path):
    out = tmp_path / "fp.json"
    assert fingerprint("--out", out).returncode == 0
    saved = json.loads(out.read_text())
    same = fingerprint("--compare", out)
    assert same.returncode == 0 and "1 of the 1 saved scenarios identical" in same.stdout
    changed = {"seed000-step": {**saved["seed000-step"], "target": DIGEST}}
    gone = {"seed000-step": {**saved["seed000-step"], "retired": DIGEST}}
    for altered, words in ((changed, "differ: target"), (gone, "no longer computed: retired")):
        out.write_text(json.dumps(altered))
        result = fingerprint("--compare", out)
        assert result.returncode == 1 and words in result.stdout, result.stdout
        assert "0 of the 1 saved scenarios identical" in result.stdout


@pytest.mark.parametrize("make, words", [
    (lambda tmp: Path("/proc/fp.json"), ["cannot be written"]),
    (lambda tmp: tmp, ["is a directory"]),
    (lambda tmp: tmp / "missing" / "fp.json", ["is not a directory"]),
    (lambda tmp: Path("/dev/null"), ["not a regular file"]),
])
def test_an_unwritable_out_is_refused_before_any_run(tmp_path, make, words):
    out = make(tmp_path)
    before = sorted(tmp_path.rglob("*"))
    result = fingerprint("--out", out)
    one_line_exit_2(result, f"--out {out}", *words)
    assert result.stdout == "" and sorted(tmp_path.rglob("*")) == before


def test_a_refused_fingerprint_leaves_its_out_as_it_was(tmp_path):
    out, compare = tmp_path / "fp.json", tmp_path / "saved.json"
    out.write_text("kept\n")
    compare.write_text("[1]")
    one_line_exit_2(fingerprint("--out", out, "--compare", compare))
    assert out.read_text() == "kept\n" and sorted(tmp_path.iterdir()) == [out, compare]


def test_out_holds_each_scenario_as_it_is_done(tmp_path):
    out = tmp_path / "fp.json"
    result = script("fingerprint.py", "seed000-step", "seed004-metro", "--duration", "5",
                    "--out", out)
    assert result.returncode == 0, result.stderr
    assert sorted(json.loads(out.read_text())) == ["seed000-step", "seed004-metro"]
    assert sorted(tmp_path.iterdir()) == [out]  # no temporary file left


def test_digests_that_cannot_be_written_are_not_lost(tmp_path):
    """The --out directory gone while the runs went on: the digests on stdout, exit 1."""
    digests = {"seed000-step": {"speed": DIGEST}}
    code = ("import sys; from pathlib import Path; sys.path.insert(0, 'scripts'); "
            "import fingerprint; fingerprint.write_digests(Path(sys.argv[1]), "
            f"{digests!r})")
    result = subprocess.run([sys.executable, "-c", code,
                             str(tmp_path / "gone" / "fp.json")],
                            capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert result.returncode == 1 and "Traceback" not in result.stderr, result.stderr
    assert "cannot be written" in result.stderr and json.loads(result.stdout) == digests


@pytest.mark.parametrize("args, words", [
    (["--seed", "-1"], [f"--seed must be 0 to {MAX_SEED:,}, not -1"]),
    (["--seed", HUGE], ["--seed must be", "not a number of 20 digits"]),
    (["--samples", HUGE], [f"--samples must be 1 to {MAX_SAMPLES:,}"]),
    (["--samples", str(10**400)], ["not a number of 401 digits"]),
    (["--samples", "0"], ["--samples must be 1"]),
    (["--workers", "99999999999999"], [f"--workers must be 1 to {MAX_WORKERS}"]),
    (["--mass", "0.05:1"], ["--mass 0.05:1, LOW", "plant.mass_factor = 0.05 is out of range"]),
])
def test_robustness_counts_out_of_bounds_are_one_line(tmp_path, args, words):
    result = script("robustness.py", "seed004-metro", *args, "--out", tmp_path / "r")
    one_line_exit_2(result, *words)
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("command", [
    ["ablation.py", "seed004-metro-ato", "--workers", "99999999999999"],
    ["compare_strategies.py", "--workers", "99999999999999"],
    ["compare_strategies.py", "--seeds", "1", "-1"],
])
def test_the_other_studies_check_their_counts_first(tmp_path, command):
    result = script(*command, "--out", tmp_path / "s")
    one_line_exit_2(result, "must be")
    assert not (tmp_path / "s").exists()


@pytest.mark.parametrize("args, words", [
    (["--seed", "-1"], [f"--seed must be 0 to {MAX_SEED:,}"]),
    (["--workers", "99999999999999"], [f"--workers must be 1 to {MAX_WORKERS}"]),
    (["--population", "99999999999"], [f"--population must be 2 to {MAX_SAMPLES:,}"]),
])
def test_a_tuning_refuses_its_counts_before_it_touches_out(tmp_path, args, words):
    """A seed of -1 was refused only once OUT held its lock and tuning.json; a huge
    --workers was an OverflowError traceback."""
    out = tmp_path / "t"
    out.mkdir()
    result = script("tune.py", "--algorithm", "pso", "--scenario", "seed000-step", "--params",
                    "adrc.mu1=600:60000", "--evaluations", "8", "--in-process", *args,
                    "--out", out)
    one_line_exit_2(result, *words)
    assert not any(out.iterdir())


BERTH_START = ["profile.journey.berth=100", "plant.initial_position=99"]


def test_a_journey_starts_at_its_first_stop_whatever_its_berth():
    with pytest.raises(ScenarioError, match="plant.initial_position is 99 m"):
        prepare("seed004-metro-line", BERTH_START)
    assert prepare("seed004-metro-line", ["plant.initial_position=0.05"])  # stopped at it


@pytest.mark.slow
def test_the_stack_refuses_a_start_off_the_first_stop_before_it_starts(tmp_path):
    result = script("run_stack.py", "--scenario", "seed004-metro-line", "--out", tmp_path / "b",
                    *(f"--set={item}" for item in BERTH_START))
    one_line_exit_2(result, "plant.initial_position is 99 m")
    assert not (tmp_path / "b").exists()


LIGHT_READING = ["plant.mass_factor=0.1", "train.load_weighing_error=0.5",
                 "train.load_weighing_seed=8"]
READ_LOW = ["train.load_weighing_max=0.05"]


@pytest.mark.parametrize("overrides, sources", [
    (LIGHT_READING, ["plant.mass_factor=0.1", "train.load_weighing_seed=8"]),
    (READ_LOW, ["train.load_weighing_max=0.05"]),
])
def test_a_weighed_mass_out_of_its_range_is_refused_where_it_is_derived(overrides, sources):
    with pytest.raises(ScenarioError, match=r"train.mass_reading = \S+ is out of range") as error:
        prepare("seed004-metro-ato", overrides)
    assert all(source in str(error.value) for source in sources), error.value
    weighed = prepare("seed004-metro-ato")
    assert 0.1 <= weighed["train.mass_reading"] <= 10 and weighed["train.load_weighing"]


@pytest.mark.parametrize("command", [
    ["run_stack.py", "--scenario", "seed004-metro-ato", "--duration", "5"],
    ["robustness.py", "seed004-metro-ato", "--samples", "2", "--workers", "1"],
    ["tune.py", "--scenario", "seed004-metro-ato", "--in-process", "--evaluations", "2",
     "--params", "ladrc.omega_c=2:5"],
])
def test_every_runner_refuses_a_weighed_mass_out_of_range_alike(tmp_path, command):
    result = script(*command, *(f"--set={item}" for item in READ_LOW), "--out", tmp_path / "o")
    one_line_exit_2(result, "train.mass_reading = 0.05 is out of range",
                    "train.load_weighing_max=0.05")
    assert not (tmp_path / "o").exists()
