"""A user's own node in place of the project's controller (docs/external-nodes.md):
started by run_stack.py --external, or by the user in the domain it prints; its series
bit for bit those of the same law in-process; a node that never joins named in one line
and nothing of it left running."""

import json
import os
import re
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

from ato_nodes.bags.bagio import read_parameters, read_series
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.components import CONTROLLERS
from ato_nodes.core.config.scenario import apply_overrides, load_scenario
from ato_nodes.core.run.loop import simulate
from ato_nodes.launcher.launch import node_environment
from commands import invocation, one_line_exit_2

ROOT = Path(__file__).resolve().parents[1]
RUN_STACK = invocation("run_stack")
SCORE_BAG = invocation("score_bag")
ANALYZE = invocation("analyze")
TUNE = invocation("tune")
PID_NODE = [sys.executable, str(ROOT / "tests" / "data" / "external_pid.py")]
SMC_NODE = ROOT / "examples" / "smc-node" / "smc_node.py"
# The PID tracking two steps ahead (its feedforward reads the horizon), on seed 000's
# target, with sensor noise
PID_RUN = ["controller.kind=pid", "controller.preview=2", "run.duration=20",
           "plant.speed_noise=0.05"]


def stack_command(bag: Path, domain, *arguments, run=PID_RUN) -> list[str]:
    return [*RUN_STACK, "--scenario", "seed000", "--out", str(bag), "--quiet",
            "--domain-id", str(domain.domain_id), *(f"--set={item}" for item in run),
            *arguments]


def assert_series_equal_in_process(bag: Path, run=PID_RUN,
                                   outputs=("proportional", "integral")) -> None:
    expected = simulate(apply_overrides(load_scenario("seed000"), run))
    recorded = read_series(bag)
    for name, series in expected.items():
        if name != "t":
            np.testing.assert_array_equal(recorded[name], series, err_msg=name)
    assert set(outputs) <= set(recorded)  # its named outputs, recorded


@pytest.mark.integration
def test_an_external_controller_started_by_run_stack_gives_the_in_process_bits(
        tmp_path, ros_domain):
    bag = tmp_path / "bag"
    done = subprocess.run(stack_command(bag, ros_domain, "--external", "controller", "--",
                                        *PID_NODE),
                          capture_output=True, text=True, timeout=180, cwd=tmp_path,
                          **ros_domain.handed_down())
    assert done.returncode == 0, done.stderr
    assert_series_equal_in_process(bag)
    assert read_parameters(bag)["controller.external"] == "tests/data/external_pid.py"
    scored = subprocess.run([*SCORE_BAG, str(bag), "--resimulate"], capture_output=True,
                            text=True, timeout=60)
    assert scored.returncode == 0 and scored.stderr.splitlines() == [
        "not re-simulated: the controller was an external node's law "
        "(tests/data/external_pid.py), which only that node runs; the bag is scored as "
        "recorded"], scored.stderr
    assert "ITAE" in scored.stdout and "re-simulated" not in scored.stdout
    analyzed = subprocess.run([*ANALYZE, str(bag), "--out", str(tmp_path / "report")],
                              capture_output=True, text=True, timeout=120)
    assert analyzed.returncode == 0, analyzed.stderr
    assert "## Controller outputs" in (tmp_path / "report" / "report.md").read_text()
    assert (tmp_path / "report" / "outputs_1.png").stat().st_size > 0


@pytest.mark.integration
def test_an_external_profile_started_by_run_stack_gives_the_in_process_bits(
        tmp_path, ros_domain):
    """The project's own profile node, started as a user's command would be."""
    bag = tmp_path / "bag"
    done = subprocess.run(stack_command(bag, ros_domain, "--external", "profile", "--",
                                        sys.executable, "-m", "ato_nodes.nodes.profile"),
                          capture_output=True, text=True, timeout=180, cwd=tmp_path,
                          **ros_domain.handed_down())
    assert done.returncode == 0, done.stderr
    assert_series_equal_in_process(bag)


