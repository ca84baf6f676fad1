"""Scenario files, train presets and --set overrides: from what a user gives to the
complete, checked values of a run.

Scenario files are ROS 2 parameter files (node name -> ros__parameters, with
`/**` for the parameters several nodes share), so the same file feeds
`--params-file` and the in-process simulation. Everything is checked here,
before any process starts; every problem is one ScenarioError line. The plug-ins a run
names (a file's `plugins:` and run.plugins, an override's run.plugins) are imported in a
first pass, before anything else is read: their kinds' parameters are then the schema's.
"""

from __future__ import annotations

import difflib
from pathlib import Path
from typing import Any, NamedTuple

import yaml

from ..base import yamlfile
from ..base.errors import ScenarioError
from ..base.paths import config_dir, resolve_file
from ..base.spec import ParamSpec
from ..control.estimation import load_weighing
from ..control.limiter import CommandLimiter
from ..scoring.catalogue import Requirement
from ..train.lines import line_of
from ..train.ttobench import is_library_file, load_train
from . import plugins
from .components import CONTROLLERS
from .context import RunContext
from .faults import parse_fault
from .schema import (
    FILE_PARAMETERS,
    NODES,
    SPEC_BY_NAME,
    SPECS,
    NodeValues,
    defaults,
    load_plugins,
    retired,
    run_plugins,
    shared,
    unused,
)
from .timetables import check_journey


def _unknown(name: str, where: str) -> ScenarioError:
    close = difflib.get_close_matches(name, SPEC_BY_NAME, n=1)
    hint = f" (did you mean {close[0]}?)" if close else ""
    return ScenarioError(f"{where}: unknown parameter {name!r}{hint}")


def parameter_spec(name: str, value: Any, where: str) -> ParamSpec:
    """The spec of a parameter a file, --set or an override gives as `value`: a retired one
    (an old switch) is refused naming what to give instead, an unknown one naming the
    closest known."""
    line = retired(name, value)
    if line:
        raise ScenarioError(f"{where}: {line}")
    spec = SPEC_BY_NAME.get(name)
    if spec is None:
        raise _unknown(name, where)
    return spec


def scenario_names() -> list[str]:
    return sorted(p.stem for p in (config_dir() / "scenarios").glob("*.yaml"))


def preset_names() -> list[str]:
    """The shipped presets (msg_config/presets/NAME.yaml): parts of scenarios that
    scenarios build on (`base: NAME`), not runs of their own."""
    return sorted(p.stem for p in (config_dir() / "presets").glob("*.yaml"))


def resolve_scenario(name_or_file: str) -> Path:
    path = Path(name_or_file)
    if path.is_dir():
        raise ScenarioError(f"scenario {name_or_file} is a directory, not a scenario file")
    if path.suffix in (".yaml", ".yml") or path.exists():
        if not path.exists():
            raise ScenarioError(f"scenario file {name_or_file} does not exist")
        return path  # read as yamlfile reads it: a regular file, bounded
    candidate = config_dir() / "scenarios" / f"{name_or_file}.yaml"
    if candidate.is_file():
        return candidate
    raise ScenarioError(f"unknown scenario {name_or_file!r}; known: {', '.join(scenario_names())}")


def prepare(scenario: str, overrides: list[str] | dict[str, Any] = ()) -> dict[str, Any]:
    """A run's complete, checked values from a scenario (a name or a file) and overrides
    (--set texts, each name once, or a mapping): loaded, overridden, then validated once
    as a whole (validation builds the plan and the controller: once, not per stage)."""
    if not isinstance(overrides, dict):
        check_given_once(list(overrides))
    values, where = _loaded(scenario)
    if overrides:
        values, where = _overridden(values, overrides), "parameters"
    return validate(values, where)


def load_scenario(name_or_file: str) -> dict[str, Any]:
    """All parameters of a scenario: defaults overlaid with the file's values, checked.
    A file with a top-level `base: BASE` (a preset's name, msg_config/presets/; a
    scenario's; or a file relative to this one) holds only what differs from BASE, which
    may have a base of its own (tune.py's best.yaml on a scenario built on a preset)."""
    return validate(*_loaded(name_or_file))


