"""No traction across a phase break: the linear ADRC's neutral cut (ladrc.neutral_cut,
core/control/train_model.neutral_ceiling), the same bits compiled and in Python, the ato
curve coasting on past a section (profile.ato.neutral_runout), and the index of the
traction commanded and applied inside neutral sections (core/scoring/operation.py)
against a count made here."""

import numpy as np
import pytest

from ato_nodes.core.base import kernels
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import apply_overrides, load_scenario, train_preset
from ato_nodes.core.config.schema import defaults
from ato_nodes.core.control.adrc import linear_adrc_of
from ato_nodes.core.control.estimation import on_board_estimator
from ato_nodes.core.control.limiter import CommandLimiter
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.run.scoring import score_series
from ato_nodes.core.scoring.journey import journey_indices
from ato_nodes.core.scoring.operation import neutral_traction_time
from ato_nodes.core.targets.profiles import ato_curve
from ato_nodes.core.targets.timetable import Stop, Timetable
from ato_nodes.core.train.line import load_line, neutral_distance, parse_line
from ato_nodes.core.train.plant import PointMassTrain, TrainParameters, TrainState
from test_adrc import paper_gains

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
MAX_RATE = 60.0  # N/kN/s, the jerk limit of the high-speed scenarios


def crh5() -> TrainParameters:
    values = {**defaults(), **train_preset("crh5"), "plant.hold_at_standstill": True}
    return TrainParameters.from_values(values)


def drive(cut: bool, speed: float = 50.0, head: float = 700.0, steps: int = 160,
          last: float = 0.0):
    """The linear ADRC asking for more speed (a target 20 m/s above) of a CRH5 at `speed`
    from `head` on LINE, its last command `last`: (pantograph positions, commands, one
    per step; the train; the controller)."""
    train = crh5()
    gains = paper_gains(omega_o=5.0, omega_c=1.0, b0=train.xi, neutral_cut=cut)
    limiter = CommandLimiter(-67.9, 57.6, PERIOD, MAX_RATE)
    limiter.last = last
    adrc = linear_adrc_of(gains, PERIOD, limiter, train, on_board_estimator(defaults(), PERIOD),
                          head, LINE)
    plant = PointMassTrain(train, PERIOD, 2, TrainState(position=head, speed=speed), LINE)
    pantograph, commands = [], []
    adrc.start(speed + 20.0, speed, [speed + 20.0])
    for _ in range(steps):
        pantograph.append(plant.state.position - train.pantograph_offset)
        commands.append(adrc.step(plant.state.speed + 20.0, plant.state.speed,
                                  [plant.state.speed + 20.0]).u)
        plant.step(commands[-1])
    return np.array(pantograph), np.array(commands), train, adrc


def test_the_next_neutral_section_is_found_ahead_or_around():
    tables = LINE.tables
    assert neutral_distance(tables, 400.0) == 600.0
    assert neutral_distance(tables, 1000.0) == neutral_distance(tables, 1299.0) == 0.0
    assert neutral_distance(tables, 1300.0) == np.inf


def test_no_traction_is_commanded_inside_nor_acts_there_and_it_returns_after():
    pantograph, commands, train, _ = drive(cut=True)
    start, end = NEUTRAL
    inside = (pantograph >= start) & (pantograph < end)
    assert inside.sum() > 50 and np.all(commands[inside] <= 0.0)
    # a command acts after the dead time, for a period: none that would act inside
    reach = 50.0 * (train.dead_time + PERIOD) + 1.0  # m at ~50 m/s, and the speed gained
    assert np.all(commands[(pantograph >= start - reach) & (pantograph < end)] <= 0.0)
    # ramped down at the jerk limit before that, not cut at once
    assert np.max(np.abs(np.diff(commands[pantograph < start]))) <= MAX_RATE * PERIOD + 1e-9
    before = (pantograph > start - 200.0) & (pantograph < start - 100.0)
    assert commands[before].min() > 40.0  # asking for traction
    # released once the pantograph has left (dead-reckoned: within a period's travel)
    after = np.flatnonzero(pantograph >= end)
    assert commands[after[0] + 1] > 0.0 and commands[after[-1]] > 40.0
    _, uncut, _, _ = drive(cut=False)
    assert np.all(uncut[inside] > 0.0)  # what the cut takes away