@pytest.mark.integration
def test_the_example_smc_node_gives_the_bits_of_the_smc_kind_in_process(tmp_path, ros_domain):
    """examples/smc-node: the plug-in's law in a node of its own, against the same law
    registered as the kind smc and run in-process."""
    pytest.importorskip("ato_smc.law", reason="the example plug-in examples/ato-smc")
    try:
        CONTROLLERS["smc"]
    except ScenarioError:
        pytest.skip("the example plug-in is not registered (pip install -e examples/ato-smc)")
    run = ["controller.kind=smc", "smc.gain=30", *PID_RUN[1:]]
    done = subprocess.run(stack_command(tmp_path / "bag", ros_domain, "--external",
                                        "controller", "--", sys.executable, str(SMC_NODE),
                                        run=run),
                          capture_output=True, text=True, timeout=180, cwd=tmp_path,
                          **ros_domain.handed_down())
    assert done.returncode == 0, done.stderr
    assert_series_equal_in_process(tmp_path / "bag", run, ("sliding_surface", "switching"))
    assert read_parameters(tmp_path / "bag")["controller.external"] == "examples/smc-node"


@pytest.mark.integration
def test_without_a_command_the_run_says_where_and_waits_for_the_users_node(
        tmp_path, ros_domain):
    bag = tmp_path / "bag"
    stack = subprocess.Popen(stack_command(bag, ros_domain, "--external", "controller"),
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             cwd=tmp_path, **ros_domain.handed_down())
    try:
        said = ""
        while "waiting" not in said:
            said = stack.stderr.readline()
            assert said, "run_stack.py ended without saying where to start the node"
        domain = re.search(r"ROS_DOMAIN_ID=(\d+)", said).group(1)
        arguments = shlex.split(said.split("the arguments ", 1)[1].split(" (")[0])
        assert int(domain) == ros_domain.domain_id and "--params-file" in arguments
        node = subprocess.run([*PID_NODE, *arguments], env=node_environment(int(domain)),
                              capture_output=True, text=True, timeout=180)
        assert node.returncode == 0, node.stderr
        assert stack.wait(timeout=60) == 0, stack.stderr.read()
    finally:
        if stack.poll() is None:
            stack.kill()
    assert_series_equal_in_process(bag)


def alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.integration
def test_an_external_node_that_never_joins_is_named_in_one_line_and_nothing_of_it_stays(
        tmp_path, ros_domain):
    pids = tmp_path / "pids"
    # a command that leaves a child of its own behind, neither ever a ROS node
    silent = [sys.executable, "-c", "import subprocess, sys, time; child = subprocess.Popen("
              "['sleep', '600']); open(sys.argv[1], 'w').write(f'{child.pid}'); time.sleep(600)",
              str(pids)]
    done = subprocess.run(stack_command(tmp_path / "bag", ros_domain,
                                        "--set=supervisor.ready_timeout=2", "--external",
                                        "controller", "--", *silent),
                          capture_output=True, text=True, timeout=120, cwd=tmp_path,
                          **ros_domain.handed_down())
    assert done.returncode == 1 and "Traceback" not in done.stderr
    (line,) = [line for line in done.stderr.splitlines() if "error" in line]
    assert line.startswith("error: nodes not ready after 2 s: controller"), line
    assert "(the external controller never announced 'ready controller'" in line
    child = int(pids.read_text())
    deadline = time.monotonic() + 10  # reaped by init once killed
    while alive(child) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not alive(child)


@pytest.mark.integration
def test_an_external_node_that_fails_fails_the_run_in_one_line_naming_it(tmp_path, ros_domain):
    done = subprocess.run(stack_command(tmp_path / "bag", ros_domain, "--external",
                                        "controller", "--", sys.executable, "-c",
                                        "import sys; sys.exit(3)"),
                          capture_output=True, text=True, timeout=120, cwd=tmp_path,
                          **ros_domain.handed_down())
    assert done.returncode == 1 and "Traceback" not in done.stderr
    (line,) = [line for line in done.stderr.splitlines() if "error" in line]
    assert line.startswith("error: node 'controller' exited with status 3"), line


@pytest.mark.parametrize("arguments, words", [
    (["--external", "plant", "--", "true"], ["--external plant", "controller or profile"]),
    (["--external", "controller", "--", "no-such-command-here"], ["no-such-command-here",
                                                                  "not found"]),
    (["--", "true"], ["needs --external"]),
])
def test_a_bad_external_node_is_refused_in_one_line_before_anything_starts(
        tmp_path, arguments, words):
    done = subprocess.run([*RUN_STACK, "--out", str(tmp_path / "bag"), *arguments],
                          capture_output=True, text=True, timeout=60, cwd=tmp_path)
    one_line_exit_2(done, *words)
    assert not (tmp_path / "bag").exists()
    assert os.listdir(tmp_path) == []


