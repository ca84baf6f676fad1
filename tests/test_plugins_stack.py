"""The plug-in seam through the real graph: the PID baseline, a 20-step preview, and
nodes started straight from a shipped scenario file with no launcher in between."""

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from ato_nodes.results import jsontext
from ato_nodes.reports.report import write_report
from ato_nodes.bags.bagio import message_counts, read_parameters, read_run, read_series
from ato_nodes.core.train.line import load_line
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.config.scenario import apply_overrides, load_scenario
from ato_nodes.core.scoring.catalogue import format_indices
from ato_nodes.core.run.scoring import kept_file, score_series
from ato_nodes.core.config.schema import NODES
from ato_nodes.launcher.launch import DomainLock, Stack, node_environment
from ato_nodes.studies.tuning import evaluate_in_process, evaluate_in_stack

pytestmark = pytest.mark.integration
ROOT = Path(__file__).resolve().parents[1]


def refuse_constant(name):
    raise ValueError(f"not JSON: {name}")


def assert_bag_equals_in_process(bag, values):
    """Every series bit for bit; the bag's time is its nanosecond stamps (k h rounded to
    1 ns), so the time-weighted indices agree to the last few bits."""
    expected, recorded = simulate(values), read_series(bag)
    np.testing.assert_allclose(recorded["t"], expected["t"], rtol=0, atol=1e-12)
    for name, series in expected.items():
        if name != "t":
            np.testing.assert_array_equal(recorded[name], series, err_msg=name)
    assert score_series(recorded, read_parameters(bag)) == pytest.approx(
        score_series(expected, values), rel=1e-12, nan_ok=True)


@pytest.mark.parametrize("scenario, duration", [
    ("seed000", 60), ("seed004-metro", 200), ("seed003-maglev", 120)])
def test_the_pid_baseline_runs_through_the_stack_bit_identical_to_in_process(
        tmp_path, scenario, duration):
    values = apply_overrides(load_scenario(scenario), [
        "controller.kind=pid", "controller.preview=2", f"run.duration={duration}"])
    outcome = Stack(values, tmp_path / "bag", quiet=True, timeout=120).run()
    assert outcome.ok, outcome.message
    recorded = read_series(tmp_path / "bag")
    assert {"feedforward", "proportional", "integral", "derivative"} <= set(recorded)
    assert_bag_equals_in_process(tmp_path / "bag", values)


def test_a_20_step_preview_reaches_the_controller_in_the_stack_as_in_process(tmp_path):
    values = apply_overrides(load_scenario("seed004-metro"), [
        "controller.preview=20", "run.duration=40"])
    outcome = Stack(values, tmp_path / "bag", quiet=True, timeout=120).run()
    assert outcome.ok, outcome.message
    assert read_series(tmp_path / "bag")["preview"].shape == (400, 21)
    assert_bag_equals_in_process(tmp_path / "bag", values)


def test_the_gpc_with_online_correction_runs_through_the_stack_and_the_bag_keeps_its_model(
        tmp_path):
    values = apply_overrides(load_scenario("seed001-crh380al"), [
        "run.duration=90", "gpc.correction_threshold=0.03"])  # samples join during the run
    bag = tmp_path / "bag"
    outcome = Stack(values, bag, quiet=True, timeout=120).run()
    assert outcome.ok, outcome.message
    assert read_series(bag)["samples_added"][-1] > 0
    assert_bag_equals_in_process(bag, values)
    parameters = read_parameters(bag)
    assert kept_file(parameters, "gpc.model") == Path(values["gpc.model"]).read_bytes()
    assert parameters["gpc.model.sha256"] == hashlib.sha256(
        Path(values["gpc.model"]).read_bytes()).hexdigest()
    markdown, _ = write_report([read_run(bag)], [], tmp_path / "report")
    assert "## Controller outputs" in markdown.read_text()
    assert (tmp_path / "report" / "outputs_1.png").stat().st_size > 0


def test_the_seed002_strategy_is_tracked_through_the_stack_with_no_traction_in_neutral_sections(
        tmp_path):
    values = apply_overrides(load_scenario("seed002-hsr"), ["run.duration=300"])
    bag = tmp_path / "bag"
    outcome = Stack(values, bag, quiet=True, timeout=180).run()
    assert outcome.ok, outcome.message
    assert_bag_equals_in_process(bag, values)
    series = read_series(bag)
    line = load_line(values["line.file"])
    pantograph = series["position"] - values["plant.pantograph_offset"]
    inside = np.array([line.in_neutral_section(x) for x in pantograph])
    held = inside[1:] & inside[:-1]  # the entering sample shows the last powered sub-step
    assert held.sum() > 10 and np.all(series["force"][1:][held] <= 0.0)
    parameters = read_parameters(bag)
    assert kept_file(parameters, "profile.strategy.file") == Path(
        values["profile.strategy.file"]).read_bytes()


