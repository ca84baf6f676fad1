#!/usr/bin/env python3
"""Seed 001's comparison through the real stack: GPC on the adaptive LSSVM model, on
the fixed LSSVM, on the mechanistic model and on the linear multi-model, beside the
project's tuned Han ADRC and PID, on the seed001-crh380al run.

    python scripts/compare_seed001.py --out bags/compare-seed001

Each variant runs through the stack (recorded, scored from its bag) and in-process;
the two must agree bit for bit. Two conditions: the nominal train, and a train whose
running resistance is 30 % above the nominal (plant.resistance_factor = 1.3: the
plant alone changes; every model was identified, or is parametrised, on the
nominal train). Prints and writes (comparison.md, comparison.json) max |e|
(km/h), ITAE, RMS of the command change per step (N/kN, smoothness), traction/brake
switches, max jerk over 1 s, traction energy and stopping error.
"""

from __future__ import annotations

from pathlib import Path

import _cli
import numpy as np

from ato_nodes.bags.bagio import read_run
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.studies.runner import Outcome, Variant, prepare_variants, run_study, write_outputs

VARIANTS = {
    "GPC, adaptive LSSVM": Variant("seed001-crh380al"),
    "GPC, LSSVM without correction": Variant("seed001-crh380al", ["gpc.correction=false"]),
    "GPC, mechanistic model": Variant("seed001-crh380al", ["gpc.prediction=mechanistic"]),
    "GPC, linear multi-model": Variant("seed001-crh380al", ["gpc.prediction=multimodel"]),
    "Han ADRC (tuned)": Variant("seed001-crh380al-adrc"),
    "PID (tuned)": Variant("seed001-crh380al-pid"),
}
CONDITIONS = {"nominal": [], "resistance +30 %": ["plant.resistance_factor=1.3"]}
COLUMNS = (  # key, heading, format
    ("max_abs_error_kmh", "max abs(e) km/h", "{:.3f}"),
    ("p95_abs_error_kmh", "p95 abs(e) km/h", "{:.3f}"),
    ("itae", "ITAE", "{:.0f}"),
    ("command_change_rms", "RMS du N/kN", "{:.3f}"),
    ("switch_count", "switches", "{:d}"),
    ("max_jerk", "max jerk m/s^3", "{:.3f}"),
    ("traction_energy_kwh", "traction kWh", "{:.1f}"),
    ("stopping_error", "stop error m", "{:+.2f}"),
    ("bit_identical", "stack = in-process", "{}"),
)


def table(results: dict) -> str:
    lines = ["| variant | " + " | ".join(h for _, h, _ in COLUMNS) + " |",
             "|---|" + "---|" * len(COLUMNS)]
    for name, indices in results.items():
        cells = [fmt.format(indices[key]) if key in indices else "" for key, _, fmt in COLUMNS]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def with_smoothness(outcome: Outcome) -> dict:
    """The bag's indices, the RMS of its command change per step and the agreement."""
    command = read_run(outcome.bag).series["command"]
    return {**outcome.indices, "command_change_rms": float(np.sqrt(np.mean(np.diff(command) ** 2))),
            "bit_identical": "yes" if outcome.identical else "NO"}


def progress(label: str, outcome: Outcome) -> None:
    print(f"{label}: max |e| {outcome.indices['max_abs_error_kmh']:.3f} km/h ({outcome.bag})",
          flush=True)


def main() -> None:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("--out", type=Path, required=True, help="directory to create")
    parser.add_argument("--duration", type=float, help="simulated seconds (default: the "
                        "scenario's whole run)")
    args = parser.parse_args()
    extra = [f"run.duration={args.duration}"] if args.duration else []
    runs, bags = {}, {}
    try:
        for number, (condition, change) in enumerate(CONDITIONS.items()):
            runs.update(prepare_variants({f"{condition}: {name}": variant for name, variant
                                          in VARIANTS.items()}, [*change, *extra]))
            bags.update({f"{condition}: {name}": args.out / f"condition{number}-variant{index}"
                         for index, name in enumerate(VARIANTS)})
    except ScenarioError as exc:
        _cli.fail(str(exc))
    _cli.new_directory(args.out)
    args.out.mkdir()
    try:
        outcomes = run_study(runs, bags=bags, progress=progress)
    except RuntimeError as exc:
        _cli.fail(str(exc), 1)
    report = {condition: {name: with_smoothness(outcomes[f"{condition}: {name}"])
                          for name in VARIANTS} for condition in CONDITIONS}
    markdown = "\n\n".join(f"## {condition}\n\n{table(results)}"
                           for condition, results in report.items())
    write_outputs(args.out, "comparison", markdown=markdown, report=report)
    print(markdown + "\n")  # a blank line after the last table, as between tables


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
