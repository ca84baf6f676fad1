"""A run's summary.json: how the run ended and what its bag holds, with the indices (a
journey's per station: ato_nodes.results.journeys.score_run).

Written into the bag directory by whoever ran the run: scripts/run_stack.py after
its launcher stopped every node, or the supervisor node itself when no launcher
takes its report (`ros2 launch`, `ros2 run`). ROS-free: it reads the closed bag.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ato_nodes.results import jsontext
from ato_nodes.bags.bagio import BagError, message_counts, read_run
from ato_nodes.results.journeys import score_run

FILE_NAME = "summary.json"


def bag_contents(bag: Path) -> dict[str, Any]:
    """`recorded` (messages per topic), `scored_steps` (the steps every topic has),
    `notes` and `indices` of a closed bag; a `bag_error` instead if it cannot be read."""
    try:
        contents: dict[str, Any] = {"recorded": message_counts(bag), "scored_steps": 0}
        if not any(contents["recorded"].values()):
            contents["notes"] = ["the run ended before its first step: the bag is empty"]
            return contents
        if not all(contents["recorded"].values()):  # some topic never got its first step
            silent = sorted(name for name, count in contents["recorded"].items() if not count)
            contents["notes"] = [f"the run ended before its first complete step: "
                                 f"{', '.join(silent)} recorded no message"]
            return contents
        run = read_run(bag)
    except BagError as exc:
        return {"bag_error": str(exc)}
    contents.update(scored_steps=len(run.series["t"]), notes=run.notes,
                    indices=score_run(run.series, run.parameters))
    return contents


def write_summary(bag: Path, summary: dict[str, Any]) -> str:
    """Write summary.json into the bag directory; '' or why it could not be written."""
    try:
        (Path(bag) / FILE_NAME).write_text(jsontext.dumps(summary, indent=2))
    except OSError as exc:
        return f"summary not written: {exc.strerror or exc}"
    return ""