def start_nodes_directly(parameter_file: Path, bag: Path, report: Path | None,
                         interrupt_when=None):
    """`python -m ato_nodes.nodes.<node> --ros-args --params-file FILE` for each node, as a
    standard launch file or `ros2 run` starts them (without a report file, as `ros2
    launch` does by default); SIGINT to every node once interrupt_when() holds. Returns
    ({node: exit status}, {node: stderr}, the supervisor's stdout)."""
    lock = DomainLock()
    env = node_environment(lock.domain_id)
    report_argument = ["-p", f"supervisor.report:={report}"] if report else []
    try:
        processes = {node: subprocess.Popen(
            [sys.executable, "-m", f"ato_nodes.nodes.{node}", "--ros-args", "--params-file",
             str(parameter_file), "-p", f"recorder.output:={bag}", *report_argument],
            env=env, cwd=ROOT, stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE if node == "supervisor" else subprocess.DEVNULL,
            stderr=subprocess.PIPE, text=True) for node in NODES}
        if interrupt_when is not None:
            deadline = time.monotonic() + 60
            while not interrupt_when() and time.monotonic() < deadline:
                time.sleep(0.05)
            for process in processes.values():
                process.send_signal(signal.SIGINT)
        errors, printed = {}, ""
        for node, process in processes.items():
            output, errors[node] = process.communicate(timeout=120)
            printed = output if node == "supervisor" else printed
        return {node: process.returncode for node, process in processes.items()}, errors, printed
    finally:
        for process in processes.values():
            if process.poll() is None:
                process.kill()
        lock.release()


def failed_nodes(codes: dict[str, int], errors: dict[str, str]) -> str:
    """Each node that exited with a status other than 0: its status and its whole stderr
    (an assertion's repr of every node's stderr is cut before the node that failed)."""
    return "\n".join(f"{node} exited {code}:\n{errors[node]}"
                     for node, code in codes.items() if code != 0)


def test_nodes_started_from_a_shipped_scenario_file_run_its_train_on_its_line(tmp_path):
    scenario = ROOT / "msg_config" / "scenarios" / "seed004-metro.yaml"
    codes, errors, _ = start_nodes_directly(scenario, tmp_path / "direct", tmp_path / "r.json")
    assert set(codes.values()) == {0}, failed_nodes(codes, errors)
    launched = tmp_path / "launched"
    assert Stack(load_scenario("seed004-metro"), launched, quiet=True, timeout=120).run().ok
    direct = read_parameters(tmp_path / "direct")
    assert direct["plant.train"] == "metro-b" and direct["plant.mass"] == 194.3
    assert direct["line.file"].endswith("msg_config/lines/metro-interstation.yaml")
    assert score_series(read_series(tmp_path / "direct"), direct) == \
        score_series(read_series(launched), read_parameters(launched))
    assert json.loads((tmp_path / "r.json").read_text())["steps"] == 2000


def test_nodes_without_a_launcher_write_the_runs_summary_and_print_its_indices(tmp_path):
    scenario = ROOT / "msg_config" / "scenarios" / "seed004-metro.yaml"
    bag = tmp_path / "direct"
    codes, errors, printed = start_nodes_directly(scenario, bag, report=None)
    assert set(codes.values()) == {0}, failed_nodes(codes, errors)
    summary = json.loads((bag / "summary.json").read_text(), parse_constant=refuse_constant)
    indices = score_series(read_series(bag), read_parameters(bag))
    assert summary["status"] == "completed" and summary["steps"] == 2000
    assert summary["indices"] == json.loads(jsontext.dumps(indices))
    assert summary["recorded"] == message_counts(bag)
    assert format_indices(indices) in printed


