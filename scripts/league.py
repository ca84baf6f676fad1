#!/usr/bin/env python3
"""A league of controller kinds: each on the same scenario and target, tuned with the
same budget, algorithm, seed and objective (or with its given or shipped gains), then
run over the same real trains, in one table.

    python scripts/league.py seed004-metro-ato --tune 200 --trains 50 --out bags/league-metro

--kinds names the controller kinds (default: every registered one). With --tune N each
kind is tuned in-process as tune.py tunes it (its default search space, --algorithm,
--seed, --fitness and --require; --require defaults to the scenario's report.require),
from its shipped gains (or those --set gives); without, it runs with the scenario's gains
(its own kind), the --set ones or the shipped ones. Every kind then runs over the same
--trains real trains (robustness.py's draw and ranges, from --seed) in --workers
processes or on a Dask cluster (--cluster). A --set of a controller kind's parameter
applies to that kind; any other to every kind. Prints and writes (league.md,
league.json, league.png) one row per kind: the trains within 1 km/h, stopping within
0.1 m and arriving within 5 s (on a journey: at every station), the median and worst of
max abs(e), stop error and jerk, and the median net energy; a kind that cannot run on
the scenario says why in its row. Interrupted (Ctrl-C), the same command continues the
league in --out: each kind's finished evaluations and trains are kept.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import _cli

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.optimizers import ALGORITHMS
from ato_nodes.core.scoring.catalogue import FITNESS, Requirement
from ato_nodes.studies.backend import Backend, ClusterLost, check_cluster
from ato_nodes.studies.league import (League, LeagueSettings, prepare_entries, registered_kinds,
                                      write_report)
from ato_nodes.studies.runner import check_counts
from ato_nodes.studies.samples import SampleFailed
from ato_nodes.studies.tuning import DEFAULT_ALGORITHM, Objective


def parse_args() -> argparse.Namespace:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("scenario")
    parser.add_argument("--kinds", nargs="+", metavar="KIND",
                        help="controller kinds (default: every registered kind)")
    parser.add_argument("--tune", type=int, default=0, metavar="N",
                        help="tune each kind with N evaluations (default: no tuning)")
    parser.add_argument("--trains", type=int, default=50, help="real trains (default 50)")
    parser.add_argument("--seed", type=int, default=1, help="the tunings' and trains' seed")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    parser.add_argument("--algorithm", default=DEFAULT_ALGORITHM, choices=sorted(ALGORITHMS))
    parser.add_argument("--fitness", default=Objective.fitness, choices=sorted(FITNESS))
    parser.add_argument("--require", action="append", metavar="INDEX<=VALUE",
                        help="a tuning's requirement (repeatable; default: the scenario's "
                        "report.require)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--cluster", default="", metavar="local:N|tcp://HOST:PORT",
                        help="run on a Dask cluster (as tune.py --cluster)")
    parser.add_argument("--out", type=Path, help="output directory (default: "
                        "bags/league-SCENARIO); the same command continues it")
    return parser.parse_args()


def checked(args: argparse.Namespace):
    """(settings, the scenario's values, the kinds' entries, the league's directory), or
    one line and exit 2: every check that can refuse the league, before anything is
    written or started."""
    try:
        check_counts(trains=args.trains, tune=args.tune, workers=args.workers, seed=args.seed)
        if args.cluster:
            check_cluster(args.cluster)
        if args.cluster.startswith("tcp://"):  # its scheduler answers, before OUT is made
            with Backend(1, args.cluster):
                pass
        settings = LeagueSettings(
            args.scenario, tuple(args.kinds or registered_kinds()), args.tune, args.trains,
            args.seed, tuple(args.set), args.algorithm, args.fitness, (), args.workers,
            args.cluster)
        base, entries = prepare_entries(settings)
        requirements = (args.require if args.require is not None else
                        [f"{r.name}<={r.limit!r}" for r in Requirement.parse_list(
                            base["report.require"], "report.require")])
        settings = dataclasses.replace(settings, requirements=tuple(requirements))
        settings.objective()
        out = args.out or Path("bags") / f"league-{Path(args.scenario).stem}"
        if not out.exists():
            _cli.new_directory(out)
        return settings, base, entries, League(out, settings, base)
    except ScenarioError as exc:
        _cli.fail(str(exc))


def main() -> None:
    args = parse_args()
    settings, base, entries, league = checked(args)
    show = sys.stderr.isatty()
    try:
        league.begin()
        for entry in entries:
            if settings.tune and entry.values is not None:
                print(f"{entry.kind}: tuning, {settings.tune} evaluations", file=sys.stderr,
                      flush=True)
                league.tune(entry, show)
        studies = league.run_trains(entries)
    except ScenarioError as exc:
        _cli.fail(str(exc))
    except KeyboardInterrupt:
        print(f"interrupted{kept(league)}", file=sys.stderr)
        sys.exit(130)
    except ClusterLost:
        _cli.fail(f"the Dask scheduler {settings.cluster} stopped answering{kept(league)}", 1)
    except SampleFailed as exc:
        _cli.fail(f"{exc}{kept(league)}", 1)
    print(write_report(league.out, settings, entries, studies))
    print(f"outputs: {league.out}/league.md, league.json, league.png")


def kept(league: League) -> str:
    """What a stopped league says of its runs (nothing, if it had not begun)."""
    if not league.started:
        return ""
    return (f"; every finished evaluation and train is in {league.out}; the same command "
            "continues")


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
