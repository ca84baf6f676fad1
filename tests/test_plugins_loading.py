"""Plug-ins loaded from outside the package: each bad plug-in refused in one line before
anything starts (commands, scenarios, the in-process API alike), a scenario's `plugins:`
(its base's included) and --plugin, and the kinds they bring run as a shipped kind runs
(compiled and Python bits equal)."""

import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config import plugins
from ato_nodes.core.config.components import REGISTRIES
from ato_nodes.core.config import schema
from ato_nodes.core.config.scenario import prepare
from ato_nodes.core.run.loop import simulate
from commands import one_line_exit_2, script

ROOT = Path(__file__).resolve().parents[1]

# A plug-in with one controller kind, `tracks_{name}`: a proportional law with its
# compiled steps. {api}, {role}, {group}, {outputs}, {steps} spoil it for one test each.
GOOD = '''
from typing import NamedTuple
from ato_nodes.plugin import (CONTROLLER_NODES, Component, ControllerSteps, Output,
                              SteppedController, jitable, limit_command, param, settings)

PLUGIN_API = {api}

class Gains(NamedTuple):
    kp: float

class State(NamedTuple):
    error: float

@jitable
def start(settings, state, target, measured, horizon):
    return State(0.0)

@jitable
def step(settings, state, target, measured, horizon, last, limits):
    error = horizon[-1] - measured
    u = limit_command(settings.kp * error, target, measured, last, limits)
    return u, (error,), State(error)

STEPS = ControllerSteps(start, step, State)

def factory(values, context, limiter):
    return SteppedController(STEPS, settings(Gains, "{group}", values), limiter, State(0.0))

COMPONENTS = (Component(
    "{kind}", "proportional, for the tests", (param("{group}.kp", 50.0, "gain, N/kN per m/s",
    CONTROLLER_NODES, 0.0, 1e4),), factory, {outputs}, steps={steps}, role="{role}",
    search_space=(("{group}.kp", 1.0, 200.0),)),)
'''
OUTPUTS = '(Output("error", "m/s", "tracking error"),)'


def plugin_source(kind, api="1", role="controller", group=None, outputs=OUTPUTS, steps="STEPS"):
    return GOOD.format(kind=kind, api=api, role=role, group=group or kind, outputs=outputs,
                       steps=steps)


@pytest.fixture
def plugin_folder(tmp_path, monkeypatch):
    """A folder on sys.path (and PYTHONPATH, for the commands) to write plug-ins into; the
    registries, the schema and the loaded plug-ins as they were after the test."""
    schema.load_plugins()  # the installed ones, before the registries are kept
    folder = tmp_path / "plugins"
    folder.mkdir()
    monkeypatch.syspath_prepend(str(folder))
    monkeypatch.setenv("PYTHONPATH", str(folder))
    for registry in REGISTRIES.values():
        monkeypatch.setattr(registry, "components", dict(registry.components))
        monkeypatch.setattr(registry, "kind_parameter", registry.kind_parameter)
    monkeypatch.setattr(plugins, "_LOADED", dict(plugins._LOADED))
    monkeypatch.setattr(plugins, "_PROVIDERS", dict(plugins._PROVIDERS))
    monkeypatch.setattr(plugins, "_IN_USE", set(plugins._IN_USE))
    specs, by_name = list(schema.SPECS), dict(schema.SPEC_BY_NAME)
    modules = set(sys.modules)
    yield folder
    schema.SPECS[:] = specs
    schema.SPEC_BY_NAME.clear()
    schema.SPEC_BY_NAME.update(by_name)
    for name in set(sys.modules) - modules:
        if name.startswith("plug_"):
            del sys.modules[name]


def write(folder: Path, name: str, source: str) -> str:
    (folder / f"{name}.py").write_text(textwrap.dedent(source))
    return name


