"""TTOBench's files (msg_config/ttobench/) read as the project's line, plant values and
journey: every file loads, the tracks agree with the library's own summary (tracks.csv),
the conversions agree with numbers worked by hand, and every problem is one line naming
the file and the field (exit 2 through the command)."""

import copy
import csv
import json
import math
import shutil
import subprocess

import pytest

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.base.paths import config_dir
from ato_nodes.core.config.scenario import train_preset
from ato_nodes.core.targets.timetable import journey_file, load_timetable
from ato_nodes.core.train.adhesion import UNLIMITED
from ato_nodes.core.train.lines import load_line_file
from ato_nodes.core.train.line import CURVE_CONSTANT, TUNNEL_CONSTANT
from ato_nodes.core.train.plant import TrainParameters
from ato_nodes.core.train.ttobench import (
    Curvature,
    is_library_file,
    load_journey,
    load_track,
    load_train,
    mean_curvature,
)
from commands import invocation

DATA = config_dir() / "ttobench"
TRACKS = sorted((DATA / "tracks").glob("*.json"))
TRAINS = sorted((DATA / "trains").glob("*.json"))
JOURNEYS = sorted((DATA / "journeys").glob("*.json"))
GRAVITY = 9.8  # plant.gravity's default, the one the hand-worked numbers use


def test_every_file_loads():
    assert len(TRACKS) == 16 and len(TRAINS) == 4 and len(JOURNEYS) == 1
    for path in TRACKS:
        track = load_track(path)
        line = track.line()
        assert line.length == track.length == track.stops[-1]
        assert [station.position for station in line.stations] == list(track.stops)
        assert line.speed_limits[0].start == 0 and line.speed_limits[-1].end == line.length
        assert all(section.value > 0 for section in line.speed_limits)
        line.additional_resistances([0.0, line.length / 2, line.length], 100.0)
    for path in TRAINS:
        train = load_train(path)
        assert train.plant_values(GRAVITY)["plant.mass"] == train.mass / 1000.0
    for path in JOURNEYS:
        journey = load_journey(path)
        track = load_track(DATA / "tracks" / f"{journey.track_id}.json")
        assert load_journey(path, track).points == journey.points
        track.line(journey)


def library_summary() -> dict[str, dict[str, str]]:
    with open(DATA / "tracks" / "tracks.csv", newline="") as handle:
        return {row["ID"]: row for row in csv.DictReader(handle)}


def test_tracks_agree_with_the_library_summary():
    """tracks.csv (the library's own table) gives each track's length, stops, speed
    limits (km/h), gradients (per mille) and least absolute radius (all but the one with
    tunnels, which is newer); the readers give the same, so positions, units and signs
    are read as the library means them."""
    summary = library_summary()
    assert {path.stem for path in TRACKS} - set(summary) == {"00_reference_with_tunnels"}
    for name, row in summary.items():
        track = load_track(DATA / "tracks" / f"{name}.json")
        line = track.line()
        limits = [section.value * 3.6 for section in line.speed_limits]
        grades = [section.value for section in line.gradients] or [0.0]
        radii = [abs(radius) for curve in track.curvatures
                 for radius in (curve.radius_start, curve.radius_end)] or [math.inf]
        assert track.length == pytest.approx(float(row["Length [m]"]))
        assert len(track.stops) == int(row["Num stops [-]"])
        assert min(limits) == pytest.approx(float(row["Min speed limit [km/h]"]))
        assert max(limits) == pytest.approx(float(row["Max speed limit [km/h]"]))
        assert min(grades) == pytest.approx(float(row["Min gradient [permil]"]))
        assert max(grades) == pytest.approx(float(row["Max gradient [permil]"]))
        assert min(radii) == pytest.approx(float(row["Min (abs) radius [m]"]))


