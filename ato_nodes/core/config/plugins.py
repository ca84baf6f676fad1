"""Plug-ins: controller and target-profile kinds registered from outside the package.

A plug-in is a module of any installed package (or on sys.path) that declares the
interface it is written against (`PLUGIN_API = 1`, core/base/registry.py) and holds its
kinds: `COMPONENTS`, a tuple of Components, each with its `role` ("controller" or
"profile"). A run names a plug-in by reference, `module` (its COMPONENTS) or
`module:attribute` (a Component, or a tuple of them); an installed package declares its
plug-ins as entry points (ENTRY_POINT_GROUPS, each naming a Component or a module),
which every process imports with the first plug-in it loads (core/config/schema.py's
load_plugins: the first run it checks or builds).

Each kind is checked as a shipped kind is before it joins its registry: a new kind name;
parameters of its own group (`KIND.*` for a controller, `profile.KIND.*` for a profile)
that the schema does not have, declared by the registry's nodes, each default valid;
a controller's named outputs and, if it runs compiled, its ControllerSteps. Every
problem is one ScenarioError line, and a refused plug-in registers none of its kinds.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import re
import sys
from collections.abc import Iterable, Mapping

from ..base.errors import ScenarioError
from ..base.registry import PLUGIN_API, Component, Output, Registry
from ..base.spec import ParamSpec, TextForm
from ..control.stepped import ControllerSteps
from .components import REGISTRIES

ENTRY_POINT_GROUPS = {"controller": "ato_nodes.controllers", "profile": "ato_nodes.profiles"}
_NAME = r"[A-Za-z_]\w*"
_REFERENCE = rf"{_NAME}(?:\.{_NAME})*(?::{_NAME}(?:\.{_NAME})*)?"
REFERENCES_FORM = TextForm(rf"\s*|\s*{_REFERENCE}\s*(?:,\s*{_REFERENCE}\s*)*",
                           "plug-in modules (MODULE or MODULE:ATTRIBUTE) separated by "
                           "commas, e.g. 'my_pkg.smc, other_pkg:KIND'")
KIND_NAME = re.compile(r"[a-z][a-z0-9_]*")

# This process's plug-ins: each reference loaded with its kinds, who registered each
# (role, kind), and the references of the runs it checked (a Dask study's workers must
# import them: studies/dask_workers.py).
_LOADED: dict[str, tuple[Component, ...]] = {}
_PROVIDERS: dict[tuple[str, str], str] = {}
_IN_USE: set[str] = set()
_PENDING: list[tuple[str, str]] = []  # the entry points (reference, role) not loaded yet
_READ: list[bool] = []  # [True] once the entry points are read


def references(text: str) -> tuple[str, ...]:
    """The references of a run.plugins text ('a.b, c:D'), each once, in order."""
    named = [part.strip() for part in text.split(",") if part.strip()]
    return tuple(dict.fromkeys(named))


def joined(named: Iterable[str]) -> str:
    """run.plugins's text for `named`: each once, sorted (every launcher writes the same)."""
    return ", ".join(sorted(set(named)))


def provider(role: str, kind: str) -> str | None:
    """The reference of the plug-in that registered `kind` in `role`'s registry (None: a
    shipped kind)."""
    return _PROVIDERS.get((role, kind))


def note_in_use(named: Iterable[str]) -> None:
    _IN_USE.update(named)


def in_use() -> tuple[str, ...]:
    """The plug-ins of the runs this process checked (what its workers must import)."""
    return tuple(sorted(_IN_USE))


def load(named: Iterable[str], schema_names: Mapping[str, object]) -> bool:
    """Import and register the installed plug-ins (those not yet) and those `named`; True
    if a kind joined a registry. `schema_names`: the schema's parameter names now (a
    plug-in's may not be one of them). ScenarioError (one line) for a plug-in refused: an
    installed one refused stays pending, so every later load says it again."""
    if not _READ:
        _PENDING.extend(installed())
        _READ.append(True)
    joined_any = False
    for reference, role in list(_PENDING):
        if _initializing(reference):  # it imports ato_nodes as it starts: joins next time
            continue
        joined_any |= _load(reference, schema_names, role)
        _PENDING.remove((reference, role))
    for reference in named:
        joined_any |= _load(reference, schema_names, None)
    return joined_any


