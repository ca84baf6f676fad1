#!/usr/bin/env python3
"""What each tracking addition gives: one scenario with every addition, without each in
turn, and built up one addition at a time from none.

    python scripts/ablation.py seed004-metro-ato --untuned ladrc.omega_o=10 \\
        --untuned ladrc.omega_c=2 --untuned ladrc.b0=0.00907 \\
        --reference seed004-metro-tuned --out bags/ablation-metro

The additions (docs/tracking.md), each undone by the overrides beside it:
  feedforward         ladrc.feedforward=none (planned acceleration, known resistance)
  preview             controller.preview=0 (and with it the prediction horizon)
  delay-aware         ladrc.prediction=none (observer input, Smith predictor)
  feasible curve      profile.envelope_share=0
  rounded curve       profile.jerk=0
  departure and berth profile.ato.start_speed=0.3, profile.departure_jerk=0,
                      controller.holding_target=0
  tuned gains         the --untuned values (the tuning objective's work; not a
                      parameter another addition undoes)
Runs in-process (the stack gives the same numbers bit for bit); --reference adds the
rows of other scenarios (today's controllers). Prints and writes ablation.md and
ablation.json in --out.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import _cli

from ato_nodes.reports.analysis import markdown_table
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import check_given_once
from ato_nodes.studies.runner import (Variant, check_counts, numeric, prepare_variants, run_study,
                                      write_outputs)

ADDITIONS = (
    ("feedforward", ["ladrc.feedforward=none"]),
    ("preview", ["controller.preview=0"]),
    ("delay-aware", ["ladrc.prediction=none"]),
    ("feasible curve", ["profile.envelope_share=0"]),
    ("rounded curve", ["profile.jerk=0"]),
    ("departure and berth", ["profile.ato.start_speed=0.3", "profile.departure_jerk=0",
                             "controller.holding_target=0"]),
)
TUNED = "tuned gains"


def parse_args() -> argparse.Namespace:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("scenario")
    parser.add_argument("--untuned", action="append", default=[], metavar="NAME=VALUE",
                        help="a gain before tuning (repeatable); without, no tuned-gains row")
    parser.add_argument("--reference", action="append", default=[], metavar="SCENARIO")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="override for every run, references included (repeatable)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, required=True)
    return parser.parse_args()


def variants(scenario: str, additions: list, references: list[str]) -> dict[str, Variant]:
    """The runs in the table's order: the references, none, the additions built up one
    at a time (the last of them is all), then each addition left out."""
    runs = {f"reference: {name}": Variant(name) for name in references}
    runs["none (linear ADRC alone)"] = Variant(
        scenario, [item for _, undo in additions for item in undo])
    for i, (name, _) in enumerate(additions[:-1]):
        still_off = [item for _, undo in additions[i + 1:] for item in undo]
        runs[f"+ {name}"] = Variant(scenario, still_off)
    runs["all additions"] = Variant(scenario)
    runs.update({f"without {name}": Variant(scenario, undo) for name, undo in additions})
    return runs


def main() -> None:
    args = parse_args()
    additions = list(ADDITIONS) + ([(TUNED, args.untuned)] if args.untuned else [])
    undone = [item.split("=", 1)[0] for _, undo in ADDITIONS for item in undo]
    for item in args.untuned:
        if item.split("=", 1)[0] in undone:
            _cli.fail(f"--untuned {item}: another addition undoes {item.split('=', 1)[0]}")
    try:
        check_counts(workers=args.workers)
        check_given_once(args.untuned)
        runs = prepare_variants(variants(args.scenario, additions, args.reference), args.set)
    except ScenarioError as exc:
        _cli.fail(str(exc))
    _cli.new_directory(args.out)
    results = {label: numeric(outcome.indices)
               for label, outcome in run_study(runs, workers=args.workers).items()}
    table = "\n".join([f"Ablation of {args.scenario} (in-process; cumulative from none, then "
                       f"each addition left out)", "", markdown_table(results)])
    write_outputs(args.out, "ablation", markdown=table, report={
        "scenario": args.scenario, "untuned": args.untuned, "reference": args.reference,
        "set": args.set, "runs": results})
    print(table)


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
