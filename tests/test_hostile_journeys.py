"""Careless or hostile journeys: line files, timetables and bags of journey runs. Bad
input is one line (exit 2 from a command) before anything starts, the stack and
in-process alike; a journey bag is scored on the timetable and the line it kept,
wherever their files were and whatever became of them since."""

import base64
import hashlib
import re
import shutil
from pathlib import Path

import pytest
from bagfile import write_run_bag
from commands import one_line_exit_2, script

from ato_nodes.bags.bagio import read_run, resimulate
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import prepare
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.run.scoring import LINE_BASE64, encode_line, kept_files
from ato_nodes.core.targets.timetable import LATEST_TIME, load_timetable
from ato_nodes.core.train.line import parse_line
from ato_nodes.results.journeys import TIMETABLE, run_timetable

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "msg_config"
METRO_LINE = (CONFIG / "lines" / "metro-line.yaml").read_text()
METRO_TIMETABLE = (CONFIG / "timetables" / "metro-line.yaml").read_text()
MARKET = "{name: Market (synthetic), position: 1550.0"
TIMETABLE_LINE = "line: lines/metro-line.yaml"




def timetable_file(tmp_path: Path, name: str = "timetable.yaml", line: str | None = None,
                   change: tuple[str, str] | None = None) -> Path:
    """The metro timetable on the shipped line (`line:` absolute unless given), with the
    text `change` (old, new) put in."""
    text = METRO_TIMETABLE.replace(TIMETABLE_LINE,
                                   f"line: {line or CONFIG / 'lines' / 'metro-line.yaml'}")
    if change is not None:
        assert change[0] in text
        text = text.replace(*change)
    path = tmp_path / name
    path.write_text(text)
    return path


# ---------------------------------------------------------------- station names ----

HEAD = "name: t\nlength: 3000\nspeed_limits:\n  - {start: 0, end: 3000, limit: 20}\nstations:\n"


@pytest.mark.parametrize("stations, line, words", [
    ("  - {name: A, position: 0}\n  - {name: B, position: 1000}\n  - {name: B, position: 2000}\n",
     8, ["'B' is already the name of the station at 1000 m"]),
    ("  - {name: A, position: 0}\n  - {position: 1000}\n", 7, ["missing 'name'"]),
    ("  - {name: A, position: 0}\n  - {name: [B, C], position: 1000}\n", 7,
     ["a name is text, not ['B', 'C']"]),
    ("  - {name: A, position: 0}\n  - {name: , position: 1000}\n", 7, ["a name is text"]),
])
def test_a_line_refuses_a_station_named_twice_unnamed_or_not_by_text(stations, line, words):
    with pytest.raises(ScenarioError) as refused:
        parse_line(HEAD + stations, "/tmp/l.yaml")
    assert str(refused.value).startswith(f"/tmp/l.yaml line {line}: stations: ")
    for word in words:
        assert word in str(refused.value)


def test_an_empty_value_in_a_line_or_timetable_is_one_line():
    """`key:` with nothing after it once escaped as a YAML ParserError traceback."""
    with pytest.raises(ScenarioError, match=r"^/tmp/l.yaml line 4: limit must be a finite "
                       "number, not None$"):
        parse_line(HEAD.replace("limit: 20", "limit: "), "/tmp/l.yaml")


def test_a_timetable_stop_names_one_station_of_its_line(tmp_path):
    """The metro line with Riverside's name given to Market too: refused on load (its stop
    once took the last of the two, the train driving 1.8 km further for 'Market')."""
    line = tmp_path / "line.yaml"
    line.write_text(METRO_LINE.replace("Riverside (synthetic), position", "Market (synthetic), "
                                       "position"))
    path = timetable_file(tmp_path, line=str(line))
    with pytest.raises(ScenarioError, match=rf"^{re.escape(str(path))} line 13: line: "
                       rf"{re.escape(str(line))} line 64: stations: 'Market \(synthetic\)' is "
                       "already"):
        load_timetable(path)


# ---------------------------------------------------------------- timetables ----

@pytest.mark.parametrize("replaced, key", [
    (("arrival: 989}", "arrival: 1e300}"), "arrival 1e+300"),
    (("arrival: 131, departure: 156", "arrival: 131, departure: 1e300"), "departure 1e+300"),
    (("departure: 0}", "departure: -700000}"), "departure -700000"),
])
def test_a_time_beyond_a_week_of_the_journeys_clock_is_refused_on_load(tmp_path, replaced, key):
    path = timetable_file(tmp_path, change=replaced)
    with pytest.raises(ScenarioError, match=rf"^{re.escape(str(path))} line \d+: stops: "
                       rf"{re.escape(key)} s is more than {LATEST_TIME:g} s \(7 days\)"):
        load_timetable(path)


