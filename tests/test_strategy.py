"""Seed 002's energy-optimal limit: dynamic programming over (position, speed)."""

import dataclasses
import hashlib

import numpy as np
import pytest

from ato_nodes.core.control.adrc import (PlanForces, next_force, on_plan_side, plan_forces,
                                         planned_force)
from ato_nodes.core.run.scoring import score_series
from ato_nodes.core.scoring.operation import SWITCH_THRESHOLD, _switch_count
from ato_nodes.core.base import kernels
from ato_nodes.core.targets import strategy
from ato_nodes.core.train import line as line_module
from ato_nodes.core.config.context import RunContext
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.train.line import parse_line
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.train.plant import TrainParameters
from ato_nodes.core.config.scenario import apply_overrides, complete, load_scenario

CRH5 = TrainParameters.from_values(complete({"plant.train": "crh5"}, []))


def line(length=20000.0, limit=69.44, body=""):
    return parse_line(f"name: t\nlength: {length}\nspeed_limits:\n"
                      f"  - {{start: 0, end: {length}, limit: {limit}}}\nstations:\n"
                      f"  - {{name: A, position: 0}}\n  - {{name: B, position: {length}}}\n"
                      f"{body}")


def runs(modes):
    """The mode sequence with repeats collapsed: [1, 1, 0, -1] -> [1, 0, -1]."""
    modes = list(modes)
    return [m for i, m in enumerate(modes) if i == 0 or modes[i - 1] != m]


@pytest.mark.slow
def test_on_a_flat_line_the_optimum_is_full_power_cruise_coast_full_brake():
    track = strategy.Track.of(line(), CRH5, ds=100.0)
    fastest = strategy.solve(track, CRH5, 0.9, None, energy_weight=0.0)
    best = strategy.solve(track, CRH5, 0.9, 1.08 * fastest.time)
    assert 1.08 * fastest.time - 2.0 < best.time <= 1.08 * fastest.time  # on time, no later
    assert runs(best.modes) == [1, 0, -1]
    kinds = [kind for kind, _ in best.controls]
    accelerating = [fraction for kind, fraction in best.controls if kind == "traction"]
    assert accelerating and min(accelerating) == 1.0  # full power while accelerating
    coasting = kinds.index("coast")
    assert "cruise" in kinds[:coasting] and "traction" not in kinds[coasting:]
    braking = [fraction for kind, fraction in best.controls if kind == "brake"]
    assert braking[-1] == 1.0
    assert best.energy_kwh < fastest.energy_kwh
    assert best.speeds[0] == 0.0 and best.speeds[-1] == pytest.approx(0.0, abs=1e-9)


@pytest.mark.slow
def test_traction_is_off_through_every_neutral_section_and_the_cap_holds():
    neutral = "neutral_sections:\n  - {start: 6000, end: 6300}\n  - {start: 12000, end: 12300}\n"
    grades = "gradients:\n  - {start: 0, end: 20000, grade: 6.0}\n"
    test_line = line(body=neutral + grades)
    track = strategy.Track.of(test_line, CRH5, ds=100.0)
    fastest = strategy.solve(track, CRH5, 0.9, None, energy_weight=0.0)
    best = strategy.solve(track, CRH5, 0.9, 1.05 * fastest.time)
    for result in (fastest, best):
        for start, force in zip(result.positions[:-1], result.forces, strict=False):
            stage = (start - CRH5.pantograph_offset, start + track.ds - CRH5.pantograph_offset)
            if any(stage[0] < s.end and stage[1] > s.start for s in test_line.neutral_sections):
                assert force <= 0.0
        assert np.all(result.speeds <= 69.44 - strategy.MARGIN + 1e-9)


def test_the_landing_control_reaches_the_cap_and_the_stop_exactly():
    """LAND takes the train onto the stage's cap (a speed off the grid) and into the stop;
    its stages' modes follow its force. Seed 002's CONTROLS have no such control."""
    metro = TrainParameters.from_values(complete({"plant.train": "metro-b"}, []))
    track = strategy.Track.of(line(length=2000.0, limit=16.67), metro, ds=20.0)
    cap = float(track.cap[0])
    assert cap / 0.05 % 1.0 > 0.01  # not a speed of the grid
    controls = (*strategy.CONTROLS, (strategy.LAND, 0.0))
    landed = strategy.solve(track, metro, 0.9, None, lam=2000.0, controls=controls,
                            speed_step=0.05)
    assert np.any(landed.speeds == cap) and np.all(landed.speeds <= cap + 1e-9)
    assert landed.speeds[-1] == 0.0
    kinds = [kind for kind, _ in landed.controls]
    assert strategy.LAND in kinds
    for kind, force, mode in zip(kinds, landed.forces, landed.modes, strict=True):
        if kind == strategy.LAND:
            assert mode == np.sign(force)
    plain = strategy.solve(track, metro, 0.9, None, lam=2000.0, speed_step=0.05)
    assert strategy.LAND not in [kind for kind, _ in plain.controls]
    assert not np.any(plain.speeds == cap)


