"""Fault injection (run.fault), for testing supervision."""

from __future__ import annotations

from .errors import ScenarioError

FAULT_NODES = ("profile", "plant", "controller", "recorder")


def parse_fault(text: str) -> tuple[str, str, int] | None:
    """run.fault as (node, 'crash' | 'hang', step), or None when empty."""
    if not text:
        return None
    parts = text.split(":")
    if (len(parts) != 3 or parts[0] not in FAULT_NODES or parts[1] not in ("crash", "hang")
            or not parts[2].isdigit()):
        raise ScenarioError(f"run.fault must be NODE:crash|hang:STEP with NODE one of "
                            f"{', '.join(FAULT_NODES)}; got {text!r}")
    return parts[0], parts[1], int(parts[2])