def track_document(**fields) -> dict:
    """A small valid track (1000 m, a stop at 600 m), with `fields` replacing its own."""
    document = {
        "metadata": {"id": "test_track", "library version": "TTOBench v1.4"},
        "stops": {"unit": "m", "values": [0.0, 600.0, 1000.0]},
        "speed limits": {"units": {"position": "m", "velocity": "km/h"},
                         "values": [[0.0, 72], [500.0, 36]]},
        "gradients": {"units": {"position": "m", "slope": "permil"},
                      "values": [[0.0, 10.0], [400.0, -5.0]]},
        "curvatures": {"units": {"position": "m", "radius at start": "m",
                                 "radius at end": "m"},
                       "values": [[0.0, "infinity", "infinity"], [100.0, "infinity", 500.0],
                                  [200.0, 500.0, 500.0], [300.0, -1000.0, 1000.0],
                                  [400.0, "infinity", "infinity"]]},
        "tunnels": {"units": {"position": "m", "length": "m", "cross section": "m^2"},
                    "values": [[700.0, 200.0, 40.0]]},
    }
    document.update(fields)
    return document


def write(tmp_path, document, name="test_track.json"):
    path = tmp_path / name
    path.write_text(json.dumps(document) if not isinstance(document, str) else document)
    return path


def test_a_track_is_read_as_the_library_states_it(tmp_path):
    """By hand: limits 72 and 36 km/h are 20 and 10 m/s; grade +10 per mille (uphill,
    the library's sign) is +10 N/kN, the project's sign; the clothoid from straight to
    R = 500 m over 100..200 m has curvature 0 -> 1/500, mean 1/1000 1/m, so a section of
    R = 1000 m: 600/1000 = 0.6 N/kN, the clothoid's mean curve resistance; the circle
    over 200..300 m is 600/500 = 1.2 N/kN; the reverse transition from R = -1000 m to
    +1000 m crosses k = 0 halfway: mean |k| = (0.001^2 + 0.001^2) / (2 (0.001 + 0.001))
    = 0.0005 1/m, R = 2000 m, 0.3 N/kN; straight sections add nothing; the 200 m tunnel
    adds 0.00013 x 200 = 0.026 N/kN (the project's formula)."""
    track = load_track(write(tmp_path, track_document()))
    line = track.line()
    assert [(s.start, s.end, s.value) for s in line.speed_limits] == [
        (0.0, 500.0, pytest.approx(20.0)), (500.0, 1000.0, pytest.approx(10.0))]
    assert [(s.start, s.end) for s in line.curves] == [(100, 200), (200, 300), (300, 400)]
    assert [CURVE_CONSTANT / s.value for s in line.curves] == pytest.approx([0.6, 1.2, 0.3])
    assert mean_curvature(-1000.0, 1000.0) == pytest.approx(0.0005)
    assert Curvature(0, 1, math.inf, math.inf).mean_curvature == 0.0
    point = line.additional_resistance
    assert point(50.0, 0.0) == pytest.approx(10.0)         # grade only
    assert point(150.0, 0.0) == pytest.approx(10.6)        # the clothoid's section
    assert point(150.0, 100.0) == pytest.approx(10.0 + (0.6 * 50 + 0.0 * 50) / 100)
    assert point(200.0, 100.0) == pytest.approx(10.6)      # the belt on the clothoid alone
    assert point(800.0, 0.0) == pytest.approx(-5.0 + TUNNEL_CONSTANT * 200.0)
    assert track.tunnels[0].cross_section == 40.0
    assert [station.name for station in line.stations] == ["km 0", "km 0.6", "km 1"]


