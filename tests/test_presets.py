"""The ATO product as configuration: the presets (msg_config/presets/) the -ato scenarios
and the journeys build on (`base:`), and how a base is resolved."""

import shutil
from pathlib import Path

import pytest
import yaml

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config import scenario as scenario_module
from ato_nodes.core.config.scenario import (load_scenario, preset_names, resolve_base,
                                            resolve_scenario, scenario_names)
from ato_nodes.core.config.scenario import _loaded as resolved  # not validated: no plans built
from ato_nodes.core.config.schema import unused
from commands import one_line_exit_2, script

ROOT = Path(__file__).resolve().parents[1]
BUILT_ON_THE_ATO = ("hsr-neutral-ato", "seed001-crh380al-ato", "seed002-hsr-ato",
                    "seed003-maglev-ato", "seed004-metro-ato", "seed002-journey",
                    "seed004-metro-line", "seed004-yizhuang-ato", "yizhuang-line")


def written_out(path: Path) -> dict:
    """The scenario file `path` with its bases written into it: each section's parameters,
    a file's over its base's (no `base:` left)."""
    document = yaml.safe_load(path.read_text())
    base = document.pop("base", None)
    merged = written_out(resolve_base(base, path)) if base else {}
    for node, section in document.items():
        merged.setdefault(node, {"ros__parameters": {}})["ros__parameters"].update(
            section["ros__parameters"])
    return merged


@pytest.mark.parametrize("name", [name for name in scenario_names()
                                  if "base" in yaml.safe_load(resolve_scenario(name).read_text())])
def test_a_scenario_on_a_base_is_its_fully_written_form(name, tmp_path):
    values, _ = resolved(name)
    document = written_out(resolve_scenario(name))
    for section in document.values():  # a base's settings of a kind the scenario replaced
        for parameter in set(section["ros__parameters"]) & set(unused(values)):
            del section["ros__parameters"][parameter]
    plain = tmp_path / f"{name}.yaml"
    plain.write_text(yaml.safe_dump(document))
    assert resolved(str(plain))[0] == values


def test_the_ato_scenarios_and_journeys_take_the_product_from_the_presets():
    for name in BUILT_ON_THE_ATO:
        values, _ = resolved(name)
        assert values["train.load_weighing"] and values["controller.holding_target"] == 0.02
    gpc, _ = resolved("seed001-crh380al-ato")  # the GPC in place of the preset's ADRC:
    assert gpc["controller.kind"] == "gpc" and gpc["ladrc.feedforward"] == "none"  # defaults
    for name in ("seed000-ato", "seed000-realistic-ato"):  # the paper's plant: the controller
        values, _ = resolved(name)
        assert values["ladrc.feedforward"] == "target" and not values["train.load_weighing"]


def test_the_wheeled_metro_and_journey_scenarios_run_on_board():
    """The ATO on its own sensors, learning its train (ato-on-board); the HSR trains, the
    Swiss journey and the maglev on the true position (docs/localisation.md says why)."""
    on_board = {name for name in BUILT_ON_THE_ATO if resolved(name)[0]["odometry.enabled"]}
    assert on_board == {"seed004-metro-ato", "seed004-yizhuang-ato", "seed004-metro-line",
                        "yizhuang-line", "seed002-journey"}
    for name in on_board:
        values, _ = resolved(name)
        assert values["estimator.enabled"] and values["profile.replan.enabled"]
        assert values["estimator.lag_sigma"] > 0 and values["odometry.radar"]


def test_one_product_decision_is_one_edit(tmp_path, monkeypatch):
    config = tmp_path / "msg_config"
    shutil.copytree(ROOT / "msg_config", config)
    preset = config / "presets" / "ato-operation.yaml"
    preset.write_text(preset.read_text().replace("train.load_weighing_max: 1.3",
                                                 "train.load_weighing_max: 1.25"))
    monkeypatch.setattr(scenario_module, "config_dir", lambda: config)
    for name in BUILT_ON_THE_ATO:
        assert resolved(name)[0]["train.load_weighing_max"] == 1.25
    assert resolved("seed004-metro")[0]["train.load_weighing_max"] == 0.0


def test_a_preset_is_no_scenario():
    presets = preset_names()
    assert {"ato", "ato-on-board", "ato-operation", "ato-controller"} <= set(presets)
    assert not set(presets) & set(scenario_names())  # `base: NAME` names one file
    with pytest.raises(ScenarioError, match="unknown scenario 'ato'"):
        load_scenario("ato")
    one_line_exit_2(script("run_stack", "--scenario", "ato", "--out", "bags/never"),
                    "unknown scenario 'ato'")
    assert not (ROOT / "bags" / "never").exists()


def test_a_base_may_have_a_base_of_its_own(tmp_path):
    scenario = tmp_path / "heavy.yaml"
    scenario.write_text("base: seed004-metro-ato\n/**:\n  ros__parameters:\n"
                        "    plant.noise_seed: 7\n")
    assert load_scenario(str(scenario)) == {**load_scenario("seed004-metro-ato"),
                                            "plant.noise_seed": 7}


def test_bases_that_go_round_in_a_circle_are_one_line(tmp_path):
    first, second = tmp_path / "first.yaml", tmp_path / "second.yaml"
    first.write_text("base: second.yaml\n")
    second.write_text("base: first.yaml\n/**:\n  ros__parameters:\n    run.duration: 5.0\n")
    with pytest.raises(ScenarioError, match=r"first.yaml: its bases go round in a circle: "
                                            r".*first.yaml -> .*second.yaml -> .*first.yaml$"):
        load_scenario(str(first))
    line = one_line_exit_2(script("run_stack", "--scenario", first, "--out", tmp_path / "bag"),
                           "go round in a circle")
    assert "\n" not in line and not (tmp_path / "bag").exists()
    first.write_text("base: first.yaml\n")
    with pytest.raises(ScenarioError, match="its bases go round in a circle"):
        load_scenario(str(first))


def test_an_unknown_base_names_the_presets_and_scenarios(tmp_path):
    scenario = tmp_path / "mine.yaml"
    scenario.write_text("base: atto\n")
    with pytest.raises(ScenarioError, match=r"mine.yaml: unknown base 'atto'; presets: ato, "
                                            r"ato-controller, ato-on-board, ato-operation; "
                                            r"scenarios: "):
        load_scenario(str(scenario))
