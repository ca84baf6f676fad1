"""The rail's adhesion, the train's position sensors and the on-board localisation
(core/train/adhesion.py, core/train/odometry.py, core/control/localisation.py,
core/run/located.py): off, the ATO reads the truth; on, it drives on its estimate."""

import numpy as np
import pytest

from ato_nodes.bags.bagio import read_series
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import apply_overrides, load_scenario, prepare
from ato_nodes.core.run.located import ODOMETRY_SERIES
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.run.scoring import limit_where_the_train_is, score_series
from ato_nodes.core.train.adhesion import (ADHESION_FACTORS, adhered, adhesion_limits,
                                           adhesion_of, wheel_creep)
from ato_nodes.core.train.lines import line_of
from ato_nodes.core.train.odometry import odometry_settings
from commands import run_stack, script

SENSED = ["odometry.enabled=true", "odometry.balise_spacing=500",
          "odometry.beacon_distances=150,50,20,5", "odometry.beacon_accuracy=0.02",
          "odometry.accelerometer=true"]


def metro(*overrides):
    return apply_overrides(load_scenario("seed004-metro-ato"), list(overrides))


def test_without_odometry_the_run_records_no_located_series_and_reads_the_truth():
    series = simulate(metro("odometry.enabled=false", "run.duration=20"), compiled=False)
    assert not set(ODOMETRY_SERIES) & set(series)


def test_a_bag_of_a_run_on_its_sensors_runs_again_bit_for_bit(tmp_path):
    """The located series hold NaN (no radar reading under 0.3 m/s, a mark read now and
    then): the same NaN are the same run."""
    from bagfile import write_run_bag

    from ato_nodes.bags.bagio import read_run, resimulate
    values = metro(*SENSED, "odometry.radar=true", "run.duration=30")
    series = simulate(values)
    assert np.isnan(series["radar_speed"]).any()
    bag = write_run_bag(tmp_path / "bag", series, values, status="completed")
    assert resimulate(read_run(bag))[1] == []


def test_overspeed_is_judged_where_the_train_is_not_where_the_ato_has_it():
    """On its sensors the run records the limit at its located position; the scorer
    judges the true speed against the limit at the true position."""
    off_values = metro("odometry.enabled=false", "run.duration=120")
    off = simulate(off_values)
    assert np.array_equal(limit_where_the_train_is(off, off_values, line_of(off_values)),
                          off["speed_limit"])  # without sensors: the recorded limit
    values = metro(*SENSED, "run.duration=120")
    series = simulate(values)
    misread = {**series, "speed_limit": np.full_like(series["speed_limit"], 0.5)}
    judged = score_series(series, values)["max_overspeed_kmh"]
    assert judged < 1.0 and score_series(misread, values)["max_overspeed_kmh"] == judged


def test_the_rails_condition_limits_the_force_and_a_slide_gives_its_share():
    wet = adhesion_of(metro("plant.adhesion=wet", "plant.motored_share=0.5"))
    dry = adhesion_of(metro("plant.adhesion=dry", "plant.motored_share=0.5"))
    low, high = adhesion_limits(10.0, wet)
    dry_low, dry_high = adhesion_limits(10.0, dry)
    assert low == pytest.approx(dry_low * ADHESION_FACTORS["wet"])
    assert high == pytest.approx(-0.5 * low)  # half the weight on motored axles
    assert adhesion_limits(0.0, dry)[1] > adhesion_limits(30.0, dry)[1]  # falls with speed
    assert adhered(0.9 * low, 10.0, wet) == 0.9 * low  # within: given as asked
    assert adhered(2.0 * low, 10.0, wet) == pytest.approx(low * wet.efficiency)
    assert wheel_creep(2.0 * low, 10.0, wet) == -wet.creep  # sliding
    assert wheel_creep(2.0 * high, 10.0, wet) == wet.creep  # slipping
    unlimited = adhesion_of(metro())
    assert adhered(-1e6, 10.0, unlimited) == -1e6


