"""Plug-in registries: the one place that maps a component's `kind` to its factory,
its parameter group and, for controllers, its named outputs; and what a controller
and a plan are (Controller, Plan: the interfaces every kind implements).

A component kind is registered once (core/config/components.py lists them); the
schema takes its parameters from here, the loop its factory, the nodes and
the recorder its outputs, the scorer what it says of its observer. Nothing
else compares kind names.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass
from collections.abc import Sequence
from typing import Any, Callable, Protocol, runtime_checkable

from .errors import ScenarioError
from .spec import ParamSpec, param


@dataclass(slots=True)
class ControllerOutput:
    """One control step: the command (N/kN) and the values of the controller's
    declared outputs, in the order of its registry entry."""

    u: float
    extras: tuple[float, ...]


@runtime_checkable
class Controller(Protocol):
    """A controller kind, as its registry entry's factory builds it. The loop calls
    start() once, before the first step, then step() once per control period; what
    it reports besides the command is declared by the entry's `outputs`, and what it
    carries from step to step (for a live change of gains) by its `state_paths`."""

    def start(self, target: float, measured: float, horizon: Sequence[float]) -> None:
        """Initialise the state from the first step's target r_0, measured speed and
        horizon r_0 .. r_N (m/s)."""

    def step(self, target: float, measured: float, horizon: Sequence[float]
             ) -> ControllerOutput:
        """The command for one period: `target` the plan's speed now, r_k (m/s),
        `measured` the sensor's speed (m/s), `horizon` the plan's targets r_k .. r_k+N
        (N = controller.preview; horizon[0] is `target`). A kind that tracks ahead reads
        horizon[-1] itself: `target` means r_k whatever the preview."""


@runtime_checkable
class Plan(Protocol):
    """A target profile, as its registry entry's factory builds it: the planned speed
    at a time and position."""

    # Indexed by position (the target follows where the train is, not the clock).
    position_indexed: bool
    # Applies profile.envelope_share and profile.jerk itself (else the run context
    # wraps a time-indexed plan in core/targets/profiles.FeasiblePlan).
    shapes_itself: bool = False
    # Has belt limits of its own (limit()), which replace the line's speed limits.
    limits_speed: bool = False
    # One line the profile node says at start-up (a planned time the plan cannot meet).
    notice: str | None = None
    # Where a train standing has ended the plan's journey, m (a journey's last mark less
    # its berth; None: a plan without stops). run.last_stop_hold ends the run there.
    journey_end: float | None = None

    def speed(self, t: float, position: float = 0.0) -> float:
        """The target at time t (s) with the head at `position` (m), m/s."""

    def limit(self, position: float) -> float:
        """The plan's own speed limit at `position`, m/s (only if limits_speed)."""
        raise NotImplementedError(f"{type(self).__name__} has no speed limits of its own")

    def table(self) -> Any:
        """A position-indexed plan as the table compiled code reads (a PlanTable of
        core/targets/profiles.py), or None: a position-indexed plan without one is refused
        (RunContext.profile_settings). Time-indexed plans need none (their targets are
        computed once per plan)."""
        return None


@dataclass(frozen=True)
class Output:
    """A named value a controller reports every step besides its command."""

    name: str
    unit: str
    description: str