def _loaded(name_or_file: str, chain: tuple[Path, ...] = ()) -> tuple[dict[str, Any], str]:
    """The scenario's values, each checked, and where they come from (for validate());
    `chain`: the files that build on it, each on the next (a base met twice is refused)."""
    path = resolve_scenario(name_or_file)
    if path.resolve() in chain:
        names = " -> ".join(str(link) for link in (*chain, path.resolve()))
        raise ScenarioError(f"{chain[0]}: its bases go round in a circle: {names}")
    document = yamlfile.load(path, "scenario")
    if not isinstance(document, dict):
        raise ScenarioError(f"{path}: expected a ROS 2 parameter file (node: ros__parameters: ...)")
    document = dict(document)
    base = document.pop("base", None)
    if base is not None and not isinstance(base, str):
        raise ScenarioError(f"{path}: base must be a preset, a scenario or a file, not {base!r}")
    # the base first: its plug-ins' kinds may be what this file sets parameters of
    base_values = None if base is None else _loaded(str(resolve_base(base, path)),
                                                    (*chain, path.resolve()))[0]
    named = _plugins_named(path, document)
    try:
        load_plugins(named)
    except ScenarioError as exc:
        raise ScenarioError(f"{path}: {exc}") from None
    given = _given_values(path, document)
    if named or base_values is not None and base_values["run.plugins"]:
        given["run.plugins"] = plugins.joined((*named, *plugins.references(
            base_values["run.plugins"] if base_values is not None else "")))
    if base_values is None:
        values = complete(given, [path.parent], str(path))
        check_not_derived(given, values, str(path))
        return values, str(path)
    given = resolved_files(given, [path.parent])
    try:
        return _overridden(base_values, given), str(path)
    except ScenarioError as exc:
        raise ScenarioError(f"{path}: {exc}") from None


def resolve_base(base: str, path: Path) -> Path:
    """The file a scenario file (`path`) names as its `base`: a file relative to it (a
    .yaml name), a shipped preset or a shipped scenario."""
    relative = path.parent / base
    if relative.suffix in (".yaml", ".yml"):
        return resolve_scenario(str(relative))
    preset = config_dir() / "presets" / f"{base}.yaml"
    if preset.is_file():
        return preset
    if (config_dir() / "scenarios" / f"{base}.yaml").is_file():
        return resolve_scenario(base)
    raise ScenarioError(f"{path}: unknown base {base!r}; presets: {', '.join(preset_names())}; "
                        f"scenarios: {', '.join(scenario_names())}")


def _plugins_named(path: Path, document: dict) -> tuple[str, ...]:
    """The plug-ins a scenario file names (`document` without its base): its top-level
    `plugins:` list (taken out of `document`) and its `/**` run.plugins (a file given
    to the nodes themselves says it so: ROS reads no `plugins:`)."""
    listed = document.pop("plugins", None) or []
    if not isinstance(listed, list) or not all(isinstance(name, str) for name in listed):
        raise ScenarioError(f"{path}: plugins must be a list of modules, e.g. "
                            f"plugins: [my_pkg.smc], not {listed!r}")
    section = document.get("/**")
    given = _flatten(section["ros__parameters"]).get("run.plugins", "") if isinstance(
        section, dict) and isinstance(section.get("ros__parameters"), dict) else ""
    spec = SPEC_BY_NAME["run.plugins"]
    named = [*plugins.references(spec.check(", ".join(listed), f"{path}: plugins")),
             *plugins.references(spec.check(given, str(path)))]
    return tuple(dict.fromkeys(named))