def test_a_planned_time_below_the_flat_out_run_is_refused():
    track = strategy.Track.of(line(), CRH5, ds=200.0)
    fastest = strategy.solve(track, CRH5, 0.9, None, energy_weight=0.0)
    with pytest.raises(ValueError, match="shorter than the flat-out"):
        strategy.solve(track, CRH5, 0.9, fastest.time - 5.0)


@pytest.mark.slow
def test_more_time_costs_less_energy():
    track = strategy.Track.of(line(), CRH5, ds=200.0)
    fastest = strategy.solve(track, CRH5, 0.9, None, energy_weight=0.0)
    energies = [strategy.solve(track, CRH5, 0.9, f * fastest.time).energy_kwh
                for f in (1.03, 1.06, 1.12)]
    assert energies[0] > energies[1] > energies[2]


def test_switching_strategies_keep_traction_off_in_neutral_sections_and_stop_at_the_mark():
    neutral = "neutral_sections:\n  - {start: 6000, end: 6300}\n"
    grades = ("gradients:\n  - {start: 0, end: 9000, grade: -8.0}\n"
              "  - {start: 9000, end: 20000, grade: 5.0}\n")
    test_line = line(body=neutral + grades)
    track = strategy.Track.of(test_line, CRH5, ds=100.0)
    problem = strategy.Problem(track, CRH5, 0.9)
    switching = strategy.SwitchingStrategy(problem)
    assert len(switching.segments) == 2
    rng = np.random.default_rng(0)
    low, high = switching.bounds()
    for x in [np.ones(switching.dimension), *(rng.uniform(low, high) for _ in range(20))]:
        result = switching.run(x)
        for start, force in zip(result.positions[:-1], result.forces, strict=False):
            head = start - CRH5.pantograph_offset
            if 6000 - track.ds < head < 6300:
                assert force <= 0.0
        assert np.all(result.speeds[1:] <= track.cap[:len(result.speeds) - 1] + 1e-6)
        if np.isfinite(result.time):  # it did not coast to a stand short of the mark
            assert result.positions[-1] == test_line.stop_position
            assert result.speeds[-1] == pytest.approx(0.0, abs=1e-9)


def test_the_flat_out_run_is_the_fastest_switching_strategy():
    track = strategy.Track.of(line(body="gradients:\n  - {start: 0, end: 20000, grade: 4.0}\n"),
                              CRH5, ds=100.0)
    problem = strategy.Problem(track, CRH5, 0.9)
    fastest = strategy.flat_out(problem)
    switching = strategy.SwitchingStrategy(problem)
    rng = np.random.default_rng(1)
    for x in (rng.uniform(*switching.bounds()) for _ in range(10)):
        assert switching.run(x).time >= fastest.time - 1e-6


def shipped_like_strategy(tmp_path, train="crh5"):
    """A DP strategy for a short line, written as scripts/optimize_strategy.py does."""
    path = tmp_path / "line.yaml"
    path.write_text("name: t\nlength: 8000\nspeed_limits:\n  - {start: 0, end: 8000, limit: 50}\n"
                    "neutral_sections:\n  - {start: 3000, end: 3300}\n"
                    "stations:\n  - {name: A, position: 0}\n  - {name: B, position: 8000}\n")
    track = strategy.Track.of(parse_line(path.read_text()), CRH5, ds=100.0)
    result = strategy.solve(track, CRH5, 0.9, None, energy_weight=0.0)
    header = {"line": str(path), "line_sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
              "train": train}
    strategy.write_strategy(tmp_path / "strategy.csv", header, result)
    return path, tmp_path / "strategy.csv", result


def strategy_run(line_path, strategy_path, *overrides):
    return apply_overrides(load_scenario("hsr-neutral"), [
        f"line.file={line_path}", "profile.kind=strategy",
        f"profile.strategy.file={strategy_path}", *overrides])


