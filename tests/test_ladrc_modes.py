"""The linear ADRC's modes (ladrc.feedforward, ladrc.prediction): each the switches its
step reads; a combination that cannot work and an old switch refused in one line, before
anything starts, in the stack and in-process alike."""

import json

import pytest
import yaml

from ato_nodes.bags.bagio import PARAMETERS_KEY, read_parameters
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import load_scenario, prepare
from ato_nodes.core.config.schema import defaults
from ato_nodes.core.control.adrc import (FEEDFORWARD_MODES, PREDICTION_MODES,
                                         linear_adrc_gains)
from ato_nodes.core.run.loop import simulate
from commands import one_line_exit_2, script

METRO = "seed004-metro-ato"


@pytest.mark.parametrize("feedforward, prediction, switches", [
    ("none", "none", (False, False, False, False)),  # the papers' law
    ("target", "speed", (True, True, False, False)),  # the ATO's (msg_config/presets)
    ("plan", "speed", (True, True, True, False)),  # seed002-hsr-ato
    ("target", "position", (True, True, False, True)),  # seed002-journey
    ("none", "position", (False, True, False, True))])
def test_each_mode_is_the_switches_the_step_reads(feedforward, prediction, switches):
    gains = linear_adrc_gains({**defaults(), "ladrc.feedforward": feedforward,
                               "ladrc.prediction": prediction})
    assert (gains.feedforward, gains.delay_aware, gains.plan_feedforward,
            gains.predicted_target) == switches


def test_no_mode_holds_a_switch_without_the_one_it_needs():
    for feedforward, plan in FEEDFORWARD_MODES.values():
        assert feedforward or not plan
    for delay_aware, predicted in PREDICTION_MODES.values():
        assert delay_aware or not predicted
    assert defaults()["ladrc.feedforward"] == defaults()["ladrc.prediction"] == "none"


@pytest.mark.parametrize("overrides, line", [
    (["ladrc.feedforward=plan"], "ladrc.feedforward plan needs a plan with forces "
                                 "(profile.kind strategy), not profile.kind ato"),
    (["ladrc.plan_lead=15"], "ladrc.plan_lead applies to ladrc.feedforward plan, not target"),
    (["ladrc.plan_band=0.2"], "ladrc.plan_band applies to ladrc.feedforward plan, not target"),
    (["ladrc.prediction=position", "profile.kind=step", "profile.berth=0",
      "profile.departure_jerk=0"], "ladrc.prediction position needs a position-indexed plan, "
                                   "not profile.kind step"),
    (["ladrc.feedforward=plna"], "ladrc.feedforward must be one of none, target, plan; "
                                 "got 'plna'")],
    ids=["plan-on-a-curve", "lead-without-plan", "band-without-plan", "position-on-time",
         "unknown-mode"])
def test_a_combination_that_cannot_work_is_one_line_before_anything_starts(
        overrides, line, tmp_path):
    with pytest.raises(ScenarioError) as refused:
        prepare(METRO, overrides)
    assert line in str(refused.value) and "\n" not in str(refused.value)
    one_line_exit_2(script("run_stack", "--scenario", METRO, "--out", tmp_path / "bag",
                           *(f"--set={item}" for item in overrides)), line)
    assert not (tmp_path / "bag").exists()


@pytest.mark.parametrize("name, value, line", [
    ("ladrc.feedforward", True, "ladrc.feedforward: true is an old switch of the linear ADRC: "
                                "give ladrc.feedforward: target"),
    ("ladrc.plan_feedforward", True, "ladrc.plan_feedforward: true is an old switch of the "
                                     "linear ADRC: give ladrc.feedforward: plan"),
    ("ladrc.delay_aware", True, "ladrc.delay_aware: true is an old switch of the linear ADRC: "
                                "give ladrc.prediction: speed"),
    ("ladrc.predicted_target", True, "ladrc.predicted_target: true is an old switch of the "
                                     "linear ADRC: give ladrc.prediction: position"),
    ("ladrc.delay_aware", False, "ladrc.delay_aware: false is an old switch of the linear "
                                 "ADRC: give ladrc.prediction: one of none, speed, position "
                                 "(speed for true; the papers' none is the default)")],
    ids=["feedforward", "plan_feedforward", "delay_aware", "predicted_target", "delay_aware-false"])
def test_an_old_switch_is_one_line_naming_the_mode(name, value, line, tmp_path):
    said = str(value).lower()
    scenario = tmp_path / "old.yaml"
    scenario.write_text(f"base: {METRO}\ncontroller:\n  ros__parameters:\n"
                        f"    {name}: {said}\n")
    with pytest.raises(ScenarioError, match=f"^{scenario}: {line}$".replace("(", r"\(")
                       .replace(")", r"\)")):
        load_scenario(str(scenario))
    for overrides, where in (([f"{name}={said}"], "--set"), ({name: value}, "override")):
        with pytest.raises(ScenarioError) as refused:
            prepare(METRO, overrides)
        assert str(refused.value) == f"{where}: {line}"
    one_line_exit_2(script("run_stack", "--scenario", scenario, "--out", tmp_path / "bag"),
                    line)
    one_line_exit_2(script("run_stack", "--scenario", METRO, "--out", tmp_path / "bag",
                           f"--set={name}={said}"), f"--set: {line}")
    assert not (tmp_path / "bag").exists()


def test_values_built_by_hand_are_refused_by_simulate_in_one_line():
    values = load_scenario(METRO)
    old = {name: value for name, value in values.items() if name != "ladrc.prediction"}
    for run, line in (
            ({**values, "ladrc.feedforward": True}, "ladrc.feedforward: true is an old switch "
                                                    "of the linear ADRC: give "
                                                    "ladrc.feedforward: target"),
            ({**old, "ladrc.delay_aware": True}, "ladrc.delay_aware: true is an old switch"),
            ({**values, "ladrc.plan_lead": 15.0}, "ladrc.plan_lead applies to "
                                                  "ladrc.feedforward plan, not target")):
        with pytest.raises(ScenarioError, match=line) as refused:
            simulate({**run, "run.duration": 1.0})
        assert "\n" not in str(refused.value)


@pytest.mark.parametrize("switches, modes", [
    ((False, False, False, False), ("none", "none")),
    ((True, True, False, False), ("target", "speed")),
    ((True, True, True, False), ("plan", "speed")),
    ((True, True, False, True), ("target", "position"))])
def test_a_bag_recorded_with_the_old_switches_reads_as_its_modes(switches, modes, tmp_path):
    old = dict(zip(("ladrc.feedforward", "ladrc.delay_aware", "ladrc.plan_feedforward",
                    "ladrc.predicted_target"), switches, strict=True))
    kept = {**{name: value for name, value in load_scenario(METRO).items()
               if not name.startswith("ladrc.") or name in ("ladrc.omega_o", "ladrc.b0")},
            **old}
    (tmp_path / "metadata.yaml").write_text(yaml.safe_dump({"rosbag2_bagfile_information": {
        "custom_data": {PARAMETERS_KEY: json.dumps(kept)}}}))
    values = read_parameters(tmp_path)
    assert (values["ladrc.feedforward"], values["ladrc.prediction"]) == modes
    assert not set(old) - {"ladrc.feedforward"} & set(values)
    assert values["ladrc.omega_o"] == kept["ladrc.omega_o"]