def test_a_train_is_converted_as_worked_by_hand():
    """CH_Stadler_FLIRT_TPF: m = 122,000 kg = 122 t, rho 10 % -> gamma 0.1 (effective
    mass 134.2 t); weight m g = 122 x 9.8 = 1195.6 kN.
      a = 2.37888 kN / 1195.6 kN x 1000 = 1.98970 N/kN
      b = 0.01698165 kN/(km/h) x 3.6 (km/h per m/s) / 1195.6 x 1000 = 0.0511324 N/kN/(m/s)
      c = 0.00093264 x 3.6^2 / 1195.6 x 1000 = 0.0101096 N/kN/(m/s)^2
    traction: min(200 kN, 134.2 t x 1.1 m/s^2 = 147.62 kN), 2600 kW; brake: the blended
    200 + 1220 kN capped at 147.62 kN, which the pneumatic brake alone gives: constant up
    to v_max = 160 / 3.6 m/s, so P = 147.62 x 44.444 = 6560.89 kW.
    At 100 km/h the library's resistance is 2.37888 + 1.698165 + 9.3264 = 13.403445 kN;
    the project's w0(27.78 m/s) x 1195.6 / 1000 gives the same, and so does a 1.3 times
    heavier train converted at its own mass (air drag does not grow with the load)."""
    train = load_train(DATA / "trains" / "CH_Stadler_FLIRT_TPF.json")
    values = train.plant_values(GRAVITY)
    assert values["plant.mass"] == 122.0 and values["plant.gamma"] == pytest.approx(0.1)
    assert values["plant.davis_a"] == pytest.approx(1.98970, abs=5e-6)
    assert values["plant.davis_b"] == pytest.approx(0.0511324, abs=5e-8)
    assert values["plant.davis_c"] == pytest.approx(0.0101096, abs=5e-8)
    assert values["plant.max_traction_force"] == pytest.approx(147.62)
    assert values["plant.max_traction_power"] == pytest.approx(2600.0)
    assert values["plant.max_brake_force"] == pytest.approx(147.62)
    assert values["plant.max_brake_power"] == pytest.approx(6560.889, abs=1e-3)
    assert values["plant.length"] == 58.6 and values["plant.efficiency"] == 0.9
    kmh100 = 100 / 3.6
    for mass in (122.0, 1.3 * 122.0):
        a, b, c = train.specific_davis(mass, GRAVITY)
        specific = a + b * kmh100 + c * kmh100 ** 2
        assert specific * mass * GRAVITY / 1000 == pytest.approx(13.403445)


def test_the_brake_envelope_of_each_kind_of_train():
    """CN_Beijing_Subway states a pneumatic force of 0 kN: its envelope is the
    regenerative brake's, 260 kN and 4333 kW, as given (its comfort limit, 1 m/s^2 of 278
    t = 278 kN, the supplement's, does not bind). NL_Intercity_VIRM6: regenerative 142.5
    kN + pneumatic 273.5 kN capped at 391 t x 1.06 x 0.66 m/s^2 = 273.5436 kN; the blended
    brake falls below that only where 3616 kW / v + 273.5 kN < 273.5436 kN, at v = 3616 /
    0.0436 = 82,936 m/s, beyond its 140 km/h: constant, P = 273.5436 x 38.889 = 10,637.8
    kW. In the plant the envelope gives 260 kN / (278 x 9.8) = 95.43 N/kN at 10 m/s."""
    beijing = load_train(DATA / "trains" / "CN_Beijing_Subway.json")
    assert beijing.pneumatic_force == 0.0 and beijing.rotating_share == 0.0
    values = beijing.plant_values(GRAVITY)
    assert (values["plant.max_brake_force"], values["plant.max_brake_power"]) == (260.0, 4333.0)
    assert values["plant.max_traction_force"] == pytest.approx(278.0)
    plant = TrainParameters(
        gamma=values["plant.gamma"], gravity=GRAVITY, davis_a=values["plant.davis_a"],
        davis_b=values["plant.davis_b"], davis_c=values["plant.davis_c"],
        mass=values["plant.mass"], disturbance_amplitude=0.0, disturbance_frequency=0.0,
        disturbance_phase=0.0, max_traction_force=values["plant.max_traction_force"],
        max_traction_power=values["plant.max_traction_power"],
        max_brake_force=values["plant.max_brake_force"],
        max_brake_power=values["plant.max_brake_power"], actuator_lag=0.0, dead_time=0.0,
        length=values["plant.length"], pantograph_offset=0.0, hold_at_standstill=True,
        adhesion=UNLIMITED)
    assert plant.force_limits(10.0)[0] == pytest.approx(-260.0 / (278 * 9.8) * 1000)
    virm = load_train(DATA / "trains" / "NL_Intercity_VIRM6.json")
    force, power = virm.brake_envelope()
    assert force == pytest.approx(273543.6) and power == pytest.approx(10637806.7, abs=1.0)
    assert virm.planning_values() == {"profile.ato.deceleration": 0.66}