def test_the_strategy_profile_publishes_the_strategy_and_its_modes(tmp_path):
    line_path, path, result = shipped_like_strategy(tmp_path)
    context = RunContext(strategy_run(line_path, path))
    plan = context.plan
    assert plan.position_indexed
    assert plan.speed(0.0, 0.0) == pytest.approx(0.3)
    for i in (5, 20, 40):
        assert plan.speed(0.0, result.positions[i]) == pytest.approx(result.speeds[i])
        assert plan.mode(result.positions[i] + 1.0) == result.modes[i]
        assert plan.force(result.positions[i] + 1.0) == pytest.approx(result.forces[i], abs=1e-5)
    assert plan.speed(0.0, 8000.0) == pytest.approx(0.0, abs=1e-9)


def test_the_tracked_strategy_has_no_traction_in_the_neutral_section(tmp_path):
    line_path, path, _ = shipped_like_strategy(tmp_path)
    series = simulate(strategy_run(line_path, path, "run.duration=400"))
    pantograph = series["position"] - CRH5.pantograph_offset
    inside = (pantograph >= 3000) & (pantograph <= 3300)
    # the sample at which the pantograph has just entered still shows the force of the
    # sub-step that began outside: traction is cut from the next sub-step on
    held = inside[1:] & inside[:-1]
    assert held.sum() > 10 and np.all(series["force"][1:][held] <= 0.0)


@pytest.mark.parametrize("change, message", [
    ("line", "planned for another line"), ("train", "planned for train 'crh380al'"),
    ("format", "not a strategy file")])
def test_a_strategy_file_for_another_line_or_train_is_one_line(tmp_path, change, message):
    line_path, path, _ = shipped_like_strategy(tmp_path, "crh380al" if change == "train"
                                               else "crh5")
    if change == "line":
        line_path.write_text(line_path.read_text().replace("limit: 50", "limit: 49"))
    if change == "format":
        path.write_text(path.read_text().replace("ato-strategy-1", "something-else"))
    with pytest.raises(ScenarioError, match=message) as caught:
        strategy_run(line_path, path)
    assert "\n" not in str(caught.value)


def edit_row(path, row: int, column: int, text: str) -> int:
    """Replace one number of the strategy file's `row`-th data row; its line number."""
    lines = path.read_text().splitlines()
    first = lines.index(strategy.COLUMNS) + 1
    cells = lines[first + row].split(",")
    cells[column] = text
    lines[first + row] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")
    return first + row + 1


@pytest.mark.parametrize("row, column, text, message", [
    (10, 1, "1e300", "speed 1e+300 m/s is outside 0-300 m/s"),
    (10, 1, "-0.5", "speed -0.5 m/s is outside 0-300 m/s"),
    (10, 3, "nan", "every number must be finite"),
    (10, 3, "1e6", "force 1e+06 N/kN is beyond +-1000 N/kN"),
    (10, 2, "2", "mode 2 is not 1 (traction), 0 (cruise or coast) or -1 (brake)"),
    (10, 0, "0.0", "position 0 m does not increase (after 900 m)"),
    (0, 0, "-5", "position -5 m is off any line (0-2e+06 m)"),
    (10, 0, "1,2", "four numbers expected (position,speed,mode,force)"),
])
def test_a_strategy_row_out_of_its_physical_range_is_one_line_naming_it(
        tmp_path, row, column, text, message):
    line_path, path, _ = shipped_like_strategy(tmp_path)
    number = edit_row(path, row, column, text)
    with pytest.raises(ScenarioError) as caught:
        strategy_run(line_path, path)
    assert str(caught.value).endswith(f"{path} line {number}: {message}")


def test_a_huge_strategy_file_is_refused_by_its_size_before_it_is_read(tmp_path):
    line_path, path, _ = shipped_like_strategy(tmp_path)
    with open(path, "r+b") as handle:  # sparse: 58 MB on paper, nothing on disk
        handle.truncate(58 << 20)
    with pytest.raises(ScenarioError, match=f"strategy file {path} is larger than 8 MiB"):
        strategy_run(line_path, path)
    with pytest.raises(ScenarioError, match=f"strategy file {tmp_path} is a directory"):
        strategy_run(line_path, tmp_path)


LADRC_PLAN = ("controller.kind=linear_adrc", "controller.holding_target=0.02",
              "controller.preview=10", "profile.strategy.start_speed=0.1",
              "ladrc.omega_o=5", "ladrc.omega_c=1", "ladrc.b0=0.008829",
              "ladrc.prediction=speed")