def _given_values(path: Path, document: dict) -> dict[str, Any]:
    """The parameters a scenario file gives (`document`, without its base), each checked
    against its spec and against the node it is given under."""
    given = {}
    for node, section in document.items():
        if node != "/**" and node not in NODES:
            raise ScenarioError(f"{path}: unknown node {node!r}; nodes are /**, {', '.join(NODES)}")
        if not isinstance(section, dict) or not isinstance(section.get("ros__parameters"), dict):
            raise ScenarioError(f"{path}: {node} needs a 'ros__parameters:' mapping")
        for name, value in _flatten(section["ros__parameters"]).items():
            spec = parameter_spec(name, value, str(path))
            if node != "/**" and node not in spec.nodes:
                raise ScenarioError(f"{path}: {name} belongs to {', '.join(spec.nodes)}, "
                                    f"not {node}")
            if node != "/**" and shared(spec):  # the other nodes would never see it
                raise ScenarioError(f"{path}: {name} is shared by {', '.join(spec.nodes)}: "
                                    f"give it under /**, not under {node}")
            value = spec.check(value, str(path))
            if name in given and given[name] != value:
                raise ScenarioError(f"{path}: {name} is given twice, as {given[name]!r} and "
                                    f"{value!r}")
            given[name] = value
    return given


def complete(given: dict[str, Any], bases: list[Path], where: str = "") -> dict[str, Any]:
    """Every value of a run from the given ones: the defaults, then the train preset's
    plant.* values (plant.train), then the given values; relative file parameters
    made absolute, from the first of `bases` that holds them, else from msg_config/.
    A given parameter of a kind the run does not use is refused (`where` names the
    source). The nodes complete what their parameter file gives them the same way, and
    take the derived parameters it gives (DERIVED_PARAMETERS: their launcher's)."""
    given = resolved_files(given, bases)
    values = defaults()
    if given.get("plant.train"):
        values.update(train_preset(given["plant.train"], given.get("plant.gravity")))
    values.update(given)
    check_used(given, values, where)
    return values


def resolved_files(given: dict[str, Any], bases: list[Path]) -> dict[str, Any]:
    """`given` with its file parameters absolute (FILE_PARAMETERS, and plant.train when it
    names a TTOBench train file), each from the first of `bases` that holds it, else from
    msg_config/ (core/base/paths.resolve_file)."""
    resolved = dict(given)
    for name in (*FILE_PARAMETERS, "plant.train"):
        if given.get(name) and (name != "plant.train" or is_library_file(given[name])):
            resolved[name] = resolve_file(given[name], bases)
    return resolved


def check_used(given, values: dict[str, Any], where: str = "") -> None:
    """Refuse a given parameter of a controller or profile kind the run (`values`) does
    not use: it would change nothing, and no node declares it."""
    idle = unused(values)
    for name in given:
        if name in idle:
            raise ScenarioError(f"{where}: {idle[name]}" if where else idle[name])


def train_names() -> list[str]:
    return sorted(p.stem for p in (config_dir() / "trains").glob("*.yaml"))


def train_preset(name: str, gravity: float | None = None) -> dict[str, Any]:
    """The plant.* values of a train, checked: msg_config/trains/NAME.yaml's (a flat
    mapping), or a TTOBench train file's (NAME a .json path, absolute: resolved_files)
    under `gravity` (plant.gravity, m/s^2; None: the schema's), plant.train its path."""
    if is_library_file(name):
        return ttobench_train(name, gravity)
    path = config_dir() / "trains" / f"{name}.yaml"
    if not path.is_file():
        raise ScenarioError(f"unknown train {name!r}; known: {', '.join(train_names())}")
    document = yamlfile.load(path, "train preset")
    if not isinstance(document, dict):
        raise ScenarioError(f"{path}: a train preset is a mapping of plant.* values")
    values = {}
    for key, value in document.items():
        spec = SPEC_BY_NAME.get(key)
        if spec is None or not key.startswith("plant.") or key == "plant.train":
            raise ScenarioError(f"{path}: {key!r} is not a plant parameter")
        values[key] = spec.check(value, str(path))
    return {**values, "plant.train": name}


def ttobench_train(path: str, gravity: float | None) -> dict[str, Any]:
    """The plant.* values of a TTOBench train file (core/train/ttobench.Train.plant_values
    under `gravity`, None: the schema's plant.gravity), each checked by its spec naming
    the file; one ScenarioError line for a missing or bad file."""
    if gravity is None:
        gravity = SPEC_BY_NAME["plant.gravity"].default
    values = {key: SPEC_BY_NAME[key].check(value, f"{path} as {key}")
              for key, value in load_train(path).plant_values(gravity).items()}
    return {**values, "plant.train": path}