def test_each_sensor_draws_from_its_own_stream():
    plain = prepare("seed004-metro-ato", [*SENSED, "odometry.radar=false"])
    more = prepare("seed004-metro-ato", [*SENSED, "odometry.radar=true"])
    first, second = (odometry_settings(values, 0.1, 100, None, 0.0) for values in (plain, more))
    assert first.wheel_scale == second.wheel_scale
    assert first.accelerometer_bias == second.accelerometer_bias
    assert np.array_equal(first.draws[:, 1], second.draws[:, 1])
    assert not first.draws[:, 0].any() and second.draws[:, 0].any()  # the radar its own


@pytest.mark.slow
def test_the_ato_stops_on_its_located_position_within_a_decimetre_with_beacons():
    series = simulate(metro(*SENSED), compiled=False)
    located, true = series["located_position"], series["position"]
    assert abs(true[-1] - 2600.0) < 0.1  # scored on the truth
    assert abs(located[-1] - true[-1]) < 3.0 * series["position_sigma"][-1]
    assert np.abs(located - true).max() > 0.1  # it did not read the truth
    assert not np.array_equal(series["measured_speed"], series["speed"])
    assert np.isfinite(series["mark_reading"]).sum() >= 9  # five balises, four beacons
    stood = series["speed"] == 0.0
    stood[:np.argmax(series["speed"] > 0.0)] = False  # after its departure
    assert stood.sum() > 100  # it stands at its stop for more than 10 s: held there
    assert np.ptp(located[stood][10:]) == 0.0 and not series["measured_speed"][stood][10:].any()
    assert not (series["target"][stood][-1]), "the profile's berth took the stop"
    departing = np.argmax(series["speed"] > 0.1)  # never held while it departs
    assert series["measured_speed"][departing] > 0.05


@pytest.mark.slow
def test_on_contaminated_rail_the_wheels_slide_and_the_localisation_sees_it():
    series = simulate(metro(*SENSED, "plant.adhesion=contaminated"), compiled=False)
    sliding = series["wheel_creep"] < 0.0
    assert sliding.any()
    detected = series["slide_detected"] < 0.0
    assert (detected & np.roll(sliding, 1)).any()  # a slide seen the step after it began


def test_a_bad_beacon_list_is_one_line():
    with pytest.raises(ScenarioError, match="odometry.beacon_distances"):
        prepare("seed004-metro-ato", ["odometry.beacon_distances=5;20"])


@pytest.mark.slow
def test_the_tachometer_alone_keeps_its_scale_and_errs_by_the_wheels_diameter():
    values = metro("odometry.enabled=true", "odometry.radar=false",
                   "odometry.accelerometer=false", "odometry.balise_spacing=0",
                   "odometry.beacon_distances=", "odometry.wheel_diameter_error=0.01")
    series = simulate(values, compiled=False)
    wheel = odometry_settings(values, 0.1, 10, None, 0.0).wheel_scale
    assert not series["scale_error"].any()  # no mark, no radar: e stays at its prior
    travelled = series["position"][-1] - series["position"][0]
    located = series["located_position"][-1] - series["located_position"][0]
    assert located == pytest.approx(travelled / wheel, abs=0.05)  # the count, no drift


@pytest.mark.slow
def test_the_radar_finds_the_odometers_scale_without_marks():
    values = metro("odometry.enabled=true", "odometry.radar=true",
                   "odometry.wheel_diameter_error=0.01")
    series = simulate(values, compiled=False)
    wheel = odometry_settings(values, 0.1, 10, None, 0.0).wheel_scale
    assert series["scale_error"][-1] == pytest.approx(1.0 / wheel - 1.0, abs=0.002)


@pytest.mark.slow
def test_on_contaminated_rail_the_degraded_mode_replans_within_the_rail_and_stops_at_the_mark():
    """Without it the planned braking asks more than the rail gives: the train slides past
    the mark; with it the departure's slips show the rail and the curve is re-planned
    within it, said as degraded adhesion."""
    rail = [*SENSED, "odometry.radar=true", "plant.adhesion=contaminated",
            "plant.motored_share=0.667", "run.duration=400", "estimator.enabled=false",
            "profile.replan.enabled=false"]  # the re-plans for the rail alone
    blind = simulate(metro(*rail))
    assert blind["position"][-1] - 2600.0 > 2.0  # past the mark
    replans = []
    degraded = simulate(metro(*rail, "profile.degraded.enabled=true"), replans=replans)
    assert abs(degraded["position"][-1] - 2600.0) < 0.3
    assert replans and all(replan.adhesion < 1.0 for replan in replans)
    assert "degraded adhesion" in replans[0].text()
    seen = degraded["adhesion_seen"][np.isfinite(degraded["adhesion_seen"])]
    assert seen.size and abs(seen[-1] / 0.2 - 1.0) < 0.25  # the rail's factor, 0.2
    assert np.all(np.isnan(simulate(metro(*SENSED, "plant.adhesion=dry",
                                          "plant.motored_share=0.667"))["adhesion_seen"]))


