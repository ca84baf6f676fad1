"""Careless or hostile input: one line and exit 2 before anything starts, bounded in
what it may read and expand to (no ROS graph is started here)."""

import json
from pathlib import Path

import pytest
from commands import one_line_exit_2, script

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = ROOT / "scripts"
BOMB = "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{chr(98 + i)}: &{chr(98 + i)} [*{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, "
    f"*{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}]\n"
    for i in range(9))  # 9 * 8^9 = 1.2e9 elements once expanded




def line_file(tmp_path: Path, body: str = "", length: str = "1000") -> Path:
    path = tmp_path / "line.yaml"
    path.write_text(f"name: t\nlength: {length}\nspeed_limits:\n"
                    f"  - {{start: 0, end: {length}, limit: 20}}\nstations:\n"
                    f"  - {{name: B, position: 900}}\n{body}")
    return path


@pytest.mark.parametrize("text, words", [
    (BOMB, ["anchors and aliases"]),
    ("/**:\n  ros__parameters:\n    run.duration: 5\n    run.duration: 6\n", ["given twice"]),
    ("/**: " + "[" * 60 + "]" * 60 + "\n", ["nested deeper"]),
])
def test_scenario_files_that_would_exhaust_or_mislead(tmp_path, text, words):
    scenario = tmp_path / "s.yaml"
    scenario.write_text(text)
    one_line_exit_2(script("run_stack.py", "--scenario", scenario, "--out", tmp_path / "b"),
                    str(scenario), *words)


def test_a_binary_scenario_file(tmp_path):
    scenario = tmp_path / "s.yaml"
    scenario.write_bytes(bytes(range(256)) * 4)
    one_line_exit_2(script("run_stack.py", "--scenario", scenario), "not UTF-8")


@pytest.mark.parametrize("make, words", [
    (lambda tmp: "/dev/zero", ["not a regular file"]),
    (lambda tmp: line_file(tmp, length="1e9"), ["beyond"]),
    (lambda tmp: line_file(tmp, "gradients:\n  - {start: 0, end: 500, grade: .nan}\n"),
     ["finite number"]),
    (lambda tmp: line_file(tmp, "x: &x 1\n"), ["anchors and aliases"]),
])
def test_line_files_that_would_exhaust_or_mislead(tmp_path, make, words):
    result = script("run_stack.py", "--scenario", "seed004-metro", "--set",
                    f"line.file={make(tmp_path)}", "--out", tmp_path / "b")
    one_line_exit_2(result, *words)


@pytest.mark.parametrize("args, words", [
    (["--set", "run.period=1e-9"], ["run.period = 1e-09 is out of range"]),
    (["--set", "adrc.mu1=1", "--set", "adrc.mu1=2"], ["adrc.mu1 is given twice"]),
    (["--timeout", "-1"], ["--timeout must be a positive"]),
    (["--timeout", "nan"], ["--timeout must be a positive"]),
    (["--out", "/proc/version/bag"], ["/proc/version"]),
    (["--out", "bags/" + "x" * 300], ["longer than 255"]),
    (["--out", "/tmp/" + "/".join(["x" * 200] * 25)], ["longer than the system allows"]),
    (["--out", "/sys/bag"], ["/sys/bag", "cannot be written"]),
    (["--out", "/proc/bag"], ["/proc/bag", "cannot be written"]),
])
@pytest.mark.slow
def test_run_stack_options(args, words):
    one_line_exit_2(script("run_stack.py", *args), *words)


@pytest.mark.slow
def test_tuning_options_and_logs(tmp_path):
    base = ["--algorithm", "pso", "--scenario", "seed000", "--in-process", "--params",
            "adrc.mu1=600:60000", "--evaluations", "8", "--population", "4", "--set",
            "run.duration=1", "--quiet"]
    one_line_exit_2(script("tune.py", *base, "--out", tmp_path / "a", "--require",
                           "max_jerk<=nan"), "finite")
    one_line_exit_2(script("tune.py", *base, "--out", tmp_path / "a", "--timeout", "0"),
                    "--timeout")
    out = tmp_path / "t"
    assert script("tune.py", *base, "--out", out).returncode == 0
    log = out / "evaluations.jsonl"
    lines = log.read_text().splitlines()
    lines[2] = lines[2][:30]
    log.write_text("\n".join(lines) + "\n")
    one_line_exit_2(script("tune.py", *base, "--out", out, "--resume"),
                    f"{log} line 3 is not an evaluation record")
    log.write_text("\n".join(lines[:2] + [lines[3][:40]]) + "\n")  # cut short at the end
    resumed = script("tune.py", *base, "--out", out, "--resume")
    assert resumed.returncode == 0 and "line 3 is incomplete" in resumed.stderr