def _flatten(mapping: dict, prefix: str = "") -> dict[str, Any]:
    """ROS parameter files may nest dotted names; flatten them back."""
    flat = {}
    for key, value in mapping.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(_flatten(value, name + "."))
        else:
            flat[name] = value
    return flat


def parse_override(text: str) -> tuple[str, Any]:
    """`name=value` with the value read as YAML (numbers, true/false, strings)."""
    name, sep, raw = text.partition("=")
    name = name.strip()
    if not sep or not name:
        raise ScenarioError(f"--set expects name=value, got {text!r}")
    try:
        value = yaml.safe_load(raw) if raw.strip() else ""
    except yaml.YAMLError:
        value = raw
    spec = parameter_spec(name, value, "--set")
    if spec.value_type is str and value is not None and not isinstance(value, str):
        value = raw.strip()
    elif spec.value_type is float and isinstance(value, str):  # YAML 1.1 reads 1e-9 as text
        try:
            value = float(value)
        except ValueError:
            pass
    return name, spec.check(value, "--set")


def check_given_once(texts: list[str]) -> None:
    """A user's --set list names each parameter once (which should win is not clear)."""
    seen = set()
    for text in texts:
        name = text.partition("=")[0].strip()
        if name in seen:
            raise ScenarioError(f"--set: {name} is given twice")
        seen.add(name)


def apply_overrides(values: dict[str, Any],
                    overrides: list[str] | dict[str, Any]) -> dict[str, Any]:
    """The run's `values` with `overrides` (--set texts, or a mapping) applied, checked as
    a whole; an override of a kind the run does not use (after the overrides: a new
    controller.kind's gains may come with it) is refused."""
    return validate(_overridden(values, overrides), "parameters")


def _overridden(values: dict[str, Any], overrides: list[str] | dict[str, Any]
                ) -> dict[str, Any]:
    """apply_overrides() without the validation of the whole."""
    load_plugins(values.get("run.plugins", ""))  # the run's own (a study's worker: not yet)
    named = _plugins_overridden(overrides)
    values = {**defaults(), **values}  # with the defaults of plug-ins loaded since
    if isinstance(overrides, dict):
        checked = {}
        for name, value in overrides.items():
            checked[name] = parameter_spec(name, value, "override").check(value, "override")
        overrides, where = checked, ""
    else:
        overrides = dict(parse_override(text) for text in overrides)  # the last one wins
        where = "--set"
    check_used(overrides, {**values, **overrides}, where)
    check_not_derived(overrides, {**values, **overrides}, where)
    # relative: from the working directory, else msg_config/
    overrides = resolved_files(overrides, [Path.cwd()])
    merged = {**values, **overrides}
    if named:  # added to the run's own
        merged["run.plugins"] = plugins.joined((*plugins.references(
            values.get("run.plugins", "")), *named))
    if overrides.get("plant.train"):  # a new train: its preset, then the other overrides
        merged.update(train_preset(overrides["plant.train"], merged["plant.gravity"]))
        merged.update(overrides)
    # another kind's parameters (a base's settings of the controller the scenario replaces)
    # go back to their defaults: a run holds only defaults for the kinds it does not use
    merged.update({name: SPEC_BY_NAME[name].default for name in unused(merged)})
    return merged


def _plugins_overridden(overrides: list[str] | dict[str, Any]) -> tuple[str, ...]:
    """The plug-ins an override's run.plugins names, imported before the other overrides
    are read (they may set the plug-ins' parameters)."""
    where = "override" if isinstance(overrides, dict) else "--set"
    if isinstance(overrides, dict):
        given = overrides.get("run.plugins", "")
    else:
        given = ", ".join(text.partition("=")[2] for text in overrides
                          if text.partition("=")[0].strip() == "run.plugins")
    named = plugins.references(SPEC_BY_NAME["run.plugins"].check(given, where))
    try:
        load_plugins(named)
    except ScenarioError as exc:
        raise ScenarioError(f"{where}: {exc}") from None
    return named


