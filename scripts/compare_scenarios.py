#!/usr/bin/env python3
"""Several scenarios through the real stack, side by side, each checked bit for bit
against the same run in-process.

    python scripts/compare_scenarios.py seed004-metro-tuned seed004-metro-ato \\
        --out bags/compare-metro

A scenario may carry overrides after colons (seed000:controller.preview=1). Prints and
writes (comparison.md, comparison.json) one row per run: max |e| (outside seed 003's
stepped approach where it has one), p95 |e|, ITAE, stopping error, max jerk over 1 s,
traction/brake switches, overspeed, net energy and whether the stack and the
in-process run agree.
"""

from __future__ import annotations

from pathlib import Path

import _cli

from ato_nodes import jsontext
from ato_nodes.analysis import markdown_table
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import apply_overrides, load_scenario
from ato_nodes.launch import run_checked

def main() -> None:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("scenarios", nargs="+", metavar="SCENARIO[:NAME=VALUE...]")
    parser.add_argument("--out", type=Path, required=True, help="directory to create")
    args = parser.parse_args()
    try:
        runs = {}
        for text in args.scenarios:
            name, *overrides = text.split(":")
            runs[text] = apply_overrides(load_scenario(name), overrides)
    except ScenarioError as exc:
        _cli.fail(str(exc))
    _cli.new_directory(args.out)
    args.out.mkdir()
    results = {}
    for number, (text, values) in enumerate(runs.items()):
        try:
            indices, identical = run_checked(values, args.out / f"run{number}")
        except RuntimeError as exc:
            _cli.fail(str(exc), 1)
        results[text] = {**{k: v for k, v in indices.items() if isinstance(v, (int, float))},
                         "bit_identical": identical}
        print(f"{text}: max |e| {indices['max_abs_error_kmh']:.3f} km/h, stack = in-process: "
              f"{identical} ({args.out / f'run{number}'})", flush=True)
    markdown = markdown_table(results, extra={"stack = in-process": {
        name: "yes" if r["bit_identical"] else "NO" for name, r in results.items()}})
    (args.out / "comparison.md").write_text(markdown + "\n")
    (args.out / "comparison.json").write_text(jsontext.dumps(results, indent=2))
    print(markdown)


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
