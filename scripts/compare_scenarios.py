#!/usr/bin/env python3
"""Several scenarios through the real stack, side by side, each checked bit for bit
against the same run in-process.

    python scripts/compare_scenarios.py seed004-metro-tuned seed004-metro-ato \\
        --out bags/compare-metro

A scenario may carry overrides after colons (seed000:controller.preview=1), whose values
may hold colons (seed004-metro-line:profile.journey.dwell_extension=2:30). Prints and
writes (comparison.md, comparison.json) one row per run, labelled by the scenario's
name and its overrides with their values short (a file's by its name; the JSON keeps
each run's whole text under "variant"): max |e| (outside seed 003's
stepped approach where it has one), p95 |e|, ITAE, stopping error, max jerk over 1 s,
traction/brake switches, overspeed, net energy and whether the stack and the
in-process run agree. With --cluster the runs go on a Dask cluster's workers, several
at once, each in a ROS domain of its own on its worker's host; the workers write the
bags into --out, so they must see it (this host, or a shared file system). With
--external ROLE -- COMMAND a node of your own stands in for the controller or the profile
in every run (docs/external-nodes.md); no in-process run repeats its law ("n/a").

    python scripts/compare_scenarios.py seed000 seed000:plant.mass_factor=1.2 \
        --out bags/compare-smc --external controller -- python examples/smc-node/smc_node.py
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import _cli

from ato_nodes.reports.analysis import markdown_table
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.launcher.launch import external_nodes
from ato_nodes.studies.backend import ClusterLost, check_cluster
from ato_nodes.studies.runner import (Outcome, Variant, labels, numeric, prepare_variants,
                                     run_study, write_outputs)


# a ':' that starts the next NAME=VALUE; any other stays in its value (dwell_extension=2:30)
OVERRIDE_START = re.compile(r":(?=[A-Za-z_][\w.]*=)")


def variant(text: str) -> Variant:
    """SCENARIO[:NAME=VALUE...] as a variant."""
    scenario, _, overrides = text.partition(":")
    return Variant(scenario, OVERRIDE_START.split(overrides) if overrides else [])


def progress(label: str, outcome: Outcome) -> None:
    print(f"{label}: max |e| {outcome.indices['max_abs_error_kmh']:.3f} km/h, stack = "
          f"in-process: {agreement(outcome.identical)} ({outcome.bag})", flush=True)


def agreement(identical: bool | None) -> str:
    return {True: "yes", False: "NO", None: "n/a (external node)"}[identical]


def main() -> None:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("scenarios", nargs="+", metavar="SCENARIO[:NAME=VALUE...]")
    parser.add_argument("--out", type=Path, required=True, help="directory to create")
    parser.add_argument("--cluster", default="", metavar="local:N|tcp://HOST:PORT",
                        help="run on a Dask cluster (as tune.py --cluster)")
    parser.add_argument("--external", metavar="ROLE", help="a node of your own stands in "
                        "for ROLE (controller or profile) in every run: the command after --")
    from ato_nodes.launcher.launch import split_command  # its command after --
    ours, command = split_command(sys.argv[1:])
    args = parser.parse_args(ours)
    texts = list(dict.fromkeys(args.scenarios))
    named = dict(zip(labels([variant(text) for text in texts]), texts, strict=True))
    try:
        external = external_nodes(args.external, command)
        if args.cluster:
            check_cluster(args.cluster)
        runs = prepare_variants({label: variant(text) for label, text in named.items()})
    except ScenarioError as exc:
        _cli.fail(str(exc))
    _cli.new_directory(args.out)
    args.out.mkdir()
    bags = {label: args.out / f"run{number}" for number, label in enumerate(runs)}
    try:
        outcomes = run_study(runs, bags=bags, cluster=args.cluster, progress=progress,
                             external=external)
    except ScenarioError as exc:  # the cluster refused (no scheduler answers): nothing ran
        args.out.rmdir()
        _cli.fail(str(exc))
    except ClusterLost as exc:
        _cli.fail(f"{exc} mid-study; the finished runs' bags are in {args.out}", 1)
    except RuntimeError as exc:
        _cli.fail(str(exc), 1)
    results = {label: {**numeric(outcome.indices), "bit_identical": outcome.identical,
                       "variant": named[label]} for label, outcome in outcomes.items()}
    markdown = markdown_table(results, extra={"stack = in-process": {
        label: agreement(result["bit_identical"]) for label, result in results.items()}})
    write_outputs(args.out, "comparison", markdown=markdown, report=results)
    print(markdown)


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
