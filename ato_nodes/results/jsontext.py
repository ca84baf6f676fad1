"""JSON as every strict parser reads it: a value that was not measured (NaN) or is
unbounded (inf) is written as null, never as the bare NaN / Infinity tokens that
Python's json module emits by default and JSON.parse refuses."""

from __future__ import annotations

import json
import math
from typing import Any


def finite_or_null(value: Any) -> Any:
    """The value with every non-finite float (numpy's included) replaced by None,
    through dicts, lists and tuples."""
    if isinstance(value, dict):
        return {key: finite_or_null(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite_or_null(item) for item in value]
    if isinstance(value, float) and not math.isfinite(value):  # numpy.float64 is a float
        return None
    if hasattr(value, "dtype") and getattr(value, "ndim", None) == 0:  # other numpy scalars
        return finite_or_null(value.item())
    return value


def dumps(value: Any, **options: Any) -> str:
    """json.dumps with non-finite numbers as null (and refused if any slipped through)."""
    return json.dumps(finite_or_null(value), allow_nan=False, **options)
