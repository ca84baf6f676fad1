"""The index of the traction commanded and applied inside neutral sections
(core/scoring/operation.py) against a count made here."""

import numpy as np
import pytest

from ato_nodes.core.run.scoring import score_series
from ato_nodes.core.scoring.journey import journey_indices
from ato_nodes.core.scoring.operation import neutral_traction_time
from ato_nodes.core.targets.timetable import Stop, Timetable
from ato_nodes.core.train.line import parse_line

PERIOD = 0.1
NEUTRAL = (1000.0, 1300.0)  # m, the test line's neutral section
LINE_TEXT = f"""\
name: flat line with one neutral section
length: 5000
speed_limits:
  - {{start: 0, end: 5000, limit: 70}}
neutral_sections:
  - {{start: {NEUTRAL[0]}, end: {NEUTRAL[1]}}}
"""
LINE = parse_line(LINE_TEXT)


def test_the_index_counts_the_samples_inside_with_traction(tmp_path):
    """Against a count by hand: a train at 10 m/s over LINE with its pantograph 60 m
    behind, commanding +5 and -5 N/kN in turn, the force traction all along."""
    t = np.arange(0.0, 200.0, PERIOD)
    position = 900.0 + 10.0 * t
    command = np.where(np.arange(len(t)) % 2 == 0, 5.0, -5.0)
    force = np.full(len(t), 3.0)
    series = {"t": t, "target": np.full(len(t), 10.0), "speed": np.full(len(t), 10.0),
              "position": position, "acceleration": np.zeros(len(t)), "force": force,
              "command": command}
    path = tmp_path / "line.yaml"
    path.write_text(LINE_TEXT)
    indices = score_series(series, {"line.file": str(path), "plant.pantograph_offset": 60.0,
                                    "plant.mass": 443.0})
    inside = [k for k, x in enumerate(position) if NEUTRAL[0] <= x - 60.0 < NEUTRAL[1]
              and k + 1 < len(t)]
    assert len(inside) == 300  # 30 s at 10 m/s
    by_hand = sum(PERIOD for k in inside if command[k] > 0.0)
    assert indices["neutral_traction_command_time"] == pytest.approx(by_hand) == 15.0
    assert indices["neutral_traction_force_time"] == pytest.approx(30.0)
    stops = (Stop("A", 0.0, None, 0.0, source_line=1), Stop("B", 4000.0, 300.0, None,
                                                             source_line=2))
    journey = journey_indices(series, Timetable("synthetic", "", None, "synthetic", stops),
                              443.0, neutral=LINE.in_neutral_sections(position - 60.0))
    assert journey.neutral_traction_command_time == indices["neutral_traction_command_time"]


def test_a_line_without_neutral_sections_has_no_such_index(tmp_path):
    path = tmp_path / "line.yaml"
    path.write_text(LINE_TEXT.split("neutral_sections")[0])
    t = np.arange(0.0, 10.0, PERIOD)
    series = {"t": t, "target": t, "speed": t, "position": t, "acceleration": t, "force": t,
              "command": t}
    indices = score_series(series, {"line.file": str(path), "plant.mass": 443.0})
    assert "neutral_traction_command_time" not in indices
    assert neutral_traction_time(t, t, np.ones(len(t), dtype=bool)) == pytest.approx(9.8)