def _initializing(reference: str) -> bool:
    """The reference's module, or a package of it, is being imported now (a process whose
    first import is the plug-in: it imports ato_nodes, whose schema loads the installed
    plug-ins)."""
    parts = reference.partition(":")[0].split(".")
    for depth in range(1, len(parts) + 1):
        spec = getattr(sys.modules.get(".".join(parts[:depth])), "__spec__", None)
        if getattr(spec, "_initializing", False):
            return True
    return False


def installed() -> list[tuple[str, str]]:
    """(reference, role) of each entry point of ENTRY_POINT_GROUPS, in name order."""
    found, points = [], importlib.metadata.entry_points()  # read once (every dist)
    for role, group in ENTRY_POINT_GROUPS.items():
        for point in sorted(points.select(group=group), key=lambda p: p.name):
            found.append((point.value.replace(" ", ""), role))
    return found


def _load(reference: str, schema_names: Mapping[str, object], role: str | None) -> bool:
    if reference in _LOADED:
        return False
    components = components_of(reference)
    # a kind registered already by another reference to it (an entry point and the
    # module named in a scenario) is the same kind, once
    fresh = [component for component in components if component.role not in REGISTRIES
             or REGISTRIES[component.role].components.get(component.kind) is not component]
    names = set(schema_names)
    kinds: set[tuple[str, str]] = set()
    for component in fresh:
        check(component, reference, role, names, kinds)
        names.update(spec.name for spec in component.parameters)
        kinds.add((component.role, component.kind))
    for component in fresh:
        REGISTRIES[component.role].add(component)
        _PROVIDERS[(component.role, component.kind)] = reference
    _LOADED[reference] = components
    return bool(fresh)


def components_of(reference: str) -> tuple[Component, ...]:
    """The Components a reference names: its module imported, its PLUGIN_API checked."""
    if not re.fullmatch(_REFERENCE, reference):
        raise ScenarioError(f"plug-in {reference!r}: expected MODULE or MODULE:ATTRIBUTE")
    module_name, _, attribute = reference.partition(":")
    try:
        module = importlib.import_module(module_name)
    except Exception as exc:  # whatever its code raises: one line that names it
        said = " ".join(str(exc).split())
        raise ScenarioError(f"plug-in {reference}: cannot import {module_name}: "
                            f"{type(exc).__name__}: {said}") from None
    declared = getattr(module, "PLUGIN_API", None)
    if declared != PLUGIN_API:
        said = "declares no PLUGIN_API" if declared is None else \
            f"declares PLUGIN_API = {declared!r}"
        raise ScenarioError(f"plug-in {reference}: {module_name} {said}; this ato_nodes "
                            f"runs plug-ins written for PLUGIN_API = {PLUGIN_API}")
    found = module
    for part in (attribute.split(".") if attribute else ["COMPONENTS"]):
        found = getattr(found, part, None)
    if isinstance(found, Component):
        found = (found,)
    if not (isinstance(found, (tuple, list)) and found
            and all(isinstance(component, Component) for component in found)):
        what = attribute or "COMPONENTS"
        raise ScenarioError(f"plug-in {reference}: {module_name}.{what} is not a Component or "
                            f"a non-empty tuple of them (ato_nodes.plugin.Component)")
    return tuple(found)


def check(component: Component, reference: str, role: str | None, names: set[str],
          kinds: set[tuple[str, str]]) -> None:
    """Refuse (ScenarioError, one line) a plug-in's kind that could not run as a shipped
    one does; `names` the parameter names taken, `kinds` those the plug-in registers
    before this one."""
    where = f"plug-in {reference}: {component.role or '?'} kind {component.kind!r}"
    if component.role not in REGISTRIES:
        raise ScenarioError(f"{where}: its role is {component.role!r}; give role='controller' "
                            f"or role='profile'")
    if role is not None and component.role != role:
        raise ScenarioError(f"{where}: it is in the entry-point group "
                            f"{ENTRY_POINT_GROUPS[role]}, not {ENTRY_POINT_GROUPS[component.role]}")
    registry = REGISTRIES[component.role]
    if not KIND_NAME.fullmatch(component.kind):
        raise ScenarioError(f"{where}: a kind is lower-case letters, digits and _")
    _check_kind_is_new(component, registry, where, kinds)
    _check_parameters(component, registry, where, names)
    if not callable(component.factory):
        raise ScenarioError(f"{where}: its factory is not callable")
    if component.role == "controller":
        _check_controller(component, where)
        _check_state_is_its_own(component, registry, where)
    elif component.outputs or component.steps is not None:
        raise ScenarioError(f"{where}: a profile has no outputs and no steps")


