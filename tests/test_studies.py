"""The study runner (ato_nodes/studies/runner.py): variants prepared before anything runs, the
variant's own overrides winning over the study's common ones, runs scored in-process."""

import json

import pytest

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import apply_overrides, load_scenario
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.run.scoring import score_series
from ato_nodes.studies.runner import (Variant, labels, numeric, prepare_variants, run_study,
                                     write_outputs)


def test_a_variant_overrides_the_common_overrides_of_its_scenario():
    runs = prepare_variants({"base": Variant("seed004-metro"),
                             "short": Variant("seed004-metro", ["run.duration=5"]),
                             "heavy": Variant("seed004-metro", {"plant.mass_factor": 1.2})},
                            ["run.duration=10"])
    expected = apply_overrides(load_scenario("seed004-metro"), ["run.duration=10"])
    assert runs["base"] == expected
    assert runs["short"] == {**expected, "run.duration": 5.0}
    assert runs["heavy"] == {**expected, "plant.mass_factor": 1.2}


@pytest.mark.parametrize("common, variant, words", [
    (["run.duration=10", "run.duration=20"], [], "given twice"),
    ([], ["adrc.mu1=7000"], "adrc.mu1"),
    ([], ["no.such=1"], "no.such"),
])
def test_a_bad_override_is_refused_before_anything_runs(common, variant, words):
    with pytest.raises(ScenarioError, match=words):
        prepare_variants({"v": Variant("seed004-metro", variant)}, common)


def test_in_process_runs_give_the_scorer_s_indices_in_the_variants_order():
    runs = prepare_variants({"b": Variant("seed004-metro", ["dadrc.b1=60"]),
                             "a": Variant("seed004-metro")}, ["run.duration=5"])
    seen = []
    outcomes = run_study(runs, workers=1, progress=lambda label, _: seen.append(label))
    assert list(outcomes) == seen == ["b", "a"]
    for label, values in runs.items():
        # repr: the same bits, NaN (an index the short run does not give) included
        assert repr(outcomes[label].indices) == repr(score_series(simulate(values), values))
        assert outcomes[label].bag is None and outcomes[label].identical is None


def test_the_outputs_are_markdown_and_strict_json(tmp_path):
    write_outputs(tmp_path / "out", "study", markdown="| a |", report={"x": float("nan")})
    assert (tmp_path / "out" / "study.md").read_text() == "| a |\n"
    assert json.loads((tmp_path / "out" / "study.json").read_text()) == {"x": None}
    assert numeric({"a": 1, "b": 2.5, "c": "text", "d": None}) == {"a": 1, "b": 2.5}


def test_a_row_label_is_short_without_machine_paths_and_unique():
    """compare_scenarios.py's rows: the scenario's stem, each override by its name and a
    short value, a file's value by its file name; labels that coincide told apart."""
    line = "/home/someone/lines/metro-interstation.yaml"
    require = "max_abs_error_kmh<=1, abs_stopping_error<=0.3, overspeed_time<=0"
    texts = labels([
        Variant("seed004-metro-ato", ["run.duration=15"]),
        Variant("/tmp/tune-1/best.yaml", [f"line.file={line}", f"report.require={require}"]),
        Variant("/tmp/tune-2/best.yaml", [f"line.file={line}", f"report.require={require}"]),
        Variant("seed000", [f"report.require={require}"]),
        Variant("seed000", [f"report.require={require[:-1]}"]),
        Variant("seed000", {"plant.mass_factor": 1.2}),
    ])
    assert texts[0] == "seed004-metro-ato:run.duration=15"
    assert texts[1] == ("tune-1/best:line.file=metro-interstation.yaml:"
                        "report.require=max_abs_error...")
    assert texts[2].startswith("tune-2/best:")
    assert texts[3:5] == ["seed000:report.require=max_abs_error... #4",
                          "seed000:report.require=max_abs_error... #5"]
    assert texts[5] == "seed000:plant.mass_factor=1.2"
    assert len(set(texts)) == len(texts) and not any("/home" in text for text in texts)
    assert all(len(text) < 90 for text in texts)
