"""Studies: named variants of a run, run side by side and set in one table.

What the study commands share (scripts/ablation.py, robustness.py, compare_scenarios.py,
compare_seed001.py; compare_strategies.py its pool and outputs, compare_tuners.py its
outputs, their variants being optimisations): each variant is a scenario and the
overrides that make it, prepared (loaded, overridden, checked) before anything runs;
the runs go in-process in a pool of processes, or through the stack one after another,
each scored from its bag and checked bit for bit against the same run in-process, or
either kind on a Dask cluster (backend.py); the study's Markdown table and its JSON
report go to its output directory. A study of many numbered samples (robustness.py)
draws and prepares each in the worker that runs it, streams its rows to a file and
resumes (samples.py).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ato_nodes.results import jsontext
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import apply_overrides, prepare
from ato_nodes.core.config.schema import FILE_PARAMETERS
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.run.scoring import score_series
from ato_nodes.studies.backend import Backend


# A study's counts, checked before anything is drawn, prepared or started (check_counts()).
MAX_WORKERS = 64      # processes of a pool: more than the machine's cores only share them
MAX_SAMPLES = 10_000  # runs of a study (robustness.py: samples.csv and its report)
MAX_SEED = 2**31 - 1  # a study's seed, as the schema's (plant.noise_seed and the others)
MAX_EVALUATIONS = 1_000_000  # a league's tuning budget per kind
COUNT_BOUNDS = {"samples": (1, MAX_SAMPLES), "workers": (1, MAX_WORKERS), "seed": (0, MAX_SEED),
                "seeds": (0, MAX_SEED), "population": (2, MAX_SAMPLES),
                "trains": (1, MAX_SAMPLES), "tune": (0, MAX_EVALUATIONS)}


def check_counts(**counts: int | Sequence[int]) -> None:
    """ScenarioError (one line naming the option --NAME and its bound, COUNT_BOUNDS) for
    the first count out of its bounds; a list (--seeds) is checked value by value, a
    value too long to read is said by its number of digits."""
    for name, given in counts.items():
        low, high = COUNT_BOUNDS[name]
        for value in given if isinstance(given, Sequence) else [given]:
            if not low <= value <= high:
                text = (str(value) if abs(value) < 10**15
                        else f"a number of {len(str(abs(value)))} digits")
                raise ScenarioError(f"--{name} must be {low} to {high:,}, not {text}")


@dataclass(frozen=True)
class Variant:
    """A scenario (a name or a file) and the overrides (--set texts or a mapping) that
    make this variant of it; they are applied after the study's common overrides and
    win over them."""
    scenario: str
    overrides: Sequence[str] | Mapping[str, Any] = ()


SHORT_VALUE = 16  # characters of an override's value a row's label shows whole


def labels(variants: Sequence[Variant]) -> list[str]:
    """Each variant's row label, short and without machine paths: the scenario's stem
    (a file's name without its suffix) and each override as NAME=VALUE, joined by ':' as
    the command line takes them; a file's value shown by its file name, a number in six
    digits, any other value longer than SHORT_VALUE cut short. Labels that coincide name
    their scenario file's folder, then their place in the list (#N): each is unique."""
    short = [_short_label(variant, folder=False) for variant in variants]
    short = [_short_label(variant, folder=True) if short.count(label) > 1 else label
             for variant, label in zip(variants, short, strict=True)]
    return [f"{label} #{number}" if short.count(label) > 1 else label
            for number, label in enumerate(short, 1)]


def _short_label(variant: Variant, folder: bool) -> str:
    scenario = Path(variant.scenario)
    name = scenario.stem if scenario.suffix in (".yaml", ".yml") else scenario.name
    if folder and scenario.parent.name:
        name = f"{scenario.parent.name}/{name}"
    overrides = (variant.overrides.items() if isinstance(variant.overrides, Mapping)
                 else (text.partition("=")[::2] for text in variant.overrides))
    return ":".join([name, *(f"{key.strip()}={short_value(key.strip(), value)}"
                             for key, value in overrides)])


def short_value(name: str, value: Any) -> str:
    """A parameter's value as a label shows it (see labels())."""
    text = f"{value:g}" if isinstance(value, float) else str(value).strip()
    if name in FILE_PARAMETERS and text:
        return Path(text).name
    return text if len(text) <= SHORT_VALUE else text[:SHORT_VALUE - 3] + "..."


def prepare_variants(variants: Mapping[str, Variant], common: Sequence[str] = ()
                     ) -> dict[str, dict[str, Any]]:
    """label -> the variant's complete, checked values. `common` (--set texts, each
    name once) applies to every variant. Raises ScenarioError (one line, naming the
    variant when its own overrides are refused)."""
    bases: dict[str, dict[str, Any]] = {}  # scenario -> its values with `common`
    prepared = {}
    for label, variant in variants.items():
        if variant.scenario not in bases:
            bases[variant.scenario] = prepare(variant.scenario, list(common))
        base = bases[variant.scenario]
        try:
            prepared[label] = (apply_overrides(base, variant.overrides) if variant.overrides
                               else base)
        except ScenarioError as exc:
            raise ScenarioError(f"{label}: {exc}") from None
    return prepared


@dataclass(frozen=True)
class Outcome:
    """One run of a study: its indices (score_series; through the stack, of its bag)
    and, through the stack, its bag and whether the same run in-process gave every
    series bit for bit."""
    indices: dict[str, Any]
    bag: Path | None = None
    identical: bool | None = None


def run_study(runs: Mapping[str, dict[str, Any]], *, workers: int = 1,
              bags: Mapping[str, Path] | None = None, cluster: str = "",
              progress: Callable[[str, Outcome], None] | None = None,
              external: Mapping[str, list[str]] | None = None) -> dict[str, Outcome]:
    """label -> Outcome of each run (label -> prepared values), in the runs' order:
    in-process in `workers` processes, or, given `bags` (label -> the bag directory to
    record), through the stack one after another; with `cluster` (--cluster) either
    kind on a Dask cluster's workers, several at once (a stack run takes a ROS domain
    of its own on its worker's host, and its bag must be a path that host writes).
    progress(label, outcome) as each outcome is known. A failed stack run raises
    RuntimeError (one line, naming its bag); a lost scheduler ClusterLost. `external`
    ({role: command}, docs/external-nodes.md) runs a node of the user's in each stack
    run, which no in-process run can repeat (Outcome.identical None)."""
    if bags is not None and not cluster:  # here: the stack takes this process's signals
        outcomes = ((label, run_through_stack(values, bags[label], external))
                    for label, values in runs.items())
        return _recorded(outcomes, progress)
    tasks = ((label, (values,) if bags is None else (values, bags[label], external))
             for label, values in runs.items())
    with Backend(workers, cluster, threads=bags is not None) as backend:
        results = _recorded(backend.stream(
            run_in_process if bags is None else run_through_stack, tasks), progress)
    return {label: results[label] for label in runs}


def _recorded(outcomes: Iterable[tuple[str, Outcome]],
              progress: Callable[[str, Outcome], None] | None) -> dict[str, Outcome]:
    results = {}
    for label, outcome in outcomes:
        results[label] = outcome
        if progress is not None:
            progress(label, outcome)
    return results


def run_in_process(values: dict[str, Any]) -> Outcome:
    return Outcome(score_series(simulate(values), values))


def run_through_stack(values: dict[str, Any], bag: Path,
                      external: Mapping[str, list[str]] | None = None) -> Outcome:
    # Imported here: the launcher loads the bag libraries, which in-process studies skip.
    from ato_nodes.launcher.launch import run_checked
    indices, identical = run_checked(values, bag, external=dict(external or {}))
    return Outcome(indices, bag, identical)


def in_pool(function: Callable, items: Iterable, workers: int, cluster: str = "") -> list:
    """function(item) for every item, in `workers` processes (or on a Dask cluster's
    workers), in the items' order."""
    with Backend(workers, cluster) as backend:
        results = dict(backend.stream(function, ((number, (item,))
                                                  for number, item in enumerate(items))))
    return [results[number] for number in range(len(results))]


def numeric(indices: Mapping[str, Any]) -> dict[str, int | float]:
    """The indices that are numbers (those a table compares)."""
    return {key: value for key, value in indices.items() if isinstance(value, (int, float))}


def write_outputs(out: Path, name: str, *, markdown: str | None = None,
                  report: Any = None) -> None:
    """`name`.md (the Markdown, ending in a newline) and `name`.json (strict JSON) in
    `out`, created if it does not exist yet; each only when given."""
    out.mkdir(exist_ok=True)
    if markdown is not None:
        (out / f"{name}.md").write_text(markdown + "\n")
    if report is not None:
        (out / f"{name}.json").write_text(jsontext.dumps(report, indent=2))