def test_plan_journey_refuses_an_absurd_arrival_in_one_short_line(tmp_path):
    path = timetable_file(tmp_path, change=("arrival: 989}", "arrival: 1e300}"))
    said = one_line_exit_2(script("plan_journey.py", "metro-line", "--timetable", path),
                           str(path), "arrival 1e+300 s")
    assert len(said) < 200


@pytest.mark.slow
def test_a_run_refuses_a_timetable_its_train_cannot_keep(tmp_path):
    """10 s for the 1.55 km to Market, whose minimum is over 120 s: refused by prepare()
    (what robustness.py and tune --in-process run) as by plan_journey.py, not warned."""
    path = timetable_file(tmp_path, change=("arrival: 131, departure: 156",
                                            "arrival: 10, departure: 35"))
    with pytest.raises(ScenarioError, match=rf"^parameters: {re.escape(str(path))} line 18: the "
                       r"running time 10 s from Westgate \(synthetic\) to Market \(synthetic\) "
                       r"is below its minimum 1[2-3]\d(\.\d)? s"):
        prepare("seed004-metro-line", [f"{TIMETABLE}={path}"])
    one_line_exit_2(script("plan_journey.py", "metro-line", "--timetable", path),
                    "running time 10 s", "below its minimum")


@pytest.mark.slow
def test_run_stack_refuses_an_impossible_timetable_before_anything_starts(tmp_path):
    path = timetable_file(tmp_path, change=("arrival: 131, departure: 156",
                                            "arrival: 10, departure: 35"))
    bag = tmp_path / "bag"
    one_line_exit_2(script("run_stack", "--scenario", "seed004-metro-line", "--quiet",
                           "--set", f"{TIMETABLE}={path}", "--out", bag),
                    str(path), "below its minimum")
    assert not bag.exists()


def test_stops_too_close_for_per_station_indices_are_refused_before_the_run(tmp_path):
    line = tmp_path / "line.yaml"
    line.write_text(METRO_LINE.replace(MARKET, "{name: Market (synthetic), position: 60.0"))
    path = timetable_file(tmp_path, line=str(line))
    with pytest.raises(ScenarioError, match=rf"^parameters: {re.escape(str(path))}: the stop "
                       r"window 50 m must be positive and under half the shortest section "
                       r"\(Westgate \(synthetic\) - Market \(synthetic\), 60 m\)"):
        prepare("seed004-metro-line", [f"{TIMETABLE}={path}", f"line.file={line}"])


def test_a_journey_refuses_line_planned_run_time_naming_why():
    with pytest.raises(ScenarioError, match=r"^parameters: line.planned_run_time 500 s does not "
                       r"apply to a journey \(profile.kind journey\): its timetable .*gives"):
        prepare("seed004-metro-line", ["line.planned_run_time=500"])


@pytest.mark.slow
def test_a_studys_runs_check_their_timetable_once(monkeypatch):
    """Each draw of a study (its own plant.mass_factor, noise seed) is validated again; the
    minimum running times are of the nominal train and are not built again."""
    from ato_nodes.core.targets import timetable
    prepare("seed004-metro-line")
    monkeypatch.setattr(timetable, "new_ato_curve", None)  # a curve built again would fail
    drawn = prepare("seed004-metro-line", ["plant.mass_factor=1.2", "plant.noise_seed=7"])
    assert drawn["plant.mass_factor"] == 1.2


# ---------------------------------------------------------------- plan_journey.py ----