def _check_kind_is_new(component: Component, registry: Registry, where: str,
                       kinds: set[tuple[str, str]]) -> None:
    if (component.role, component.kind) in kinds:
        raise ScenarioError(f"{where}: the plug-in registers this kind twice")
    if component.kind in registry.shipped_kinds:
        raise ScenarioError(f"{where}: clashes with the shipped {registry.role} kind "
                            f"{component.kind}; choose another name")
    if component.kind in registry.components:
        raise ScenarioError(f"{where}: clashes with the {registry.role} kind "
                            f"{component.kind} of plug-in "
                            f"{provider(registry.role, component.kind)}")


def _check_parameters(component: Component, registry: Registry, where: str,
                      names: set[str]) -> None:
    group = component.kind if registry.role == "controller" else f"profile.{component.kind}"
    own = set()
    for spec in component.parameters:
        if not isinstance(spec, ParamSpec):
            raise ScenarioError(f"{where}: its parameters are ParamSpecs (ato_nodes.plugin."
                                f"param), not {type(spec).__name__}")
        if not spec.name.startswith(f"{group}.") or spec.name == f"{group}.":
            raise ScenarioError(f"{where}: parameter {spec.name} is not in its group "
                                f"{group}.* (named after the kind)")
        if spec.name in names or spec.name in own:
            raise ScenarioError(f"{where}: parameter {spec.name} is in the schema already")
        if set(spec.nodes) != set(registry.nodes):
            raise ScenarioError(f"{where}: parameter {spec.name} is declared by "
                                f"{', '.join(spec.nodes) or 'no node'}; a {registry.role} "
                                f"kind's are declared by {', '.join(registry.nodes)}")
        spec.check(spec.default, f"{where}: the default of")
        own.add(spec.name)
    for name, low, high in component.search_space:
        if name not in own or not low < high:
            raise ScenarioError(f"{where}: its search_space entry ({name}, {low}, {high}) is "
                                f"not one of its parameters with low < high")


def _check_controller(component: Component, where: str) -> None:
    outputs = component.outputs
    if not outputs or not all(isinstance(output, Output) for output in outputs):
        raise ScenarioError(f"{where}: a controller declares its named outputs "
                            f"(a non-empty tuple of ato_nodes.plugin.Output)")
    names = [output.name for output in outputs]
    if len(set(names)) != len(names) or not all(re.fullmatch(_NAME, n) for n in names):
        raise ScenarioError(f"{where}: its outputs' names are identifiers, each once: "
                            f"{', '.join(names)}")
    steps = component.steps
    if steps is not None and not (isinstance(steps, ControllerSteps) and callable(steps.start)
                                  and callable(steps.step)
                                  and hasattr(steps.state_type, "_fields")):
        raise ScenarioError(f"{where}: its steps are not ControllerSteps(start, step, "
                            f"state NamedTuple type) (ato_nodes.plugin.ControllerSteps)")


def _check_state_is_its_own(component: Component, registry: Registry, where: str) -> None:
    """numba tells NamedTuple classes apart by name and fields only: a state class named and
    shaped as another kind's would run that kind's compiled loop."""
    state = getattr(component.steps, "state_type", None)
    for other in registry.components.values():
        theirs = getattr(other.steps, "state_type", None)
        if (state is not None and theirs is not None and theirs is not state
                and theirs.__name__ == state.__name__ and theirs._fields == state._fields):
            raise ScenarioError(f"{where}: its state class {state.__name__}{state._fields} is "
                                f"named and shaped as kind {other.kind}'s; compiled code would "
                                f"run {other.kind}'s loop for it: give it a name of its own")