# Set by the launcher (ato_nodes.launcher.launch.Stack) for every run it starts, from the command's
# --out: a value given to run_stack.py or tune.py would be overridden without a word.
LAUNCHER_PARAMETERS = ("recorder.output", "supervisor.report")


def check_launcher_free(values: dict[str, Any]) -> None:
    """Refuse a launcher's parameter given by the user (one line naming --out)."""
    for name in LAUNCHER_PARAMETERS:
        if values[name]:
            raise ScenarioError(f"{name} is set by the launcher for each run it starts; give "
                                f"--out instead")


class Derivation(NamedTuple):
    """How validate() derives a parameter: when the parameter `switch` is on (true, or
    above 0), as `meaning` says (the error of a value given anyway quotes it), from the
    values of `sources` (named when the value derived is out of its schema's range)."""

    switch: str
    meaning: str
    sources: tuple[str, ...]


# Derived from the run's values by validate(), once, for every runner: the nodes that
# declare them cannot derive them (a profile or controller node does not see the real
# train's plant.mass_factor, the plant does not read the timetable), so every launcher
# passes them (launch.Stack with all the values, launch/stack.launch.py on top of the
# scenario file).
DERIVED_PARAMETERS = {
    "train.mass_reading": Derivation("train.load_weighing", "the load weighing's reading",
                                     ("plant.mass_factor", "train.load_weighing_bias",
                                      "train.load_weighing_error", "train.load_weighing_seed",
                                      "train.load_weighing_max")),
    "run.last_stop_position": Derivation("run.last_stop_hold", "the timetable's last mark "
                                         "less profile.journey.berth",
                                         ("profile.journey.timetable", "profile.journey.berth")),
}


def derived(values: dict[str, Any], name: str, value: Any) -> dict[str, Any]:
    """The values with the derived parameter `name` (DERIVED_PARAMETERS) set to `value`,
    checked against its schema as a given value is (the nodes check what they are
    passed): ScenarioError (one line naming the values it was derived from)."""
    try:
        SPEC_BY_NAME[name].check(value)
    except ScenarioError as exc:
        derivation = DERIVED_PARAMETERS[name]
        sources = ", ".join(f"{source}={values[source]:g}" if isinstance(values[source], float)
                            else f"{source}={values[source]}" for source in derivation.sources)
        raise ScenarioError(f"{exc}: {derivation.meaning}, from {sources}") from None
    return {**values, name: value}


def weighed(values: dict[str, Any]) -> dict[str, Any]:
    """The values with train.mass_reading the load weighing's reading of the real train
    (plant.mass_factor read train.load_weighing_bias off, its error drawn from
    train.load_weighing_seed, at most train.load_weighing_max) when train.load_weighing;
    else as they are. ScenarioError (one line) for a reading out of train.mass_reading's
    range."""
    if not values["train.load_weighing"]:
        return values
    biased = values["plant.mass_factor"] * (1.0 + values["train.load_weighing_bias"])
    reading = load_weighing(biased, values["train.load_weighing_error"],
                            values["train.load_weighing_seed"])
    ceiling = values["train.load_weighing_max"]
    return derived(values, "train.mass_reading", min(reading, ceiling) if ceiling else reading)


def at_last_stop(values: dict[str, Any], plan) -> dict[str, Any]:
    """The values with run.last_stop_position where the run's journey (`plan`) ends
    when run.last_stop_hold > 0; else as they are. ScenarioError (one line) for a hold
    on a run whose plan has no last stop (not a journey)."""
    if values["run.last_stop_hold"] <= 0.0:
        return values
    if plan.journey_end is None:
        raise ScenarioError(f"run.last_stop_hold ends a journey's run at its last stop; "
                            f"profile.kind {values['profile.kind']} has no stops (give 0, or "
                            "profile.kind journey)")
    return derived(values, "run.last_stop_position", plan.journey_end)


def check_not_derived(given, values: dict[str, Any], where: str = "") -> None:
    """Refuse a derived parameter given while the run derives it (one line)."""
    for name, derivation in DERIVED_PARAMETERS.items():
        switch = values[derivation.switch]
        if switch and name in given:
            prefix = f"{where}: " if where else ""
            on = "true" if isinstance(switch, bool) else "above 0"
            raise ScenarioError(f"{prefix}{name} is {derivation.meaning} when "
                                f"{derivation.switch} is {on}: give one of them")