@pytest.mark.integration
def test_tune_tunes_an_external_nodes_own_parameter_in_its_declared_range(tmp_path):
    out = tmp_path / "tune"
    node = [sys.executable, str(ROOT / "tests" / "data" / "proportional_node.py")]
    done = subprocess.run([*TUNE, "--scenario", "seed000", "--set", "run.duration=5",
                           "--evaluations", "4", "--population", "2", "--out", str(out),
                           "--keep-bags", "--quiet", "--external", "controller", "--", *node],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert json.loads((out / "tuning.json").read_text())["params"] == {"gain": [1.0, 200.0]}
    logged = [json.loads(line) for line in (out / "evaluations.jsonl").read_text().splitlines()]
    assert len(logged) == 4 and logged[0]["params"] == {"gain": 50.0}  # its declared value
    for record in logged:  # each candidate's node ran with the candidate's gain
        bag = out / "runs" / f"candidate-{record['index']:05d}"
        assert read_parameters(bag)["gain"] == record["params"]["gain"]
        assert 1.0 <= record["params"]["gain"] <= 200.0 and record["status"] == "ok"
    assert "--external controller -- " in done.stdout and "-p gain:=" in done.stdout


@pytest.mark.integration
def test_tune_tunes_the_example_nodes_own_gains_named_as_an_installed_plugins(tmp_path):
    """The example node's gains are smc.*, the schema's too once the plug-in is installed:
    on a run of another kind they are still the node's own, tuned on its command line (the
    tuner used to take them for the run's and refuse every candidate)."""
    pytest.importorskip("ato_smc.law", reason="the example plug-in examples/ato-smc")
    out = tmp_path / "tune"
    done = subprocess.run([*TUNE, "--scenario", "seed000", "--set", "run.duration=5",
                           "--evaluations", "4", "--population", "2", "--out", str(out),
                           "--quiet", "--external", "controller", "--", sys.executable,
                           str(SMC_NODE)], capture_output=True, text=True, timeout=300,
                          cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert set(json.loads((out / "tuning.json").read_text())["params"]) == {
        "smc.integral_weight", "smc.gain", "smc.boundary", "smc.feedforward"}
    logged = [json.loads(line) for line in (out / "evaluations.jsonl").read_text().splitlines()]
    statuses = [record["status"] for record in logged]  # none refused as the run's values
    assert len(logged) == 4 and "invalid" not in statuses and statuses[0] == "ok"
    assert "-p smc.gain:=" in (out / "best.yaml").read_text()


def test_tune_refuses_an_external_node_in_process_in_one_line(tmp_path):
    one_line_exit_2(subprocess.run([*TUNE, "--out", str(tmp_path / "tune"), "--in-process",
                                    "--external", "controller", "--", "true"],
                                   capture_output=True, text=True, timeout=60),
                    "runs only in its node")
    assert not (tmp_path / "tune").exists()


@pytest.mark.integration
def test_compare_scenarios_runs_an_external_node_in_every_variant(tmp_path):
    out = tmp_path / "compare"
    node = [sys.executable, str(ROOT / "tests" / "data" / "proportional_node.py")]
    done = subprocess.run([*invocation("compare_scenarios.py"), "seed000:run.duration=5",
                           "seed000:run.duration=5:plant.speed_noise=0.1", "--out", str(out),
                           "--external", "controller", "--", *node, "--ros-args", "-p",
                           "gain:=80.0"], capture_output=True, text=True, timeout=300,
                          cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    report = json.loads((out / "comparison.json").read_text())
    assert [row["bit_identical"] for row in report.values()] == [None, None]
    assert done.stdout.count("n/a (external node)") == 4  # two progress lines, two rows
    for bag in ("run0", "run1"):  # the node's own parameter, from its command line
        assert read_parameters(out / bag)["gain"] == 80.0


@pytest.mark.integration
def test_robustness_runs_each_sample_through_the_stack_with_the_external_node(tmp_path):
    out = tmp_path / "robust"
    node = [sys.executable, str(ROOT / "tests" / "data" / "proportional_node.py")]
    done = subprocess.run([*invocation("robustness.py"), "seed000", "--samples", "2",
                           "--workers", "2", "--set", "run.duration=5", "--out", str(out),
                           "--external", "controller", "--", *node], capture_output=True,
                          text=True, timeout=300, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    rows = (out / "samples.csv").read_text().splitlines()
    assert len(rows) == 3 and "2 samples" in done.stdout  # a header and a row per sample
    assert not list(Path(tempfile.gettempdir()).glob("ato-sample-*/bag"))  # scored, deleted
