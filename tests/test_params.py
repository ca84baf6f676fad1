"""Scenario files and overrides: checked before any process starts; what a node
declares."""

import json
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.components import CONTROLLERS
from ato_nodes.core.config.scenario import (apply_overrides, check_launcher_free, load_scenario,
                                            ros_parameter_file, scenario_names)
from ato_nodes.core.config.schema import SPECS, NodeValues, for_node, steps, unused
from ato_nodes.launcher.launch import DomainLock, node_environment

ROOT = Path(__file__).resolve().parents[1]
METRO_FILE = ROOT / "msg_config" / "scenarios" / "seed004-metro.yaml"


@pytest.mark.slow
def test_shipped_scenarios_load():
    names = scenario_names()
    assert {"seed000", "seed000-step", "seed000-realistic"} <= set(names)
    for name in names:
        values = load_scenario(name)
        assert steps(values) >= 1


def test_seed000_has_the_papers_parameters():
    values = load_scenario("seed000")
    assert ((values["adrc.mu1"], values["adrc.mu2"], values["adrc.beta3"])
            == (6000.0, 5500.0, 4500.0))
    assert values["run.duration"] == 2400.0 and steps(values) == 48000
    assert not values["plant.envelope"]


def test_unknown_scenario_names_the_known_ones():
    with pytest.raises(ScenarioError, match="unknown scenario 'nope'.*seed000"):
        load_scenario("nope")


def test_a_scenario_that_is_a_directory_or_missing_says_which(tmp_path):
    with pytest.raises(ScenarioError, match=f"^scenario {tmp_path} is a directory, not a "
                                            "scenario file$"):
        load_scenario(str(tmp_path))
    with pytest.raises(ScenarioError, match="scenario file .*absent.yaml does not exist"):
        load_scenario(str(tmp_path / "absent.yaml"))


