"""The study runner (ato_nodes/studies/runner.py): variants prepared before anything runs, the
variant's own overrides winning over the study's common ones, runs scored in-process."""

import json

import pytest

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import apply_overrides, load_scenario
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.run.scoring import score_series
from ato_nodes.studies.runner import Variant, numeric, prepare_variants, run_study, write_outputs


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