def validate(values: dict[str, Any], where: str) -> dict[str, Any]:
    """Check a run's values as a whole before anything starts, by building what the
    nodes will build (each from the values its node declares, as the run's stages
    do): the line (errors name file and line), the context's plan and the controller
    (errors name the parameter). Returns them with the derived parameters
    (DERIVED_PARAMETERS) set."""
    if values["run.duration"] < values["run.period"]:
        raise ScenarioError(f"{where}: run.duration must be at least one run.period")
    try:
        load_plugins(values["run.plugins"])
        values = {**values, "run.plugins": run_plugins(values)}
        values = weighed(values)
        parse_fault(values["run.fault"])
        Requirement.parse_list(values["report.require"], "report.require")
    except ScenarioError as exc:
        raise ScenarioError(f"{where}: {exc}") from None
    line = line_of(values)
    if values["estimator.enabled"] and not CONTROLLERS.chosen(values).estimates:
        raise ScenarioError(f"{where}: estimator.enabled: controller.kind "
                            f"{values['controller.kind']} does not use the on-board estimator "
                            f"(those that do: {', '.join(estimating_kinds())})")
    try:
        check_replan(values, CONTROLLERS.chosen(values).output_names)
        check_journey(values, line)  # before the plan: its curves then never evict the plan's
        profile = RunContext(NodeValues("profile", values), line)
        # a berth or a departure ramp where the plan has no such stop or start: refused now
        _ = profile.berth_mark, profile.departure
        values = at_last_stop(values, profile.plan)
        controller_values = NodeValues("controller", values)
        CONTROLLERS.chosen(controller_values).factory(
            controller_values, RunContext(controller_values, line),
            CommandLimiter.from_values(controller_values))
    except ScenarioError as exc:
        raise ScenarioError(f"{where}: {exc}") from None
    plugins.note_in_use(plugins.references(values["run.plugins"]))
    return values


def check_replan(values, output_names: tuple[str, ...]) -> None:
    """Refuse profile.replan.enabled without the estimate it reads, profile.degraded.enabled
    without the localisation that sees the adhesion (one line)."""
    if values["profile.degraded.enabled"] and not (
            values["odometry.enabled"]
            and (values["odometry.accelerometer"] or values["odometry.radar"])):
        raise ScenarioError("profile.degraded.enabled reads the adhesion from the slips and "
                            "slides the localisation sees: it needs odometry.enabled true and "
                            "odometry.accelerometer or odometry.radar true")
    if not values["profile.replan.enabled"]:
        return
    if not values["estimator.enabled"]:
        raise ScenarioError("profile.replan.enabled plans from the on-board estimate: it needs "
                            "estimator.enabled true")
    if not {"mass_factor", "mass_sigma"} <= set(output_names):
        raise ScenarioError(f"profile.replan.enabled reads the controller's mass estimate; "
                            f"controller.kind {values['controller.kind']} has none (those that "
                            f"have: {', '.join(estimating_kinds())})")


def estimating_kinds() -> tuple[str, ...]:
    return tuple(kind for kind, component in CONTROLLERS.components.items()
                 if component.estimates)


def ros_parameter_file(values: dict[str, Any], names=None) -> dict[str, Any]:
    """The values (those of `names`, default all the run uses: none of the kinds it does
    not use) as a ROS 2 parameter file: shared parameters under /**, the others under
    the one node that declares each; sections left empty are left out when `names` is
    given."""
    document: dict[str, Any] = {"/**": {"ros__parameters": {}}}
    for node in NODES:
        document[node] = {"ros__parameters": {}}
    idle = unused(values)
    for spec in SPECS:
        if (names is not None and spec.name not in names) or spec.name in idle:
            continue
        if spec.nodes:
            section = "/**" if shared(spec) else spec.nodes[0]
            document[section]["ros__parameters"][spec.name] = values[spec.name]
    if names is not None:
        document = {node: section for node, section in document.items()
                    if section["ros__parameters"]}
    return document
