"""What a journey run (profile.kind journey) must hold before it starts, beyond what its
plan checks as it is built (core/targets/served.py): checked once by validate() for the
stack and in-process alike."""

from __future__ import annotations

from ..base.errors import ScenarioError
from ..scoring.journey import check_stop_window
from ..targets.timetable import check_running_times, load_timetable


def check_journey(values, line) -> None:
    """ScenarioError for a journey run given line.planned_run_time (its timetable gives
    the running times), a timetable whose stops are too close for per-station indices,
    or one the run's nominal train cannot keep at the timetable's load (its minimum
    running times: core/targets/timetable.py). A timetable of another line or train than
    the run's (`line`, plant.train) is left to the plan, which refuses it naming both."""
    path = values["profile.journey.timetable"]
    if values["profile.kind"] != "journey" or not path:
        return  # not a journey, or one the plan refuses
    if values["line.planned_run_time"]:
        raise ScenarioError(f"line.planned_run_time {values['line.planned_run_time']:g} s does "
                            "not apply to a journey (profile.kind journey): its timetable "
                            f"{path} gives each section's running time")
    timetable = load_timetable(path)
    if not (timetable.on_line(line, values) and timetable.for_train(values["plant.train"])):
        return
    try:
        check_stop_window(timetable)
    except ScenarioError as exc:
        raise ScenarioError(f"{path}: {exc}: per-station indices could not tell its stops "
                            "apart") from None
    check_running_times(timetable, values)
