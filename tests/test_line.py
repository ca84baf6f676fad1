"""Line files: validation with file and line, and mass-belt additional resistance."""

import subprocess
from pathlib import Path

import numpy as np
import pytest

from ato_nodes.core.train.line import (CURVE_CONSTANT, TUNNEL_CONSTANT, _belt_resistances,
                                      load_line)
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.base.paths import config_dir
from commands import invocation

ROOT = Path(__file__).resolve().parents[1]

GOOD = """\
name: test line
length: 1000
gradients:
  - {start: 0, end: 400, grade: 10}
  - {start: 400, end: 1000, grade: -5}
curves:
  - {start: 500, end: 600, radius: 600}
tunnels:
  - {start: 700, end: 900}
speed_limits:
  - {start: 0, end: 1000, limit: 20}
"""


def write(tmp_path, text):
    path = tmp_path / "line.yaml"
    path.write_text(text)
    return path


def test_shipped_lines_load():
    lines = sorted((config_dir() / "lines").glob("*.yaml"))
    assert lines
    for path in lines:
        line = load_line(path)
        assert line.length > 0 and line.speed_limit(0.0) > 0


def test_resistance_on_one_section_is_the_point_value(tmp_path):
    line = load_line(write(tmp_path, GOOD))
    assert line.additional_resistance(300.0, 200.0) == pytest.approx(10.0)  # wholly on +10
    assert line.additional_resistance(600.0, 100.0) == pytest.approx(-5.0 + CURVE_CONSTANT / 600)
    assert line.additional_resistance(900.0, 200.0) == pytest.approx(-5.0 + TUNNEL_CONSTANT * 200)


def test_resistance_varies_linearly_while_straddling_a_change(tmp_path):
    line = load_line(write(tmp_path, GOOD))
    length = 100.0  # the head goes from 400 m (all on +10) to 500 m (all on -5)
    values = [line.additional_resistance(400.0 + d, length) for d in (0, 25, 50, 75, 100)]
    assert values[0] == pytest.approx(10.0) and values[-1] == pytest.approx(-5.0)
    steps = [b - a for a, b in zip(values, values[1:], strict=False)]
    assert steps == pytest.approx([-3.75] * 4)  # (-5 - 10) / 100 m * 25 m


@pytest.mark.parametrize("length", [0.0, 0.1, 100.0, 2000.0])
def test_resistances_at_once_are_those_point_by_point_bit_for_bit(tmp_path, length):
    """additional_resistances (compiled when numba is installed) gives each head exactly
    what additional_resistance gives it: the same operations in the same order."""
    line = load_line(write(tmp_path, GOOD))
    heads = np.concatenate((np.arange(-50.0, 1100.0, 0.3), [400.0, 500.0, 600.0, 900.0]))
    one_by_one = np.array([line.additional_resistance(head, length) for head in heads])
    at_once = line.additional_resistances(heads, length)
    assert at_once.tobytes() == one_by_one.tobytes()
    assert _belt_resistances(line.tables, heads, length).tobytes() == one_by_one.tobytes()


@pytest.mark.parametrize("change, problem", [
    ("  - {start: 400, end: 1000, grade: -5}", "gradients: section starting at 300 m overlaps"),
    ("  - {start: 0, end: 400, grade: 10}", "no positive length"),
    ("  - {start: 0, end: 1000, limit: 20}", "limit must be positive, not 0"),
    ("  - {start: 700, end: 900}", "tunnels: unknown key 'lenght'"),
    ("length: 1000", "unknown key 'lenght'"),
    ("  - {start: 0, end: 1000, limit: 20}", "no limit from 800 m to the end"),
    ("  - {start: 0, end: 400, grade: 10}\n  - {start: 400, end: 1000, grade: -5}",
     "gradients: section starting at 0 m overlaps or precedes"),
    ("  - {start: 700, end: 900}", "tunnels: section from 900 to 700 m has no positive length"),
])
def test_bad_line_files_name_the_file_and_line(tmp_path, change, problem):
    replacement = {
        "gradients: section starting at 300 m overlaps": "  - {start: 300, end: 1000, grade: -5}",
        "no positive length": "  - {start: 0, end: 0, grade: 10}",
        "limit must be positive, not 0": "  - {start: 0, end: 1000, limit: 0}",
        "tunnels: unknown key 'lenght'": "  - {start: 700, end: 900, lenght: 3}",
        "unknown key 'lenght'": "lenght: 1000",
        "no limit from 800 m to the end": "  - {start: 0, end: 800, limit: 20}",
        "gradients: section starting at 0 m overlaps or precedes":
            "  - {start: 400, end: 1000, grade: -5}\n  - {start: 0, end: 400, grade: 10}",
        "tunnels: section from 900 to 700 m has no positive length": "  - {start: 900, end: 700}",
    }[problem]
    path = write(tmp_path, GOOD.replace(change, replacement, 1))
    with pytest.raises(ScenarioError) as failure:
        load_line(path)
    message = str(failure.value)
    assert str(path) in message and " line " in message and problem in message
    assert "\n" not in message


def test_speed_limit_and_neutral_sections_by_position(tmp_path):
    text = GOOD.replace("speed_limits:\n  - {start: 0, end: 1000, limit: 20}",
                        "speed_limits:\n  - {start: 0, end: 500, limit: 20}\n"
                        "  - {start: 500, end: 1000, limit: 30}\n"
                        "neutral_sections:\n  - {start: 800, end: 850}")
    line = load_line(write(tmp_path, text))
    assert line.speed_limit(499.0) == 20 and line.speed_limit(500.0) == 30
    assert line.in_neutral_section(820.0) and not line.in_neutral_section(850.0)


def test_a_bad_line_stops_run_stack_with_one_line_and_exit_2(tmp_path):
    line = write(tmp_path, GOOD.replace("limit: 20", "limit: 0"))
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text("/**:\n  ros__parameters:\n    profile.kind: ato\n"
                        f"    line.file: {line}\n")
    result = subprocess.run([*invocation("run_stack"), "--scenario",
                             str(scenario), "--out", str(tmp_path / "bag")],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and str(line) in lines[0] and "line 11" in lines[0]
    assert "limit must be positive" in lines[0] and not (tmp_path / "bag").exists()


def test_a_negative_station_dwell_is_refused_with_file_and_line(tmp_path):
    path = write(tmp_path, GOOD + "stations:\n  - {name: A, position: 0, dwell: 30}\n"
                 "  - {name: B, position: 1000, dwell: -30}\n")
    with pytest.raises(ScenarioError) as failure:
        load_line(path)
    assert str(failure.value) == f"{path} line 14: stations: dwell -30 s is negative"