@dataclass(frozen=True)
class Component:
    """One registered kind.

    factory(values, context, **extra) builds it from the run's values (a mapping
    that holds exactly what the node declares) and the read-only RunContext.
    observer_gain(values), for controllers with a third-order extended state
    observer whose outputs z1, z2, z3 estimate speed, acceleration and total
    disturbance: the observer's input gain b0 in m/s^3 per N/kN, which the
    scorer needs to rebuild the disturbance z3 estimates. search_space: the
    (parameter, low, high) that tune.py tunes when given no --params. state_paths, for
    controllers: the attribute paths of what the controller carries from step to step
    (observer, filters, integrators); with it, the kind's own float parameters are live
    during a run: a change rebuilds the controller with the new values and carries
    the state over (stages.ControllerStage.retune). Without it none are.
    steps, for controllers whose step is a plain function of NamedTuples: their
    core/control/stepped.ControllerSteps, which the compiled loop runs too
    (core/run/fast_loop.py); without it the compiled loop calls the kind's own Python
    step. warm_up, for controllers: the (parameter, value) overrides of a cheap run of
    the kind (no file to read, short horizons), with which loop.warm() compiles the
    kind's loop (or the one signature that every kind without steps shares).
    estimates, for controllers: the kind uses the on-board estimator of the train
    (core/control/estimation.py) when estimator.enabled; a run that enables it for a kind
    that does not is refused.
    """

    kind: str
    description: str
    parameters: tuple[ParamSpec, ...]
    factory: Callable[..., Any]
    outputs: tuple[Output, ...] = ()
    observer_gain: Callable[[Any], float] | None = None
    search_space: tuple[tuple[str, float, float], ...] = ()  # what tune.py tunes by default
    state_paths: tuple[str, ...] = ()  # carried over when live parameters change (controllers)
    steps: Any = None  # ControllerSteps: what the Python and the compiled loop run
    warm_up: tuple[tuple[str, Any], ...] = ()  # overrides of a cheap run (controllers)
    estimates: bool = False  # controllers: uses the on-board estimator (estimator.enabled)

    @property
    def live_parameters(self) -> tuple[str, ...]:
        """Its own parameters that may change during a run (see `state_paths`)."""
        return tuple(spec.name for spec in self.parameters
                     if self.state_paths and spec.value_type is float)

    @property
    def output_names(self) -> tuple[str, ...]:
        return tuple(output.name for output in self.outputs)

    @property
    def own_parameters(self) -> str:
        """Its parameter group, as a person reads it: 'dadrc.*'."""
        if not self.parameters:
            return "it has no parameters of its own"
        return f"its parameters are {self.parameters[0].name.rsplit('.', 1)[0]}.*"


class Registry:
    """The kinds of one component role; `role.kind` chooses among them."""

    def __init__(self, role: str, default: str, nodes: tuple[str, ...],
                 components: tuple[Component, ...]):
        self.role, self.nodes = role, nodes
        self.components = {component.kind: component for component in components}
        if len(self.components) != len(components) or default not in self.components:
            raise ValueError(f"{role} registry: duplicate kinds or unknown default {default!r}")
        self.kind_parameter = param(
            f"{role}.kind", default, f"{role} kind: " + "; ".join(
                f"{c.kind} ({c.description})" for c in components), nodes,
            choices=tuple(self.components))

    def __getitem__(self, kind: str) -> Component:
        try:
            return self.components[kind]
        except KeyError:
            close = difflib.get_close_matches(kind, self.components, n=1)
            hint = f" (did you mean {close[0]}?)" if close else ""
            raise ScenarioError(f"unknown {self.role}.kind {kind!r}{hint}; known: "
                                f"{', '.join(self.components)}") from None

    def chosen(self, values) -> Component:
        return self[values[self.kind_parameter.name]]

    def unused(self, values) -> dict[str, str]:
        """The parameters of the kinds `values` does not choose, each with the line that
        says whose they are: a run declares none of them, and a scenario or an override
        that gives one is refused (it would change nothing). Empty when `values` does not
        say which kind runs (a node that does not declare `role.kind` has none of them)."""
        name = self.kind_parameter.name
        if name not in values:
            return {}
        chosen = self[values[name]]
        # by name: a spec compared with each of the chosen kind's, field by field, costs
        # ~2 ms a run (every node's values ask)
        own = {spec.name for spec in chosen.parameters}
        return {spec.name: f"{spec.name} belongs to {self.role} kind {component.kind}; this "
                           f"run uses {chosen.kind} ({chosen.own_parameters})"
                for component in self.components.values() if component is not chosen
                for spec in component.parameters if spec.name not in own}

    def parameters(self) -> tuple[ParamSpec, ...]:
        # once each: a kind may take another's too (a journey drives ato curves)
        own = {spec.name: spec for component in self.components.values()
               for spec in component.parameters}
        return (self.kind_parameter, *own.values())
