"""One parameter of the schema: name, default, type, range or choices, unit, owners.

A default is written only here, in a ParamSpec; configuration objects of the
core (gains, train parameters, profiles) are built from the schema's values.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, fields
from typing import Any

from .errors import ScenarioError


@dataclass(frozen=True)
class TextForm:
    """The form a string parameter's value must have: a regular expression the whole
    value matches, and the same said for a person (the error names it)."""

    pattern: str
    wording: str


@dataclass(frozen=True)
class ParamSpec:
    name: str
    default: Any
    description: str             # with the unit
    nodes: tuple[str, ...]       # the nodes that declare it
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] | None = None
    form: TextForm | None = None  # what a string must look like

    @property
    def value_type(self) -> type:
        return type(self.default)

    def check(self, value: Any, where: str = "") -> Any:
        """Return `value` converted to this parameter's type, or raise ScenarioError."""
        prefix = f"{where}: " if where else ""
        value_type = self.value_type
        if value_type is bool:
            if not isinstance(value, bool):
                raise ScenarioError(f"{prefix}{self.name} must be true or false, not {value!r}")
        elif value_type is int:
            if isinstance(value, bool) or not isinstance(value, int):
                raise ScenarioError(f"{prefix}{self.name} must be an integer, not {value!r}")
        elif value_type is float:
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ScenarioError(f"{prefix}{self.name} must be a number, not {value!r}")
            value = float(value)
            if not math.isfinite(value):
                raise ScenarioError(f"{prefix}{self.name} must be finite, not {value!r}")
        elif not isinstance(value, str):
            raise ScenarioError(f"{prefix}{self.name} must be a string, not {value!r}")
        if self.choices is not None and value not in self.choices:
            raise ScenarioError(f"{prefix}{self.name} must be one of {', '.join(self.choices)}; "
                                f"got {value!r}")
        if self.form is not None and not re.fullmatch(self.form.pattern, value):
            raise ScenarioError(f"{prefix}{self.name} must be {self.form.wording}, "
                                f"not {value!r}")
        if self.low is not None and not (self.low <= value <= self.high):
            raise ScenarioError(f"{prefix}{self.name} = {value} is out of range "
                                f"[{self.low:g}, {self.high:g}]")
        return value


def param(name: str, default: Any, description: str, nodes: str | tuple[str, ...],
          low: float | None = None, high: float | None = None,
          choices: tuple[str, ...] | None = None, form: TextForm | None = None) -> ParamSpec:
    if isinstance(nodes, str):
        nodes = (nodes,)
    return ParamSpec(name, default, description, tuple(nodes), low, high, choices, form)


def settings(cls, group: str, values) -> Any:
    """A configuration dataclass or NamedTuple whose fields are the parameters
    `group.<field>`."""
    names = cls._fields if hasattr(cls, "_fields") else [f.name for f in fields(cls)]
    return cls(**{name: values[f"{group}.{name}"] for name in names})


# The read-only run context (core/config/context.py) holds the nominal train and the planned
# target, so the nodes whose components receive it declare those parameters too.
PLANT_NODES = ("plant", "profile", "controller")
MAX_PREVIEW = 1000  # steps: the longest target horizon a controller may ask for
PROFILE_NODES = ("profile", "controller")