def test_the_linear_adrc_reads_the_plans_force_by_stage_and_brakes_on_past_the_stop(
        tmp_path):
    line_path, path, result = shipped_like_strategy(tmp_path)
    plan = RunContext(strategy_run(line_path, path)).plan
    forces = plan_forces(plan)
    assert len(forces.positions) == len(result.positions) - 1  # the stop mark is no stage
    for position in (0.0, 50.0, result.positions[7], result.positions[30] + 12.5, 3150.0):
        assert planned_force(forces, position) == plan.force(position)
    last = result.forces[-1]
    assert last < 0.0
    assert planned_force(forces, result.positions[-1] + 1.0) == pytest.approx(last, abs=1e-5)
    assert planned_force(forces, -5.0) == pytest.approx(result.forces[0], abs=1e-5)


@pytest.mark.parametrize("position, reach, expected", [
    (50.0, 30.0, 0.0), (50.0, 60.0, 20.0),     # the traction stage at 100 m once in reach
    (150.0, 200.0, 20.0),                      # held: no other force within reach
    (150.0, 300.0, -30.0), (250.0, 0.0, 20.0), # past the equal-force stage to the brake
    (450.0, 100.0, -30.0)])                    # the last stage holds on
def test_the_next_force_is_the_first_other_one_within_reach(position, reach, expected):
    plan = PlanForces(np.array([0.0, 100.0, 200.0, 400.0]), np.array([0.0, 20.0, 20.0, -30.0]))
    assert next_force(plan, position, reach) == expected


@pytest.mark.parametrize("u, planned, speed, expected", [
    (-3.0, 20.0, 10.0, 0.0), (25.0, 20.0, 10.0, 25.0),    # driving: no braking
    (4.0, -30.0, 10.0, 0.0), (-35.0, -30.0, 10.0, -35.0),  # braking: no traction
    (4.0, 0.0, 10.0, 0.0), (-4.0, 0.0, 10.0, 0.0),         # coasting: neither
    (4.0, 0.0, 9.8, 4.0), (-4.0, 0.0, 10.2, -4.0),         # unless beyond the band
    (-3.0, 20.0, 10.2, -3.0), (4.0, -30.0, 9.8, 4.0)])
def test_the_command_stays_on_the_plans_side_within_the_band(u, planned, speed, expected):
    assert on_plan_side(u, planned, planned, speed, 10.0, 0.1) == expected


@pytest.mark.parametrize("u, planned, coming, speed, expected", [
    (4.0, 0.0, 20.0, 9.92, 4.0), (4.0, 0.0, 20.0, 9.97, 0.0),   # coasting, traction coming:
    (4.0, 0.0, 20.0, 10.05, 0.0), (-4.0, 0.0, 20.0, 9.92, 0.0),  # traction only if half a
    (4.0, 0.0, 0.0, 9.92, 0.0), (4.0, 0.0, -30.0, 9.92, 0.0),    # band behind, no brake
    (-4.0, 0.0, -30.0, 10.05, 0.0),                              # no lead into braking
    (4.0, -30.0, 20.0, 9.92, 0.0)])                              # nor out of a braking stage
def test_a_coasting_command_leads_into_a_coming_traction_stage_only_when_behind(
        u, planned, coming, speed, expected):
    assert on_plan_side(u, planned, coming, speed, 10.0, 0.1) == expected


@pytest.mark.slow
def test_the_plans_force_keeps_the_tracked_strategys_coasting_and_modes(tmp_path):
    line_path, path, result = shipped_like_strategy(tmp_path)
    runs_of = {}
    for feedforward in ("target", "plan"):
        values = strategy_run(line_path, path, *LADRC_PLAN, f"ladrc.feedforward={feedforward}")
        runs_of[feedforward] = score_series(simulate(values), values)
    planned = _switch_count(result.forces, SWITCH_THRESHOLD)
    assert runs_of["plan"]["switch_count"] <= min(planned + 2, runs_of["target"]["switch_count"])


def test_the_plans_force_needs_a_plan_with_forces():
    with pytest.raises(ScenarioError, match="^parameters: ladrc.feedforward plan needs a plan "
                                            "with forces .profile.kind strategy., not "
                                            "profile.kind ato$"):
        apply_overrides(load_scenario("hsr-neutral-ato"), ["ladrc.feedforward=plan"])