BAD = {  # name: (its modules' sources, the plug-in named, words of the one line)
    "import_error": ({"plug_broken": "import no_such_module_here\n"}, "plug_broken",
                     ("cannot import plug_broken", "ModuleNotFoundError")),
    "missing": ({}, "plug_absent", ("cannot import plug_absent", "ModuleNotFoundError")),
    "no_components": ({"plug_empty": "PLUGIN_API = 1\n"}, "plug_empty",
                      ("plug_empty.COMPONENTS is not a Component",)),
    "other_api": ({"plug_future": plugin_source("future", api="2")}, "plug_future",
                  ("declares PLUGIN_API = 2", "PLUGIN_API = 1")),
    "no_api": ({"plug_unversioned": "COMPONENTS = ()\n"}, "plug_unversioned",
               ("declares no PLUGIN_API",)),
    "shipped_kind": ({"plug_pid": plugin_source("pid", group="pid")}, "plug_pid",
                     ("clashes with the shipped controller kind pid",)),
    "other_plugins_kind": ({"plug_first": plugin_source("twin"),
                            "plug_second": plugin_source("twin")}, "plug_first,plug_second",
                           ("plug_second", "clashes with the controller kind twin of plug-in "
                                           "plug_first")),
    "state_clash": ({"plug_one": plugin_source("one"), "plug_two": plugin_source("two")},
                    "plug_one,plug_two", ("plug_two", "its state class State('error',) is "
                                          "named and shaped as kind one's")),
    "group": ({"plug_group": plugin_source("grouped", group="other")}, "plug_group",
              ("parameter other.kp is not in its group grouped.*",)),
    "schema_clash": ({"plug_run": plugin_source("run", group="run").replace(
        '"run.kp"', '"run.period"').replace("Gains, \"run\"", "Gains, \"x\"")}, "plug_run",
        ("parameter run.period is in the schema already",)),
    "no_outputs": ({"plug_silent": plugin_source("silent", outputs="()")}, "plug_silent",
                   ("declares its named outputs",)),
    "steps": ({"plug_steps": plugin_source("stepless", steps="(start, step)")}, "plug_steps",
              ("its steps are not ControllerSteps",)),
    "role": ({"plug_role": plugin_source("roleless", role="")}, "plug_role",
             ("give role='controller' or role='profile'",)),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_a_bad_plugin_is_refused_in_one_line_by_the_commands_and_in_process(
        plugin_folder, tmp_path, case):
    sources, named, words = BAD[case]
    kinds = {role: set(registry.components) for role, registry in REGISTRIES.items()}
    for name, source in sources.items():
        write(plugin_folder, name, source)
    bag = tmp_path / "bag"
    options = [item for name in named.split(",") for item in ("--plugin", name)]
    result = script("run_stack", *options, "--out", bag)
    one_line_exit_2(result, *words)
    assert result.stderr.startswith("error: --plugin: plug-in ")
    assert not bag.exists()
    scenario = tmp_path / "s.yaml"
    scenario.write_text(f"plugins: [{named}]\n/**:\n  ros__parameters:\n    run.duration: 1.0\n")
    with pytest.raises(ScenarioError) as refused:
        prepare(str(scenario))
    assert all(word in str(refused.value) for word in words)
    if case not in ("other_plugins_kind", "state_clash"):  # no refused plug-in's kind joined
        assert kinds == {role: set(registry.components) for role, registry in REGISTRIES.items()}


def test_a_scenario_names_its_plugins_and_one_built_on_it_inherits_them(plugin_folder,
                                                                         tmp_path):
    write(plugin_folder, "plug_good", plugin_source("good"))
    base = tmp_path / "base.yaml"
    base.write_text("plugins: [plug_good]\n/**:\n  ros__parameters:\n    run.duration: 20.0\n"
                    "controller:\n  ros__parameters:\n    controller.kind: good\n")
    derived = tmp_path / "derived.yaml"
    derived.write_text("base: base.yaml\ncontroller:\n  ros__parameters:\n    good.kp: 80.0\n")
    values = prepare(str(derived))
    assert values["run.plugins"] == "plug_good" and values["good.kp"] == 80.0
    assert schema.SPEC_BY_NAME["good.kp"].default == 50.0
    assert "good" in schema.SPEC_BY_NAME["controller.kind"].choices
    compiled, python = simulate(values), simulate(values, compiled=False)
    for name in python:
        np.testing.assert_array_equal(compiled[name], python[name], err_msg=name)
    # its declared output, recorded as a shipped kind's: r_k - y without preview
    np.testing.assert_array_equal(python["error"], python["target"] - python["measured_speed"])


def test_a_file_for_the_nodes_names_its_plugins_as_run_plugins(plugin_folder, tmp_path):
    write(plugin_folder, "plug_direct", plugin_source("direct"))
    scenario = tmp_path / "direct.yaml"
    scenario.write_text("/**:\n  ros__parameters:\n    run.plugins: plug_direct\n"
                        "controller:\n  ros__parameters:\n    controller.kind: direct\n"
                        "    direct.kp: 60.0\n")
    values = prepare(str(scenario), ["run.duration=1"])
    assert values["run.plugins"] == "plug_direct" and values["direct.kp"] == 60.0


def test_a_run_names_the_plugin_of_the_kind_it_uses(plugin_folder):
    write(plugin_folder, "plug_used", plugin_source("used"))
    schema.load_plugins("plug_used")
    assert prepare("seed000", ["run.duration=1"])["run.plugins"] == ""
    used = prepare("seed000", ["run.duration=1", "controller.kind=used", "used.kp=10"])
    assert used["run.plugins"] == "plug_used"
    assert "plug_used" in plugins.in_use()


def test_plugin_names_a_plugin_for_tune_and_without_it_its_parameters_are_unknown(
        plugin_folder, tmp_path):
    write(plugin_folder, "plug_tuned", plugin_source("tuned"))
    common = ["--scenario", "seed000", "--set", "controller.kind=tuned", "--set",
              "run.duration=5", "--in-process", "--algorithm", "pso", "--evaluations", "4",
              "--population", "2", "--params", "tuned.kp=1:100"]
    result = script("tune", "--plugin", "plug_tuned", *common, "--out", tmp_path / "t")
    assert result.returncode == 0, result.stderr
    assert "run.plugins: plug_tuned" in (tmp_path / "t" / "best.yaml").read_text()
    refused = script("tune", *common, "--out", tmp_path / "u")
    one_line_exit_2(refused, "tuned")
    assert not (tmp_path / "u").exists()


def test_a_dask_worker_without_the_plugin_is_named_in_one_line():
    from types import SimpleNamespace

    from ato_nodes.studies.dask_workers import check_plugins, importing
    answers = {"tcp://10.0.0.2:4000": importing(("plug_nowhere",)),
               "tcp://10.0.0.1:4000": ""}
    client = SimpleNamespace(run=lambda function, named: answers)
    with pytest.raises(ScenarioError) as refused:
        check_plugins(client, ("plug_nowhere",))
    line = str(refused.value)
    assert "\n" not in line and line.startswith("Dask worker tcp://10.0.0.2:4000 cannot import")
    assert "plug_nowhere" in line
    check_plugins(SimpleNamespace(run=None), ())  # no plug-ins: no question asked


@pytest.mark.slow
def test_the_smc_example_tracks_closer_than_the_pid_with_the_compiled_bits_of_python():
    """examples/ato-smc, installed (scripts/setup.sh): its kind found by its entry point."""
    from ato_nodes.api import score
    values = prepare("seed000", ["run.duration=120", "controller.kind=smc"])
    assert values["run.plugins"] == "ato_smc:SMC"
    compiled, python = simulate(values), simulate(values, compiled=False)
    for name in python:
        np.testing.assert_array_equal(compiled[name], python[name], err_msg=name)
    assert {"sliding_surface", "switching"} <= set(python)
    pid = prepare("seed000", ["run.duration=120", "controller.kind=pid"])
    assert score(python, values)["max_abs_error_kmh"] < score(simulate(pid), pid)[
        "max_abs_error_kmh"]


@pytest.mark.slow
def test_the_smc_example_is_tuned_in_process_and_studied_over_three_trains(tmp_path):
    tuned = script("tune", "--scenario", "seed000", "--set", "controller.kind=smc", "--set",
                   "run.duration=20", "--in-process", "--algorithm", "pso", "--evaluations", "4",
                   "--population", "2", "--out", tmp_path / "tune")
    assert tuned.returncode == 0, tuned.stderr
    assert "tuning the default search space: smc.integral_weight=" in tuned.stdout
    best = (tmp_path / "tune" / "best.yaml").read_text()
    assert "run.plugins: ato_smc:SMC" in best and "smc.gain" in best
    studied = script("robustness.py", "seed000", "--set", "controller.kind=smc", "--set",
                     "run.duration=20", "--samples", "3", "--out", tmp_path / "robust")
    assert studied.returncode == 0, studied.stderr
    assert "3 samples" in studied.stdout


@pytest.mark.integration
def test_a_plugin_on_pythonpath_runs_through_the_stack_and_its_bag_names_it(
        plugin_folder, tmp_path, monkeypatch):
    """The nodes import the run's plug-in (run.plugins in their parameter file) before they
    read their parameters; the bag keeps it, so a resimulation imports it again, and says
    in one line that it is missing where it is."""
    write(plugin_folder, "plug_stack", plugin_source("stacked"))
    bag = tmp_path / "bag"
    run = script("run_stack", "--plugin", "plug_stack", "--set", "controller.kind=stacked",
                 "--set", "stacked.kp=90", "--duration", "30", "--quiet", "--out", bag)
    assert run.returncode == 0, run.stderr
    from ato_nodes.bags.bagio import read_parameters, read_series
    parameters = read_parameters(bag)
    assert parameters["run.plugins"] == "plug_stack" and parameters["stacked.kp"] == 90.0
    values = prepare("seed000", ["controller.kind=stacked", "stacked.kp=90", "run.duration=30"])
    expected, recorded = simulate(values, compiled=False), read_series(bag)
    for name in ("command", "speed", "error"):
        np.testing.assert_array_equal(recorded[name], expected[name], err_msg=name)
    again = script("score_bag", bag, "--resimulate", "--json")
    assert again.returncode == 0 and '"resimulated_identical": true' in again.stdout
    monkeypatch.delenv("PYTHONPATH")
    missing = script("score_bag", bag, "--resimulate")
    one_line_exit_2(missing, "plug_stack", "cannot import")


@pytest.mark.integration
def test_the_smc_example_runs_through_the_stack_bit_identical_to_in_process(tmp_path):
    from ato_nodes.bags.bagio import read_parameters, read_series
    values = prepare("seed004-metro", ["controller.kind=smc", "run.duration=60"])
    run = script("run_stack", "--scenario", "seed004-metro", "--set", "controller.kind=smc",
                 "--duration", "60", "--quiet", "--out", tmp_path / "bag")
    assert run.returncode == 0, run.stderr
    assert read_parameters(tmp_path / "bag")["run.plugins"] == "ato_smc:SMC"
    expected, recorded = simulate(values), read_series(tmp_path / "bag")
    for name, series in expected.items():
        if name != "t":
            np.testing.assert_array_equal(recorded[name], series, err_msg=name)


@pytest.mark.slow
def test_a_dask_worker_that_cannot_import_the_studys_plugin_is_named_before_any_run(
        plugin_folder, tmp_path, monkeypatch):
    from dask_cluster import scheduler_and_workers
    write(plugin_folder, "plug_far", plugin_source("far"))
    monkeypatch.delenv("PYTHONPATH")  # the workers' environment: without it
    with scheduler_and_workers(tmp_path) as (address, _, _):
        monkeypatch.setenv("PYTHONPATH", str(plugin_folder))
        result = script("robustness.py", "seed000", "--plugin", "plug_far", "--set",
                        "controller.kind=far", "--set", "run.duration=5", "--samples", "3",
                        "--cluster", address, "--out", tmp_path / "study")
    one_line_exit_2(result, "Dask worker tcp://127.0.0.1:", "plug_far", "cannot import")
    assert not (tmp_path / "study").exists()


@pytest.mark.slow
def test_a_plugins_compiled_kind_is_cached_apart_and_compiled_again_when_its_sources_change(
        plugin_folder, monkeypatch):
    """Each in a process of its own, as the disk cache serves them: the plug-in's kind
    gives the Python loop's bits after its law changed (no machine code of the old law
    loaded), and a process without the plug-in still loads the shipped kinds' code."""
    import subprocess
    write(plugin_folder, "plug_cached", plugin_source("cached"))
    code = ("from ato_nodes.api import prepare, simulate; import numpy as np; "
            "v = prepare('seed000', {}); c, p = simulate(v), simulate(v, compiled=False); "
            "print(all(np.array_equal(c[k], p[k]) for k in p), repr(c['command'][-1]))")
    kind = "['run.plugins=plug_cached', 'controller.kind=cached', 'run.duration=2']"

    def run(overrides: str) -> list[str]:
        done = subprocess.run([sys.executable, "-c", code.format(overrides)], cwd=ROOT,
                              capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr
        return done.stdout.split()

    same, first = run(kind)
    law = plugin_folder / "plug_cached.py"
    law.write_text(law.read_text().replace("settings.kp * error", "2.0 * settings.kp * error"))
    same_again, second = run(kind)
    assert same == same_again == "True" and first != second
    monkeypatch.delenv("PYTHONPATH")
    assert run("['run.duration=2']")[0] == "True"


def test_an_override_names_a_plugin_whose_kind_the_same_overrides_choose(plugin_folder):
    write(plugin_folder, "plug_late", plugin_source("late"))
    values = prepare("seed000", ["run.plugins=plug_late", "controller.kind=late",
                                 "run.duration=1"])
    assert values["late.kp"] == 50.0 and values["run.plugins"] == "plug_late"
    again = prepare("seed000", {"run.plugins": "plug_late", "controller.kind": "late",
                                "late.kp": 7.0, "run.duration": 1.0})
    assert again["late.kp"] == 7.0


@pytest.mark.integration
def test_nodes_started_alone_import_the_plugins_their_parameter_file_names(plugin_folder,
                                                                           tmp_path):
    """`python -m ato_nodes.nodes.NODE --ros-args --params-file FILE`, no launcher: each
    node reads run.plugins first, then the plug-in's parameters as its own."""
    from test_plugins_stack import failed_nodes, start_nodes_directly

    from ato_nodes.bags.bagio import read_parameters, read_series
    write(plugin_folder, "plug_alone", plugin_source("alone"))
    scenario = tmp_path / "alone.yaml"
    scenario.write_text("/**:\n  ros__parameters:\n    run.plugins: plug_alone\n"
                        "    run.duration: 10.0\ncontroller:\n  ros__parameters:\n"
                        "    controller.kind: alone\n    alone.kp: 70.0\n")
    codes, errors, _ = start_nodes_directly(scenario, tmp_path / "bag", tmp_path / "r.json")
    assert set(codes.values()) == {0}, failed_nodes(codes, errors)
    assert read_parameters(tmp_path / "bag")["alone.kp"] == 70.0
    values = prepare(str(scenario))
    np.testing.assert_array_equal(read_series(tmp_path / "bag")["command"],
                                  simulate(values, compiled=False)["command"])