def test_the_library_tunnel_resistance_is_kept_beside_the_line():
    """FLIRT in a 24 m^2 tunnel at 100 km/h: 0.0011698 kN/(km/h)^2 x 100^2 = 11.698 kN."""
    train = load_train(DATA / "trains" / "CH_Stadler_FLIRT_TPF.json")
    assert train.tunnel_drag(24.0, 100 / 3.6) == pytest.approx(11698.0)
    with pytest.raises(ScenarioError, match=r"CH_Stadler_FLIRT_TPF.json: tunnel resistance: "
                       r"no coefficient for a cross section of 30 m\^2 \(given: 24, 40\)"):
        train.tunnel_drag(30.0, 10.0)


def test_the_journey_is_read_with_its_stops_and_dwells():
    """CH_StGallen_Wil_Journey_01: departs 0 m at 0 s; passes 12,500 m in [480, 540] s at
    10 km/h at least (no upper bound); arrives at 15,000 m in [620, 680] s, leaves in
    [800, 840] s: a least dwell of 800 - 680 = 120 s; passes 20,000 m in [1200, 1250] s
    with no speed bound; arrives at 29,556.1 m in [1400, 1450] s."""
    track = load_track(DATA / "tracks" / "CH_StGallen_Wil.json")
    journey = load_journey(DATA / "journeys" / "CH_StGallen_Wil_Journey_01.json", track)
    passing = journey.points[1]
    assert (passing.position, passing.earliest, passing.latest) == (12500.0, 480.0, 540.0)
    assert passing.min_speed == pytest.approx(10 / 3.6) and passing.max_speed is None
    assert not passing.stopping and journey.points[4].min_speed is None
    assert [[p.position for p in s] for s in journey.sections] == [
        [0.0, 12500.0, 15000.0], [15000.0, 20000.0, 29556.1]]
    assert journey.dwells() == {0.0: 0.0, 15000.0: 120.0, 29556.1: 0.0}
    line = track.line(journey)
    assert [(s.position, s.dwell) for s in line.stations] == [
        (0.0, 0.0), (15000.0, 120.0), (29556.1, 0.0)]
    assert [s.position for s in track.line().stations] == [0.0, 29556.1]


def test_a_library_file_is_known_by_its_json_name_in_every_reader(tmp_path, monkeypatch):
    """One predicate (is_library_file), .json in any case: a track as line.file, a train
    as plant.train and as a timetable's train, a journey as a timetable and as
    --journey's; any other name is the project's own file (a line file, a preset, a
    timetable file)."""
    for folder, stem, name in [("tracks", "CN_Songjiazhuang_Yizhuang", "track.JSON"),
                               ("trains", "CN_Beijing_Subway", "train.JSON"),
                               ("journeys", "CH_StGallen_Wil_Journey_01", "journey.JSON")]:
        shutil.copy(DATA / folder / f"{stem}.json", tmp_path / name)
    assert load_line_file(tmp_path / "track.JSON") == load_line_file(
        DATA / "tracks" / "CN_Songjiazhuang_Yizhuang.json")
    assert train_preset(str(tmp_path / "train.JSON"))["plant.mass"] == 278.0
    assert load_timetable(tmp_path / "journey.JSON").journey == "CH_StGallen_Wil_Journey_01"
    monkeypatch.chdir(tmp_path)
    assert journey_file("journey.JSON") == str((tmp_path / "journey.JSON").resolve())
    shipped = (config_dir() / "timetables" / "yizhuang-line.yaml").read_text()
    (tmp_path / "timetable.yaml").write_text(
        shipped.replace("ttobench/trains/CN_Beijing_Subway.json", "train.JSON"))
    assert load_timetable(tmp_path / "timetable.yaml").train == str(
        (tmp_path / "train.JSON").resolve())
    assert [is_library_file(name) for name in ("metro-b", "lines/metro-line.yaml",
                                               "timetables/yizhuang-line.yaml")] == [False] * 3


