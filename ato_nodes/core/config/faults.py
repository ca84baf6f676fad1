"""Fault injection (run.fault), for testing supervision."""

from __future__ import annotations

from ..base.errors import ScenarioError
from .schema import SUPERVISED_NODES

FAULT_NODES = SUPERVISED_NODES  # not the supervisor: it reports what the faults do
FAULT_KINDS = ("crash", "hang", "kill", "diskfull")


def parse_fault(text: str) -> tuple[str, str, int] | None:
    """run.fault as (node, kind, step), or None when empty. Kinds: crash (an exception),
    hang (deaf to SIGINT and SIGTERM), kill (SIGKILL of itself), diskfull (the node's
    file writes fail from then on)."""
    if not text:
        return None
    parts = text.split(":")
    if (len(parts) != 3 or parts[0] not in FAULT_NODES or parts[1] not in FAULT_KINDS
            or not parts[2].isdigit()):
        raise ScenarioError(f"run.fault must be NODE:{'|'.join(FAULT_KINDS)}:STEP with NODE one "
                            f"of {', '.join(FAULT_NODES)}; got {text!r}")
    return parts[0], parts[1], int(parts[2])