def test_the_degraded_mode_needs_the_localisation_that_sees_the_rail():
    with pytest.raises(ScenarioError, match="profile.degraded.enabled"):
        prepare("seed004-metro-ato", ["profile.degraded.enabled=true", "odometry.enabled=false"])
    with pytest.raises(ScenarioError, match="odometry.accelerometer or odometry.radar"):
        prepare("seed004-metro-ato", ["profile.degraded.enabled=true", "odometry.enabled=true",
                                      "odometry.accelerometer=false", "odometry.radar=false"])


# A train of a wet-rail study (seed 1, sample 54 of seed004-metro-ato) whose wheels slip
# under full traction just before the line's limit rises 200 m out
SLIPPING_TRAIN = ["run.duration=60", "plant.adhesion=wet", "plant.motored_share=0.667",
                  "profile.degraded.enabled=true", "plant.mass_factor=0.9217981550334462",
                  "plant.resistance_factor=1.1946685749465082",
                  "plant.lag_factor=1.2983890344069313", "plant.noise_seed=1593272116",
                  "train.load_weighing_seed=1083626686", "odometry.seed=522334131",
                  "plant.adhesion_scale=1.119330297656854"]


def test_a_slipping_trains_command_is_held_at_what_the_rail_gives():
    """With controller.slip_hold (the on-board preset's) the jerk limit ramps from the
    force the rail gives while the wheels slip: the command is not wound up to its
    ceiling and the train does not pass its limit once it grips again (without: 0.59
    km/h over it)."""
    held = prepare("seed004-metro-ato", SLIPPING_TRAIN)
    assert held["controller.slip_hold"]
    series = simulate(held)
    slipping = series["wheel_creep"] > 0.0
    assert slipping.any()
    after = np.flatnonzero(slipping[:-1]) + 1  # the step after each slipping period
    assert np.all(series["command"][after] <= series["force"][after])  # the wheels may grip
    wound = simulate(apply_overrides(held, ["controller.slip_hold=false"]))
    assert series["command"][slipping].max() < wound["command"][wound["wheel_creep"] > 0].max()
    over = {name: score_series(run, held)["max_overspeed_kmh"]
            for name, run in (("held", series), ("wound", wound))}
    assert over["held"] == 0.0 < over["wound"]


def test_the_slip_hold_needs_the_jerk_limit_it_ramps():
    with pytest.raises(ScenarioError, match="controller.slip_hold .* controller.max_rate"):
        prepare("seed004-metro-ato", ["controller.max_rate=0"])


@pytest.mark.integration
def test_a_slipping_train_through_the_stack_is_the_in_process_run(tmp_path):
    """The drive's effort reaches the controller node on its own topic, step by step: the
    held commands, and every series, are the loop's bits."""
    run_stack("seed004-metro-ato", tmp_path / "bag", SLIPPING_TRAIN)
    stack = read_series(tmp_path / "bag")
    looped = simulate(prepare("seed004-metro-ato", SLIPPING_TRAIN))
    assert (looped["wheel_creep"] > 0.0).any()
    for name in set(looped) - {"t"}:
        assert np.array_equal(stack[name], looped[name], equal_nan=True), name


def test_the_accuracy_study_runs_each_sensor_set_it_names(tmp_path):
    """scripts/localisation_accuracy.py on a scenario with its own sensors (ato-on-board):
    every case runs the sensors its label names, not the scenario's (fails before: five
    identical rows)."""
    result = script("localisation_accuracy.py", "--figure", tmp_path / "accuracy.png")
    assert result.returncode == 0, result.stderr
    rows = [line for line in result.stdout.splitlines() if line.startswith("| tach")]
    assert len(rows) == 5 and len({row.split("|")[2] for row in rows}) >= 3, result.stdout