def edited(document: dict, edit) -> dict:
    document = copy.deepcopy(document)
    edit(document)
    return document


TRACK_PROBLEMS = [
    (lambda d: d["speed limits"]["values"][1].__setitem__(1, 0), "speed limits entry 2"),
    (lambda d: d["gradients"]["values"][1].__setitem__(0, 0.0), "gradients entry 2"),
    (lambda d: d["gradients"]["values"][0].__setitem__(0, 5.0), "gradients entry 1"),
    (lambda d: d["speed limits"]["units"].__setitem__("velocity", "m/s"), "speed limits"),
    (lambda d: d["curvatures"]["values"][1].__setitem__(2, "inf"), "curvatures entry 2"),
    (lambda d: d["curvatures"]["values"][1].__setitem__(2, 0), "curvatures entry 2"),
    (lambda d: d["tunnels"]["values"].append([800.0, 50.0, 40.0]), "tunnels entry 2"),
    (lambda d: d["tunnels"]["values"][0].__setitem__(1, 400.0), "tunnels entry 1"),
    (lambda d: d["stops"]["values"].__setitem__(1, 0.0), "stops entry 2"),
    (lambda d: d["metadata"].__setitem__("library version", "TTOBench v2.0"), "metadata"),
    (lambda d: d.pop("speed limits"), "missing field 'speed limits'"),
    (lambda d: d.__setitem__("gradient", {}), "unknown field 'gradient'"),
    (lambda d: d["speed limits"]["values"][0].__setitem__(1, True), "speed limits entry 1"),
    (lambda d: d.__setitem__("ETCS braking data", {"Kt_int": {}}), "ETCS braking data"),
]


@pytest.mark.parametrize("edit, field", TRACK_PROBLEMS)
def test_a_bad_track_is_one_line_naming_file_and_field(tmp_path, edit, field):
    path = write(tmp_path, edited(track_document(), edit))
    with pytest.raises(ScenarioError) as problem:
        load_track(path)
    message = str(problem.value)
    assert message.startswith(f"{path}: ") and field in message and "\n" not in message


@pytest.mark.parametrize("text, expected", [
    ('{"metadata": {}, "metadata": {}}', "key 'metadata' is given twice"),
    ('{"stops": NaN}', "NaN is not a number"),
    ('{\n"stops": [0, 1,\n}', "line 3: malformed JSON"),
    ("[" * 100000 + "]" * 100000, "nested too deeply"),
    ("[]", "a TTOBench track file is a JSON object"),
])
def test_a_file_that_is_no_track_json_is_one_line(tmp_path, text, expected):
    path = write(tmp_path, text)
    with pytest.raises(ScenarioError, match=expected) as problem:
        load_track(path)
    assert str(problem.value).startswith(str(path))


def train_document() -> dict:
    return json.loads((DATA / "trains" / "CH_Stadler_KISS_SBB.json").read_text())