def test_a_plan_at_an_envelope_share_keeps_the_rest_in_reserve():
    track = strategy.Track.of(line(body="gradients:\n  - {start: 0, end: 20000, grade: 4.0}\n"),
                              CRH5, ds=100.0)
    whole, reserved = (strategy.Problem(track, CRH5, 0.9, share) for share in (1.0, 0.85))
    speeds = np.array([5.0, 30.0, 60.0])
    for full, part in zip(whole.limits(speeds), reserved.limits(speeds), strict=True):
        assert np.allclose(part, 0.85 * full)
    for problem, share in ((whole, 1.0), (reserved, 0.85)):
        result = strategy.flat_out(problem)
        brake, traction = (limit * 1.0 / share for limit in whole.limits(result.speeds[:-1]))
        assert np.all(result.forces <= share * traction + 1e-9)
        assert np.all(result.forces >= min(strategy.PLANNED_BRAKING, share) * brake - 1e-9)
    assert strategy.flat_out(reserved).time > strategy.flat_out(whole).time
    with pytest.raises(ValueError, match="share"):
        strategy.Problem(track, CRH5, 0.9, 0.0)


def switching_file(tmp_path, share=0.85, time_factor=1.1):
    """A line, and a MARECO-like strategy file for it at `share` of the envelopes with its
    switching points in the header, as scripts/optimize_strategy.py writes it."""
    path = tmp_path / "line.yaml"
    path.write_text("name: t\nlength: 20000\nspeed_limits:\n"
                    "  - {start: 0, end: 20000, limit: 69.44}\n"
                    "gradients:\n  - {start: 0, end: 20000, grade: 3.0}\n"
                    "neutral_sections:\n  - {start: 9000, end: 9300}\n"
                    "stations:\n  - {name: A, position: 0}\n  - {name: B, position: 20000}\n")
    test_line = parse_line(path.read_text())
    problem = strategy.Problem(strategy.Track.of(test_line, CRH5, 100.0), CRH5, 0.9, share)
    planned = time_factor * strategy.flat_out(problem).time
    result = strategy.mareco(problem, planned)
    header = {"line": str(path), "line_sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
              "train": "crh5", "planned_time_s": f"{planned:.3f}", "algorithm": "mareco",
              "share": repr(share),
              "switching": ",".join(repr(float(v)) for v in result.switching)}
    strategy.write_strategy(tmp_path / "strategy.csv", header, result)
    return test_line, path, tmp_path / "strategy.csv", result


def test_the_strategy_driven_again_for_the_planned_train_is_the_file(tmp_path):
    test_line, _, path, result = switching_file(tmp_path)
    plan = strategy.read_strategy(path)
    again = strategy.for_train(plan, test_line, CRH5, 0.9)
    assert np.allclose(again.speeds, result.speeds, atol=1e-5)
    assert np.allclose(again.forces[:-1], result.forces, atol=1e-5)


def test_a_heavier_train_gets_its_own_plan_on_time_within_its_reserve(tmp_path):
    test_line, _, path, result = switching_file(tmp_path)
    plan = strategy.read_strategy(path)
    planned = float(plan.header["planned_time_s"])
    heavy = dataclasses.replace(CRH5, mass=1.15 * CRH5.mass)
    again = strategy.for_train(plan, test_line, heavy, 0.9)
    problem = strategy.Problem(strategy.Track.of(test_line, heavy, 100.0), heavy, 0.9, 0.85)
    brake, traction = problem.limits(again.speeds[:-1])
    assert np.all(again.forces[:-1] <= traction + 1e-9)  # the heavy train's 85 %
    assert np.all(again.forces[:-1] >= brake - 1e-9)
    assert strategy.running_time(again) <= planned + 0.5  # recovered: on time
    assert again.speeds[-1] == pytest.approx(0.0, abs=1e-9) and again.positions[-1] == 20000
    assert float(again.header["time_for_train_s"]) > result.time - 1e-6
    crushed = dataclasses.replace(CRH5, mass=1.6 * CRH5.mass)
    late = strategy.for_train(plan, test_line, crushed, 0.9, max_share=0.85)  # flat out
    fastest = strategy.flat_out(strategy.Problem(problem.track, crushed, 0.9, 0.85))
    assert np.allclose(late.speeds, fastest.speeds) and fastest.time > planned
    rising = strategy.for_train(plan, test_line, crushed, 0.9)  # up to the whole envelope
    assert fastest.time > strategy.running_time(rising) > planned - 0.5