@pytest.mark.slow
def test_plan_journey_takes_a_line_and_a_timetable_given_as_files(tmp_path):
    shutil.copy(CONFIG / "lines" / "metro-line.yaml", tmp_path / "my-line.yaml")
    path = timetable_file(tmp_path, line="my-line.yaml")
    done = script("plan_journey.py", tmp_path / "my-line.yaml", "--timetable", path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("synthetic metro line, 7 stations")
    one_line_exit_2(script("plan_journey.py", tmp_path / "my-line.yaml"), "--timetable")
    one_line_exit_2(script("plan_journey.py", "metro-line", "--timetable", path),
                    f"timetable {path} is for line {tmp_path / 'my-line.yaml'}")


@pytest.mark.parametrize("given, words", [
    ("missing.yaml", ["cannot read timetable file missing.yaml"]),
    ("nowhere", ["unknown timetable 'nowhere'"]),
])
def test_plan_journey_names_the_timetable_the_user_gave(given, words):
    one_line_exit_2(script("plan_journey.py", "metro-line", "--timetable", given), *words)


def test_a_timetable_whose_line_is_nowhere_is_named_first(tmp_path):
    path = timetable_file(tmp_path, line="lines/no-such-line.yaml")
    one_line_exit_2(script("plan_journey.py", "metro-line", "--timetable", path),
                    f"{path} line 13: line: cannot read line file")


# ---------------------------------------------------------------- kept files ----

DURATION = 200.0  # s: Market reached (arrival 131 s), left, on the way to Riverside


@pytest.fixture(scope="module")
def user_run(tmp_path_factory):
    """A journey run of a user's own line and timetable outside msg_config/ (the timetable
    names the line by ../lines/, climbing out of its folder), with what its bag keeps."""
    user = tmp_path_factory.mktemp("user")
    (user / "lines").mkdir()
    (user / "timetables").mkdir()
    (user / "lines" / "my-12km.yaml").write_text(METRO_LINE)
    timetable_file(user / "timetables", "my.yaml", line="../lines/my-12km.yaml")
    scenario = user / "my.yaml"
    scenario.write_text("base: seed004-metro-line\n/**:\n  ros__parameters:\n"
                        "    line.file: lines/my-12km.yaml\n"
                        "    profile.journey.timetable: timetables/my.yaml\n"
                        f"    run.duration: {DURATION}\n")
    values = prepare(str(scenario))
    kept = {**values, LINE_BASE64: encode_line(METRO_LINE), **kept_files(values)}
    return user, kept, simulate(values)


def market_row(report: Path) -> list[str]:
    row = next(line for line in report.read_text().splitlines()
               if line.startswith("| Market (synthetic) |"))
    return [cell.strip() for cell in row.strip("|").split(" | ")]


@pytest.mark.slow
def test_analyze_reads_a_users_line_back_after_it_moved_and_went(user_run, tmp_path):
    """analyze.py once read the kept timetable's ../lines/ against msg_config/ ("cannot
    read line file <checkout>/lines/my-12km.yaml"); a line since edited was read as it is
    now (Market 150 m further: "no standstill within 50 m"); a line since deleted gave no
    report at all."""
    user, parameters, series = user_run
    bag = write_run_bag(tmp_path / "bag", series, parameters, status="completed")
    first = script("analyze", bag, "--out", tmp_path / "r1")
    assert first.returncode == 0, first.stderr
    assert market_row(tmp_path / "r1" / "report.md")[8] == "pass"
    moved = user / "lines" / "my-12km.yaml"
    moved.write_text(METRO_LINE.replace(MARKET, "{name: Market (synthetic), position: 1700.0"))
    again = script("analyze", bag, "--out", tmp_path / "r2")
    assert again.returncode == 0, again.stderr
    assert market_row(tmp_path / "r2" / "report.md") == market_row(tmp_path / "r1" / "report.md")
    moved.unlink()
    (user / "timetables" / "my.yaml").unlink()
    gone = script("analyze", bag, "--out", tmp_path / "r3")
    assert gone.returncode == 0, gone.stderr
    assert market_row(tmp_path / "r3" / "report.md") == market_row(tmp_path / "r1" / "report.md")


def test_a_kept_timetable_is_read_on_the_kept_line_whatever_its_line_names(user_run, tmp_path):
    """The copy's `line:` absolute, relative or climbing, to a file edited or gone: the
    stations are the kept line's."""
    _, parameters, _ = user_run
    edited = tmp_path / "edited.yaml"
    edited.write_text(METRO_LINE.replace(MARKET, "{name: Market (synthetic), position: 1700.0"))
    for named in (str(edited), "edited.yaml", "../../nowhere/line.yaml", str(tmp_path / "gone")):
        text = METRO_TIMETABLE.replace(TIMETABLE_LINE, f"line: {named}").encode()
        copy = dict(parameters, **{f"{TIMETABLE}.base64": base64.b64encode(text).decode(),
                                   f"{TIMETABLE}.sha256": hashlib.sha256(text).hexdigest()})
        timetable = run_timetable(copy)
        assert timetable.stops[1].position == 1550.0, named
        assert timetable.line == parse_line(METRO_LINE, "kept")



def test_a_users_journey_bag_runs_again_bit_for_bit_after_its_files_went(user_run, tmp_path):
    """The kept timetable names its line by ../lines/, which the re-run's copy of it did
    not find ("cannot simulate the run again: ... cannot read line file"), even with the
    user's files in place."""
    user, parameters, series = user_run
    (user / "lines" / "my-12km.yaml").write_text(METRO_LINE)  # as the run found them
    timetable_file(user / "timetables", "my.yaml", line="../lines/my-12km.yaml")
    bag = write_run_bag(tmp_path / "bag", series, parameters, status="completed")
    for files in ("kept", "gone"):
        assert resimulate(read_run(bag))[1] == [], files
        for left in (user / "lines" / "my-12km.yaml", user / "timetables" / "my.yaml"):
            left.unlink(missing_ok=True)