def test_malformed_yaml_names_file_and_line(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("plant:\n  ros__parameters:\n    plant.mass: [1, 2\n")
    with pytest.raises(ScenarioError, match=r"bad.yaml line \d+: malformed YAML"):
        load_scenario(str(bad))


def test_misspelled_parameter_gets_a_suggestion(tmp_path):
    bad = tmp_path / "typo.yaml"
    bad.write_text("controller:\n  ros__parameters:\n    adrc.mu11: 3.0\n")
    with pytest.raises(ScenarioError,
                       match="unknown parameter 'adrc.mu11' \\(did you mean adrc.mu1"):
        load_scenario(str(bad))


def test_parameter_in_the_wrong_node(tmp_path):
    bad = tmp_path / "wrong.yaml"
    bad.write_text("plant:\n  ros__parameters:\n    adrc.mu1: 3.0\n")
    with pytest.raises(ScenarioError, match="belongs to controller"):
        load_scenario(str(bad))


@pytest.mark.parametrize("override, problem", [
    ("adrc.r0=-1", "out of range"),
    ("adrc.r0=fast", "must be a number"),
    ("plant.substeps=1.5", "must be an integer"),
    ("controller.kind=mpc", "must be one of"),
    ("run.real_time=maybe", "true or false"),
    ("adrc.mu11=1", "did you mean adrc.mu1"),
    ("adrc.mu1", "name=value"),
])
def test_bad_overrides(override, problem):
    with pytest.raises(ScenarioError, match=problem):
        apply_overrides(load_scenario("seed000"), [override])


def test_overrides_apply_with_their_types():
    values = apply_overrides(load_scenario("seed000"), ["adrc.mu1=7000", "run.duration=5",
                                                         "run.real_time=true"])
    assert values["adrc.mu1"] == 7000.0 and isinstance(values["adrc.mu1"], float)
    assert values["run.real_time"] is True and steps(values) == 100


def test_ros_parameter_file_shares_under_the_wildcard_and_gives_each_node_its_own():
    file = ros_parameter_file(load_scenario("seed000"))
    assert "adrc.mu1" in file["controller"]["ros__parameters"]
    assert "adrc.mu1" not in file["plant"]["ros__parameters"]
    shared = file["/**"]["ros__parameters"]
    assert {"run.period", "plant.mass", "profile.kind", "line.file"} <= set(shared)
    assert not any(name in section["ros__parameters"] for node, section in file.items()
                   if node != "/**" for name in shared)
    declared = {name for section in file.values() for name in section["ros__parameters"]}
    assert declared == {spec.name for spec in SPECS} - set(unused(load_scenario("seed000")))
    assert "adrc.mu1" in declared and not any(name.startswith(("dadrc.", "pid.", "gpc.",
                                                                "profile.step."))
                                              for name in declared)


METRO_USES = "this run uses discrete_adrc (its parameters are dadrc.*)"


def test_a_parameter_of_a_kind_the_run_does_not_use_is_one_line_wherever_it_is_given(tmp_path):
    metro = load_scenario("seed004-metro")
    with pytest.raises(ScenarioError) as refused:
        apply_overrides(metro, ["adrc.mu1=7000"])
    assert str(refused.value) == (f"--set: adrc.mu1 belongs to controller kind han_adrc; "
                                  f"{METRO_USES}")
    with pytest.raises(ScenarioError, match=r"--set: profile.step.speed belongs to profile kind "
                                            r"step; this run uses ato \(its parameters are "
                                            r"profile.ato.\*\)"):
        apply_overrides(metro, ["profile.step.speed=3"])
    scenario = tmp_path / "metro-adrc.yaml"  # its default value changes nothing either
    scenario.write_text("base: seed004-metro\ncontroller:\n  ros__parameters:\n"
                        "    adrc.mu1: 6000.0\n")
    with pytest.raises(ScenarioError) as refused:
        load_scenario(str(scenario))
    assert str(refused.value) == f"{scenario}: adrc.mu1 belongs to controller kind han_adrc; " \
                                 f"{METRO_USES}"
    scenario.write_text("/**:\n  ros__parameters:\n    profile.kind: ato\n"
                        "    line.file: lines/metro-interstation.yaml\n"
                        "    profile.seed000.cycle: 10.0\n")
    with pytest.raises(ScenarioError, match=f"^{scenario}: profile.seed000.cycle belongs to "
                                            "profile kind seed000; this run uses ato"):
        load_scenario(str(scenario))


def test_a_new_kind_comes_with_its_own_parameters_and_leaves_the_old_ones_out():
    values = apply_overrides(load_scenario("seed000"), ["controller.kind=pid", "pid.kp=900"])
    assert values["pid.kp"] == 900.0
    file = ros_parameter_file(values)
    assert "pid.kp" in file["controller"]["ros__parameters"]
    assert not any(name.startswith("adrc.") for name in file["controller"]["ros__parameters"])
    controller = NodeValues("controller", values)
    with pytest.raises(ScenarioError, match="controller: adrc.mu1 belongs to controller kind "
                                            "han_adrc; this run uses pid"):
        controller["adrc.mu1"]


def test_a_node_declares_its_kinds_parameters_only():
    metro = load_scenario("seed004-metro")
    declared = {spec.name for spec in for_node("controller", metro)}
    assert {"dadrc.b1", "profile.ato.acceleration", "controller.kind", "plant.mass"} <= declared
    everything = {spec.name for spec in for_node("controller")}
    installed = set(CONTROLLERS.components) - set(CONTROLLERS.shipped_kinds)  # plug-ins'
    assert {name.split(".")[0] for name in everything - declared} - installed == {
        "adrc", "nladrc", "ladrc", "pid", "gpc", "profile"}
    assert len(declared) < len(everything) - 50
    assert for_node("plant", metro) == for_node("plant")  # it runs no kind


@pytest.mark.parametrize("override", ["recorder.output=/", "supervisor.report=/"])
def test_what_the_launcher_sets_is_refused_naming_out(override):
    values = apply_overrides(load_scenario("seed000"), [override])
    with pytest.raises(ScenarioError, match=f"^{override.split('=')[0]} is set by the launcher "
                                            "for each run it starts; give --out instead$"):
        check_launcher_free(values)
    check_launcher_free(load_scenario("seed000"))


def start_node(node: str, *arguments) -> tuple[subprocess.Popen, DomainLock]:
    """`python -m ato_nodes.nodes.NODE --ros-args ARGUMENTS` in a domain of its own."""
    lock = DomainLock()
    process = subprocess.Popen([sys.executable, "-m", f"ato_nodes.nodes.{node}", "--ros-args",
                                *arguments], env=node_environment(lock.domain_id), cwd=ROOT,
                               stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE, text=True)
    return process, lock


@pytest.mark.integration
def test_a_running_node_lists_only_what_its_run_uses_and_keeps_use_sim_time_fixed():
    """`ros2 param list /controller` on a discrete-ADRC run: no other kind's gains;
    `ros2 param set /controller use_sim_time false`: read-only, as every start-up value."""
    process, lock = start_node("controller", "--params-file", str(METRO_FILE))
    try:
        probe = subprocess.run([sys.executable, str(ROOT / "tests" / "param_probe.py"),
                                "/controller", "use_sim_time", "false"], capture_output=True,
                               text=True, timeout=90, env=node_environment(lock.domain_id))
    finally:
        process.send_signal(signal.SIGINT)
        process.communicate(timeout=60)
        lock.release()
    assert probe.returncode == 0, probe.stderr
    answer = json.loads(probe.stdout)
    assert answer["successful"] is False and "read-only" in answer["reason"], answer
    declared = {spec.name for spec in for_node("controller", load_scenario("seed004-metro"))}
    assert set(answer["names"]) == declared | {"use_sim_time", "start_type_description_service"}


@pytest.mark.integration
def test_a_node_given_a_parameter_of_a_kind_its_run_does_not_use_stops_in_one_line():
    process, lock = start_node("controller", "--params-file", str(METRO_FILE),
                               "-p", "adrc.mu1:=7000.0")
    try:
        _, stderr = process.communicate(timeout=60)
    finally:
        lock.release()
    assert process.returncode == 2
    assert stderr.strip().splitlines() == [
        f"controller: error: adrc.mu1 belongs to controller kind han_adrc; {METRO_USES}"]


def test_prepare_loads_overrides_and_validates_once(monkeypatch):
    from ato_nodes.core.config import scenario
    expected = scenario.apply_overrides(scenario.load_scenario("seed004-metro-ato"),
                                        ["run.duration=30", "ladrc.omega_c=3"])
    checks = []
    real = scenario.validate
    monkeypatch.setattr(scenario, "validate", lambda values, where: checks.append(where)
                        or real(values, where))
    assert scenario.prepare("seed004-metro-ato", ["run.duration=30", "ladrc.omega_c=3"]) \
        == expected
    assert checks == ["parameters"]
    checks.clear()
    scenario.prepare("seed004-metro-ato")
    assert len(checks) == 1 and checks[0].endswith("seed004-metro-ato.yaml")


def test_prepare_refuses_a_name_given_twice_and_an_override_of_an_unused_kind():
    from ato_nodes.core.config.scenario import prepare
    with pytest.raises(ScenarioError, match="run.duration is given twice"):
        prepare("seed000", ["run.duration=10", "run.duration=20"])
    with pytest.raises(ScenarioError, match="belongs to controller kind"):
        prepare("seed004-metro", ["adrc.mu1=7000"])