@pytest.mark.parametrize("edit, field", [
    (lambda d: d["mass"].__setitem__("value", -1.0), "mass"),
    (lambda d: d["mass"].__setitem__("unit", "t"), "mass"),
    (lambda d: d["rho"].__setitem__("value", "10"), "rho"),
    (lambda d: d["efficiency traction"].__setitem__("value", 120.0), "efficiency traction"),
    (lambda d: d.pop("max speed"), "missing field 'max speed'"),
    (lambda d: (d["max reg braking force"].__setitem__("value", 0.0),
                d["max pn braking force"].__setitem__("value", 0.0)), "max reg braking force"),
    (lambda d: d["num seats"].__setitem__("value", 10.5), "num seats"),
])
def test_a_bad_train_is_one_line_naming_file_and_field(tmp_path, edit, field):
    path = write(tmp_path, edited(train_document(), edit), "train.json")
    with pytest.raises(ScenarioError) as problem:
        load_train(path)
    assert str(problem.value).startswith(f"{path}: ") and field in str(problem.value)


def journey_document() -> dict:
    return json.loads((DATA / "journeys" / "CH_StGallen_Wil_Journey_01.json").read_text())


def set_point(number: int, column: int, value):
    return lambda d: d["timing points"]["values"][number - 1].__setitem__(column, value)


@pytest.mark.parametrize("edit, field", [
    (set_point(2, 1, 600), "timing points entry 2"),                 # lower time > upper
    (set_point(2, 3, -5), "timing points entry 2"),                  # a negative speed
    (lambda d: d["timing points"]["values"][4].__setitem__(slice(3, 5), [50, 40]),
     "timing points entry 5"),                                       # lower speed > upper
    (set_point(1, 4, 10), "timing points"),                          # first not stopping
    (set_point(4, 4, 30), "timing points entry 4"),                  # arrival without departure
    (set_point(5, 0, 14000), "timing points entry 5"),               # position decreases
    (set_point(6, 2, 1000), "timing points entry 6"),                # window before an earlier
    (set_point(3, 0, 12500), "timing points entry 3"),               # shares a passing point's
    (lambda d: d["metadata"].__setitem__("id", "Other_Journey"), "metadata"),
    (lambda d: d["timing points"]["units"].__setitem__("position", "km"), "timing points"),
])
def test_a_bad_journey_is_one_line_naming_file_and_field(tmp_path, edit, field):
    path = write(tmp_path, edited(journey_document(), edit), "journey.json")
    with pytest.raises(ScenarioError) as problem:
        load_journey(path)
    assert str(problem.value).startswith(f"{path}: ") and field in str(problem.value)


def test_a_journey_on_another_track_or_beyond_its_end_is_refused(tmp_path):
    journey = DATA / "journeys" / "CH_StGallen_Wil_Journey_01.json"
    other = load_track(DATA / "tracks" / "CH_Fribourg_Bern.json")
    with pytest.raises(ScenarioError, match="associated track 'CH_StGallen_Wil' is not"):
        load_journey(journey, other)
    short = edited(journey_document(), set_point(6, 0, 40000.0))
    with pytest.raises(ScenarioError, match="40000 m is beyond the end of track"):
        load_journey(write(tmp_path, short, "journey.json"),
                     load_track(DATA / "tracks" / "CH_StGallen_Wil.json"))


def test_the_table_command_refuses_a_bad_file_with_one_line_and_exit_2(tmp_path):
    (tmp_path / "tracks").mkdir()
    (tmp_path / "trains").mkdir()
    broken = edited(track_document(), TRACK_PROBLEMS[0][0])
    path = write(tmp_path / "tracks", broken, "CH_Broken.json")
    write(tmp_path / "trains", train_document(), "train.json")
    done = subprocess.run([*invocation("ttobench_table.py"), "--data", str(tmp_path)],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.splitlines() == [
        f"error: {path}: speed limits entry 2: the speed limit 0 km/h must be above 0"]


def test_a_number_too_large_for_a_float_is_one_line(tmp_path):
    text = json.dumps(track_document()).replace("[500.0, 36]", "[500.0, 1" + "0" * 400 + "]")
    with pytest.raises(ScenarioError, match=r"speed limits entry 2: must be a finite number"):
        load_track(write(tmp_path, text))