def test_interrupted_nodes_without_a_launcher_say_so_in_the_runs_summary(tmp_path):
    scenario = tmp_path / "slow.yaml"
    scenario.write_text((ROOT / "msg_config" / "scenarios" / "seed004-metro.yaml").read_text()
                        .replace("/**:\n  ros__parameters:\n",
                                 "/**:\n  ros__parameters:\n    run.real_time: true\n", 1))
    bag = tmp_path / "direct"
    codes, errors, _ = start_nodes_directly(
        scenario, bag, report=None, interrupt_when=lambda: any(bag.glob("*.mcap")) and sum(
            path.stat().st_size for path in bag.glob("*.mcap")) > 5000)
    assert set(codes.values()) == {0}, failed_nodes(codes, errors)
    summary = json.loads((bag / "summary.json").read_text(), parse_constant=refuse_constant)
    assert summary["status"] == "interrupted" and 0 < summary["steps"] < 2000
    assert "indices" not in summary and (bag / "metadata.yaml").exists()


def test_a_shared_parameter_given_to_one_node_only_is_refused_before_the_run(tmp_path):
    scenario = tmp_path / "one-node.yaml"
    scenario.write_text("plant:\n  ros__parameters:\n    plant.train: metro-b\n")
    codes, errors, _ = start_nodes_directly(scenario, tmp_path / "bag", tmp_path / "r.json")
    assert codes["supervisor"] == 2
    # one error line among the console log's INFO lines (its shutdown)
    (line,) = [line for line in errors["supervisor"].splitlines() if "INFO" not in line]
    assert "plant.train is" in line and "'metro-b' in plant" in line and "'' in" in line
    assert "give shared parameters under /**" in line
    assert not (tmp_path / "r.json").exists()


def test_a_supervisor_whose_nodes_never_come_fails_and_names_them(tmp_path):
    lock = DomainLock()
    try:
        result = subprocess.run(
            [sys.executable, "-m", "ato_nodes.nodes.supervisor", "--ros-args", "-p",
             "supervisor.ready_timeout:=1.0"], env=node_environment(lock.domain_id), cwd=ROOT,
            stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=60)
    finally:
        lock.release()
    assert result.returncode != 0
    assert "controller, plant, profile, recorder" in result.stderr


def echo_during_run(values: dict, bag: Path, topic: str, quiet: float) -> list:
    """What tests/topic_probe.py (standing in for `ros2 topic echo`) receives on `topic`
    while the stack runs `values` in the run's own domain."""
    stack = Stack(values, bag, quiet=True, timeout=120)
    env = {**os.environ, "ROS_DOMAIN_ID": str(stack.lock.domain_id),
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    probe = subprocess.Popen([sys.executable, str(ROOT / "tests" / "topic_probe.py"), topic,
                              "60", str(quiet)], env=env, stdout=subprocess.PIPE, text=True)
    try:
        assert probe.stdout.readline().strip() == "ready"
        assert stack.run().ok
        return json.loads(probe.communicate(timeout=60)[0])
    finally:
        if probe.poll() is None:
            probe.kill()


def test_the_running_fitness_topic_grows_to_the_runs_final_fitness(tmp_path):
    values = apply_overrides(load_scenario("seed000"), [
        "run.duration=8", "run.real_time=true", "supervisor.fitness=itae"])
    received = echo_during_run(values, tmp_path / "bag", "/ato/running_fitness", quiet=1.0)
    run = read_run(tmp_path / "bag")
    final = score_series(run.series, run.parameters)["itae"]
    assert len(received) > 100 and received == sorted(received) and received[0] < final / 2
    assert received[-1] == pytest.approx(final, rel=1e-12)


def test_a_candidate_the_supervisor_prunes_ends_where_the_in_process_one_does(tmp_path):
    values = apply_overrides(load_scenario("seed000"), ["run.duration=60"])
    in_process = evaluate_in_process(values, {}, "itae", 0, bound=20.0)
    through_stack = evaluate_in_stack(values, {}, "itae", 0, tmp_path / "bag", 120.0,
                                      bound=20.0)
    assert in_process.status == through_stack.status == "pruned", through_stack.message
    assert in_process.fitness == through_stack.fitness > 20.0


def test_the_nodes_log_their_run_to_rosout(tmp_path):
    values = apply_overrides(load_scenario("seed000"), ["run.duration=3", "run.real_time=true"])
    records = echo_during_run(values, tmp_path / "bag", "/rosout", quiet=10.0)  # silent steps
    said = {(r["name"], r["msg"]) for r in records}
    for node in NODES:  # the supervisor is the one that gathers the others' readiness
        assert node == "supervisor" or (node, "every edge of the topic map matched: ready") \
            in said, node
        assert (node, "run event: start") in said, node
    for node, event in (("plant", "finished"), ("recorder", "recorded")):
        assert any(name == node and msg.startswith(f"run event: {event} ")
                   for name, msg in said), (node, event)