def test_the_cut_yields_the_jerk_limit_where_it_starts_inside_its_reach():
    """A train at full traction 10 m short of the section: no ramp could take it off in
    time, so the command drops to none at once rather than act inside; the observer is
    told the cut command (no feedforward: its input is the command)."""
    _, commands, _, adrc = drive(cut=True, head=NEUTRAL[0] - 10.0 + 60.0, steps=5, last=57.6)
    assert np.all(commands <= 0.0)
    assert adrc.state.u_applied == adrc.state.observer_input == commands[-1]
    _, uncut, _, _ = drive(cut=False, head=NEUTRAL[0] - 10.0 + 60.0, steps=1, last=57.6)
    assert uncut[0] == 57.6  # what the jerk limit alone would let through


def test_a_train_standing_short_of_a_section_is_not_cut():
    _, commands, _, _ = drive(cut=True, speed=0.0, head=NEUTRAL[0] - 5.0 + 60.0, steps=3)
    assert np.all(commands > 0.0)


# A high-speed run over its second neutral section, started 200 m short of it, cut
CROSSING = ["plant.initial_position=19400", "plant.initial_speed=52", "run.duration=15",
            "ladrc.neutral_cut=true"]


@pytest.mark.skipif(not kernels.AVAILABLE, reason="numba is not installed")
@pytest.mark.parametrize("scenario", ["hsr-neutral-ato",  # feedforward, delay-aware observer
                                      "hsr-neutral"])     # the papers' law
def test_the_compiled_cut_gives_the_python_bits(scenario):
    values = apply_overrides(load_scenario(scenario), CROSSING)
    compiled, python = simulate(values), simulate(values, compiled=False)
    for name in python:
        assert np.array_equal(compiled[name], python[name], equal_nan=True), name
    indices = score_series(compiled, values)
    assert indices["neutral_traction_command_time"] == 0.0
    uncut = score_series(simulate(apply_overrides(values, ["ladrc.neutral_cut=false"])), values)
    assert uncut["neutral_traction_command_time"] > 1.0


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



def hsr_curve(*overrides):
    values = apply_overrides(load_scenario("hsr-neutral-ato"), list(overrides))
    train = TrainParameters.from_values(values)
    return ato_curve(values, load_line(values["line.file"]), train), train, values


@pytest.mark.slow
def test_the_curve_coasts_on_past_a_neutral_section_for_its_runout():
    curve, train, values = hsr_curve()
    runout = values["profile.ato.neutral_runout"]
    assert runout > 0.0
    plain, _, _ = hsr_curve("profile.ato.neutral_runout=0")
    end = curve.line.neutral_sections[1].end + train.pantograph_offset  # the head there
    x = curve.positions

    def rates(speeds, low, high):
        """The planned acceleration over [low, high) m, against what coasting gives."""
        cells = np.flatnonzero((x[:-1] >= low) & (x[:-1] < high))
        v = speeds[cells]
        rate = (speeds[cells + 1] ** 2 - v ** 2) / (2 * np.diff(x)[cells])
        coasting = -train.xi * np.array([train.resistance(s) + curve.line.additional_resistance(
            p, train.length) for s, p in zip(v, x[cells], strict=True)])
        return rate - coasting

    assert np.all(rates(curve.speeds, end, end + runout) <= 1e-6)  # no traction planned
    assert np.all(rates(plain.speeds, end + 5.0, end + runout) > 0.01)  # traction at once
    assert np.all(rates(curve.speeds, end + runout + 5.0, end + runout + 50.0) > 0.01)
    # both on time: the cruise a little higher for the longer coasting
    assert curve.planned_run_time == pytest.approx(plain.planned_run_time, abs=0.05)
    assert curve.cruise > plain.cruise


def test_a_runout_without_an_envelope_share_is_refused():
    with pytest.raises(ScenarioError, match="profile.ato.neutral_runout needs"):
        hsr_curve("profile.envelope_share=0")