@pytest.mark.slow
def test_replay_times_must_be_finite(tmp_path):
    one_line_exit_2(script("replay_bag.py", tmp_path, "--start", "nan"), "finite")
    one_line_exit_2(script("replay_bag.py", tmp_path, "--end", "1e300"), "finite")


def test_bags_with_broken_metadata_or_embedded_line_are_one_line(tmp_path):
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: [unclosed\n")
    (bag / "bag.mcap").write_bytes(b"\x89MCAP0\r\n")
    one_line_exit_2(script("score_bag.py", bag), str(bag))


@pytest.mark.parametrize("model, words", [
    (b"PK\x03\x04 cut short", ["not a readable .npz"]),
    (None, ["cannot read model file"]),
])
def test_a_bad_gpc_model_file_stops_run_stack_before_anything_starts(tmp_path, model, words):
    path = tmp_path / "model.npz"
    if model is not None:
        path.write_bytes(model)
    result = script("run_stack.py", "--scenario", "seed001-crh380al", "--set",
                    f"gpc.model={path}", "--out", tmp_path / "bag")
    one_line_exit_2(result, *words)
    assert not (tmp_path / "bag").exists()


def test_a_truncated_shipped_model_stops_run_stack(tmp_path):
    shipped = (ROOT / "msg_config" / "models" / "crh380al-lssvm.npz").read_bytes()
    path = tmp_path / "cut.npz"
    path.write_bytes(shipped[:len(shipped) * 2 // 3])
    one_line_exit_2(script("run_stack.py", "--scenario", "seed001-crh380al", "--set",
                           f"gpc.model={path}", "--out", tmp_path / "bag"), "model file")


@pytest.mark.parametrize("args, words", [
    (["--speed-lags", "0"], ["speed lag"]),
    (["--train", "1600"], ["--train"]),
    (["--out", "model.txt"], [".npz"]),
])
def test_identify_refuses_bad_options_in_one_line(tmp_path, args, words):
    options = ["--out", tmp_path / "m.npz", *args] if "--out" not in args else args
    one_line_exit_2(script("identify.py", tmp_path / "no-bag", *options), *words)


def test_identify_refuses_a_missing_bag_in_one_line(tmp_path):
    one_line_exit_2(script("identify.py", tmp_path / "no-bag", "--out", tmp_path / "m.npz"),
                    "no-bag")


@pytest.mark.parametrize("args, words", [
    (["--time", "600"], ["shorter than the flat-out run"]),
    (["--line", "lines/no-such-line.yaml"], ["no-such-line"]),
    (["--train", "nonexistent"], ["nonexistent"]),
])
def test_optimize_strategy_refuses_impossible_plans_in_one_line(tmp_path, args, words):
    base = {"--line": "lines/lanxin-67km.yaml", "--train": "crh5"}
    base.update(dict(zip(args[::2], args[1::2], strict=True)))
    options = [item for pair in base.items() for item in pair]
    extra = [a for a in args if a not in base and a not in base.values()]
    result = script("optimize_strategy.py", *options, *extra, "--algorithm", "flatout",
                    "--out", tmp_path / "out")
    one_line_exit_2(result, *words)
    assert not (tmp_path / "out").exists()


def test_optimize_strategy_refuses_a_line_without_a_stop(tmp_path):
    path = line_file(tmp_path).read_text().replace("position: 900", "position: 0")
    (tmp_path / "nostop.yaml").write_text(path)
    one_line_exit_2(script("optimize_strategy.py", "--line", tmp_path / "nostop.yaml",
                           "--train", "crh5", "--algorithm", "dp", "--out", tmp_path / "o"),
                    "no stop")


def model_with(tmp_path: Path, name: str, array) -> Path:
    """The shipped model with one member replaced."""
    import io
    import zipfile
    import numpy as np
    with zipfile.ZipFile(ROOT / "msg_config" / "models" / "crh380al-lssvm.npz") as shipped:
        stored = {info.filename: shipped.read(info) for info in shipped.infolist()}
    buffer = io.BytesIO()
    np.save(buffer, array)
    stored[f"{name}.npy"] = buffer.getvalue()
    path = tmp_path / "edited.npz"
    with zipfile.ZipFile(path, "w") as edited:
        for member, data in stored.items():
            edited.writestr(member, data)
    return path


@pytest.mark.parametrize("make, words", [
    (lambda tmp: ["--scenario", "seed004-metro", "--set", "adrc.mu1=7000"],
     ["adrc.mu1 belongs to controller kind han_adrc; this run uses discrete_adrc (its "
      "parameters are dadrc.*)"]),
    (lambda tmp: ["--set", "recorder.output=/"], ["recorder.output is set by the launcher",
                                                   "give --out instead"]),
    (lambda tmp: ["--set", "supervisor.report=/"], ["supervisor.report is set by the launcher",
                                                     "give --out instead"]),
    (lambda tmp: ["--scenario", tmp / "folder.yaml"], ["folder.yaml is a directory"]),
    (lambda tmp: ["--scenario", "seed004-metro", "--set", "line.file=" + str(line_file(
        tmp, "  - {name: C, position: 950, dwell: -30}\n"))], ["dwell -30 s is negative"]),
    (lambda tmp: ["--scenario", "seed001-crh380al", "--set", "gpc.prediction=multimodel",
                  "--set", f"gpc.model={model_with(tmp, 'arx_width', float('nan'))}"],
     ["arx_width holds non-finite numbers"]),
])
def test_run_stack_refuses_what_would_be_ignored_or_wrong_in_one_line(tmp_path, make, words):
    (tmp_path / "folder.yaml").mkdir()
    one_line_exit_2(script("run_stack.py", *make(tmp_path), "--out", tmp_path / "bag"), *words)
    assert not (tmp_path / "bag").exists()


def test_tune_refuses_what_the_launcher_sets_and_other_kinds_parameters(tmp_path):
    base = ["--algorithm", "pso", "--scenario", "seed004-metro", "--in-process",
            "--evaluations", "4", "--population", "2", "--out", tmp_path / "t"]
    one_line_exit_2(script("tune.py", *base, "--set", "recorder.output=/"),
                    "recorder.output is set by the launcher", "--out")
    one_line_exit_2(script("tune.py", *base, "--set", "adrc.mu1=7000"),
                    "--set: adrc.mu1 belongs to controller kind han_adrc")
    assert not (tmp_path / "t").exists()


# Bags, tuning directories and report outputs that are not what the offline tools expect
# (bags written in-process, tests/bagfile.py).

def metro_bag(tmp_path: Path, name: str = "bag", overrides=(), **kept) -> Path:
    """A 5 s metro run's bag (with --set-like `overrides`); `kept` replaces parameters in
    its metadata as given ("whole": all of them)."""
    from ato_nodes.core.run.loop import simulate
    from ato_nodes.core.config.scenario import apply_overrides, load_scenario
    from bagfile import write_run_bag
    values = apply_overrides(load_scenario("seed004-metro"), ["run.duration=5", *overrides])
    bag = write_run_bag(tmp_path / name, simulate(values), values)
    if kept:
        import yaml
        from ato_nodes.bags.bagio import PARAMETERS_KEY
        metadata = yaml.safe_load((bag / "metadata.yaml").read_text())
        custom = metadata["rosbag2_bagfile_information"]["custom_data"]
        parameters = json.loads(custom[PARAMETERS_KEY])
        custom[PARAMETERS_KEY] = json.dumps(kept.get("whole", {**parameters, **kept}))
        (bag / "metadata.yaml").write_text(yaml.safe_dump(metadata))
    return bag


@pytest.mark.parametrize("kept, words", [
    ({"whole": [["run.period", 0.1]]}, ["parameters kept in metadata.yaml are a JSON list, "
                                        "not an object"]),
    ({"plant.mass": None}, ["plant.mass must be a number, not None"]),
    ({"run.period": "fast"}, ["run.period must be a number, not 'fast'"]),
])
@pytest.mark.slow
def test_offline_tools_refuse_a_bags_malformed_parameters_in_one_line(tmp_path, kept, words):
    bag = metro_bag(tmp_path, **kept)
    for name, args in (("score_bag.py", []), ("analyze.py", ["--out", tmp_path / "report"]),
                       ("export.py", ["--csv", tmp_path / "run.csv"])):
        one_line_exit_2(script(name, bag, *args), str(bag), *words)
    assert not (tmp_path / "report").exists() and not (tmp_path / "run.csv").exists()


@pytest.mark.parametrize("history, words", [
    ("iteration,evaluations,best_fitness\n0,four,1.0\n", ["history.csv line 2 is not"]),
    ("evaluations\n4\n", ["history.csv line 2 is not"]),
    ("", ["holds no history rows"]),
    (b"\xff\xfe\x00binary", ["history.csv: cannot read it"]),
])
def test_analyze_refuses_a_malformed_tuning_history_in_one_line(tmp_path, history, words):
    tuning = tmp_path / "tune"
    tuning.mkdir()
    history_file = tuning / "history.csv"
    (history_file.write_bytes if isinstance(history, bytes) else history_file.write_text)(history)
    one_line_exit_2(script("analyze.py", tuning, "--out", tmp_path / "report"), *words)
    assert not (tmp_path / "report").exists()


def test_analyze_refuses_an_out_that_is_a_file_in_one_line(tmp_path):
    taken = tmp_path / "taken"
    taken.write_text("mine\n")
    one_line_exit_2(script("analyze.py", metro_bag(tmp_path), "--out", taken),
                    f"--out {taken} exists and is not a directory")
    assert taken.read_text() == "mine\n"


@pytest.mark.slow
def test_report_markdown_shows_names_from_a_bag_as_text(tmp_path):
    """A bag's directory, scenario, train, line and station names are anyone's text: in
    report.md they stay text (no live HTML, no broken table) as in report.html."""
    import re

    from ato_nodes.reports.report import write_report
    from ato_nodes.bags.bagio import read_run
    hostile = "<svg onload=alert(1)>|x"
    line = (ROOT / "msg_config" / "lines" / "metro-interstation.yaml").read_text()
    line = line.replace("name: synthetic metro interstation (Yizhuang-like)",
                        f"name: '{hostile} line'").replace("Xiaocun (synthetic)",
                                                           "'<img src=x onerror=alert(2)>|B'")
    (tmp_path / "line.yaml").write_text(line)
    bag = metro_bag(tmp_path, hostile, [f"line.file={tmp_path / 'line.yaml'}"],
                    **{"plant.train": "<b>train</b>|t"})
    (bag / "summary.json").write_text(json.dumps({"scenario": f"{hostile} scenario"}))
    markdown, page = write_report([read_run(bag)], [], tmp_path / "report")
    text = markdown.read_text()
    for name in ("x line:", "x scenario |", "\\|B (2600 m)", "&lt;b>train&lt;/b>\\|t ("):
        assert name in text, name
    assert not re.search(r"<(svg|img|b)\b", text)
    assert text.count("&lt;svg onload=alert(1)>\\|x") >= 4  # title, table, verdict, figure
    for table in re.findall(r"(?:^\|.*\n)+", text, flags=re.M):  # a name adds no column
        cells = {len(re.findall(r"(?<!\\)\|", row)) for row in table.splitlines()}
        assert cells in ({3}, {4}), table
    assert "<svg onload" not in page.read_text() and "<img src=x" not in page.read_text()


@pytest.mark.parametrize("name", ["score_bag.py", "analyze.py", "export.py", "repair_bag.py",
                                  "screenshot_report.py"])
def test_offline_commands_help_gives_their_whole_description(name):
    from ato_nodes.cli import analyze, score_bag
    modules = {"score_bag.py": score_bag, "analyze.py": analyze}
    doc = modules[name].__doc__ if name in modules else \
        (SCRIPTS / name).read_text().split('"""')[1]
    first = " ".join(doc.split("\n\n")[0].split())
    result = script(name, "--help")
    assert result.returncode == 0, result.stderr
    assert first.endswith(".") and first in " ".join(result.stdout.split()), result.stdout
