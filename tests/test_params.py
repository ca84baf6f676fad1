"""Scenario files and overrides: checked before any process starts."""

import pytest

from ato_nodes.core.errors import ScenarioError
from ato_nodes.core.scenario import (apply_overrides, load_scenario, ros_parameter_file,
                                     scenario_names)
from ato_nodes.core.schema import SPECS, steps


def test_shipped_scenarios_load():
    names = scenario_names()
    assert {"seed000", "seed000-step", "seed000-realistic"} <= set(names)
    for name in names:
        values = load_scenario(name)
        assert steps(values) >= 1


def test_seed000_has_the_papers_parameters():
    values = load_scenario("seed000")
    assert (values["adrc.mu1"], values["adrc.mu2"], values["adrc.beta3"]) == (6000.0, 5500.0, 4500.0)
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
    with pytest.raises(ScenarioError, match="unknown parameter 'adrc.mu11' \\(did you mean adrc.mu1"):
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
    assert declared == {spec.name for spec in SPECS}
