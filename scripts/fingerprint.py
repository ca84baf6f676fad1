#!/usr/bin/env python3
"""The sha256 of every series of every shipped scenario (or those named), for a slice of
each run: the check that a change which should leave behaviour alone did.

    python scripts/fingerprint.py --duration 300 --out before.json
    python scripts/fingerprint.py --duration 300 --compare before.json
    python scripts/fingerprint.py --stack --duration 300 --compare before.json

In-process by default (simulate(), compiled where the compiled loop covers the run);
--stack runs each scenario through the nodes and hashes the series its bag holds
(all but t: the bag's times are its nanosecond stamps, in-process t is k * period).
--compare FILE prints each scenario's series that differ from FILE's and exits 1 if
any does.
"""

from __future__ import annotations

import hashlib
import json
import sys
import tempfile
from pathlib import Path

import _cli
import numpy as np

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.config.scenario import apply_overrides, load_scenario, scenario_names


def digests(series: dict[str, np.ndarray]) -> dict[str, str]:
    return {name: hashlib.sha256(np.ascontiguousarray(values, dtype=float).tobytes()).hexdigest()
            for name, values in sorted(series.items())}


def stack_series(values: dict, bag: Path) -> dict[str, np.ndarray]:
    from ato_nodes.bagio import read_run
    from ato_nodes.launch import Stack
    outcome = Stack(values, bag, quiet=True).run()
    if not outcome.ok:
        _cli.fail(f"{bag}: {outcome.message}", 1)
    return {name: values for name, values in read_run(bag).series.items() if name != "t"}


def main() -> None:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("scenarios", nargs="*", metavar="SCENARIO",
                        help="scenario names (default: every shipped one)")
    parser.add_argument("--duration", type=float, default=300.0,
                        help="simulated seconds of each run, at most its own duration (300)")
    parser.add_argument("--stack", action="store_true", help="through the nodes, from the bags")
    parser.add_argument("--out", type=Path, help="write the digests to this JSON file")
    parser.add_argument("--compare", type=Path, help="JSON file of digests to compare with")
    args = parser.parse_args()
    try:
        names = args.scenarios or scenario_names()
        runs = {name: load_scenario(name) for name in names}
        runs = {name: apply_overrides(values, {"run.duration": min(args.duration,
                                                                   values["run.duration"])})
                for name, values in runs.items()}
        reference = json.loads(args.compare.read_text()) if args.compare else None
    except (ScenarioError, OSError, ValueError) as exc:
        _cli.fail(str(exc))
    result, differing = {}, 0
    with tempfile.TemporaryDirectory() as scratch:
        for name, values in runs.items():
            series = (stack_series(values, Path(scratch) / name) if args.stack
                      else simulate(values))
            result[name] = digests(series)
            if reference is not None:
                wanted = reference.get(name, {})
                changed = [s for s, digest in result[name].items()
                           if s in wanted and wanted[s] != digest]
                differing += bool(changed)
                compared = len([s for s in result[name] if s in wanted])
                verdict = ("not in the saved set" if not compared else
                           "differ: " + ", ".join(changed) if changed else "identical")
                print(f"{name}: {compared} series compared, {verdict}", flush=True)
            else:
                print(f"{name}: {len(result[name])} series", flush=True)
    if args.out:
        args.out.write_text(json.dumps(result, indent=1, sort_keys=True) + "\n")
    if reference is not None:
        saved = sum(name in reference for name in result)
        print(f"{saved - differing} of the {saved} saved scenarios identical")
        sys.exit(1 if differing else 0)


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