def test_replan_drives_the_weighed_train_and_needs_switching_points(tmp_path):
    _, line_path, path, _ = switching_file(tmp_path)
    nominal = strategy_run(line_path, path, "profile.strategy.replan=true")
    file_plan = RunContext(nominal).plan
    assert RunContext(apply_overrides(nominal, ["train.mass_reading=0.9"])).plan.forces is \
        not None
    heavy = RunContext(apply_overrides(nominal, ["train.mass_reading=1.2"])).plan
    assert heavy.forces.max() < file_plan.forces.max()  # the heavier train's 85 %
    plain = RunContext(apply_overrides(nominal, ["train.mass_reading=1.2",
                                                 "profile.strategy.replan=false"])).plan
    assert np.array_equal(plain.forces, file_plan.forces)
    text = path.read_text().splitlines()
    path.write_text("\n".join(row for row in text if not row.startswith("# switching")) + "\n")
    with pytest.raises(ScenarioError, match="switching points"):
        RunContext(apply_overrides(nominal, ["train.mass_reading=1.2"])).plan  # noqa: B018


def python_only(monkeypatch):
    """The strategy's compiled loops, and the line's, replaced by their Python sources."""
    for name in ("driven", "braking_speeds", "track_columns"):
        monkeypatch.setattr(strategy, name, getattr(strategy, f"_{name}"))
    monkeypatch.setattr(line_module, "belt_resistances", line_module._belt_resistances)


def columns(plan) -> list[bytes]:
    """A plan's (Strategy's or StrategyFile's) arrays, bit for bit."""
    return [np.asarray(column).tobytes() for column in (
        plan.positions, plan.speeds, plan.modes, plan.forces)]


def shipped_strategy_plans(scenarios: dict) -> dict:
    """For each of `scenarios` (name: values of a shipped scenario with a strategy file):
    its line's track (caps, powered stages, resistances), braking curve, flat-out, MARECO
    and replayed runs, and its file driven again for a heavier and a much heavier train
    (past the file's share)."""
    plans = {}
    for name, values in scenarios.items():
        plan = strategy.read_strategy(values["profile.strategy.file"])
        test_line = line_module.load_line(values["line.file"])
        problem, planning = strategy.problems(test_line, values, 100.0, True, 0.85)
        track, fastest = problem.track, strategy.flat_out(planning)
        plans[name, "track"] = [track.line_resistance.tobytes(), track.cap.tobytes(),
                                track.powered.tobytes(),
                                strategy.SwitchingStrategy(problem).curve.tobytes()]
        plans[name, "flat out"] = columns(fastest)
        plans[name, "mareco"] = columns(strategy.mareco(problem, 1.05 * fastest.time))
        plans[name, "replayed"] = columns(strategy.replay(problem, fastest))
        if "switching" in plan.header:
            for factor, max_share in ((1.2, values["profile.strategy.max_share"]), (1.6, 1.0)):
                heavy = TrainParameters.from_values(
                    apply_overrides(values, [f"plant.mass_factor={factor}"]))
                plans[name, factor] = columns(strategy.for_train(
                    plan, test_line, heavy, values["plant.efficiency"], max_share))
    return plans


@pytest.mark.skipif(not kernels.AVAILABLE, reason="without numba every run is Python")
def test_the_compiled_strategy_runs_are_the_python_ones_bit_for_bit(monkeypatch):
    scenarios = {name: load_scenario(name) for name in ("seed002-hsr", "seed002-hsr-ato")}
    assert {values["profile.kind"] for values in scenarios.values()} == {"strategy"}
    compiled_plans = shipped_strategy_plans(scenarios)
    python_only(monkeypatch)
    python_plans = shipped_strategy_plans(scenarios)
    assert strategy.driven is strategy._driven
    assert any(len(key) == 2 and isinstance(key[1], float) for key in python_plans)
    assert compiled_plans.keys() == python_plans.keys()
    for key, plan in compiled_plans.items():
        assert plan == python_plans[key], key


def test_a_plan_that_stops_short_replays_as_far_as_it_has_forces_only():
    test_line = line(body="neutral_sections:\n  - {start: 9000, end: 9300}\n")
    problem = strategy.Problem(strategy.Track.of(test_line, CRH5, 100.0), CRH5, 0.9)
    fastest = strategy.flat_out(problem)
    assert np.array_equal(strategy.replay(problem, fastest).speeds, fastest.speeds)
    short = dataclasses.replace(fastest, forces=fastest.forces[:3])
    with pytest.raises(ValueError, match="^the replayed plan stops short"):
        strategy.replay(problem, short)
