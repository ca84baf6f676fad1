"""Tune controller parameters with a swarm optimizer.

Each candidate relaunches the node graph with the candidate's parameters, is
recorded to MCAP and scored from its bag (or, with --in-process, runs the same
core code without ROS). Example, seed 000's BAS-PSO on the paper's gains:

    python scripts/tune.py --algorithm bas-pso --scenario seed000 --in-process \\
        --params adrc.mu1=100:20000,adrc.mu2=100:20000,adrc.beta1=50:3000 \\
        --evaluations 2700 --seed 1 --workers 2 --out bags/tune-baspso-1

With --external controller -- COMMAND the candidates are a node of your own
(docs/external-nodes.md) in place of the controller, its own ROS parameters tuned: those
it declares live with a FloatingPointRange, in that range (--params narrows it), given
to each candidate's COMMAND as --ros-args -p NAME:=VALUE:

    python scripts/tune.py --scenario seed000 --evaluations 40 --out bags/tune-smc \
        --external controller -- python examples/smc-node/smc_node.py

Outputs in --out: best.yaml (a scenario run_stack.py accepts as it is),
evaluations.jsonl (every evaluation, appended as it finishes), history.csv
(best and mean fitness per iteration), convergence.png, summary.json.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

from ato_nodes import cli
from ato_nodes.core.optimizers import ALGORITHMS
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import check_launcher_free, prepare
from ato_nodes.studies.runner import COUNT_BOUNDS, check_counts
from ato_nodes.core.optimizers.pareto import PARETO_ALGORITHMS
from ato_nodes.studies.pareto_tuning import Choice, ParetoTuner
from ato_nodes.studies.train_spread import TrainSpread
from ato_nodes.studies.tuning import (DEFAULT_ALGORITHM, FITNESS, PENALTY, Requirement,
                                      SearchSpace, Tuner, TuningLost, TuningSettings,
                                      best_command, check_external, fitness_name)


def parse_args() -> argparse.Namespace:
    from ato_nodes.launcher.launch import split_command  # its command after --
    ours, command = split_command(sys.argv[1:])
    parser = cli.argument_parser(__doc__)
    parser.add_argument("--algorithm", choices=sorted(ALGORITHMS) + list(PARETO_ALGORITHMS),
                        help=f"default {DEFAULT_ALGORITHM}; with --objectives nsga2")
    parser.add_argument("--scenario", default="seed000")
    parser.add_argument("--params", action="append", metavar="NAME=LOW:HIGH,...",
                        help="parameters to tune and their bounds (repeatable; default: the "
                        "default search space of the scenario's controller kind)")
    parser.add_argument("--evaluations", type=int, default=300,
                        help="budget of fitness evaluations")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--workers", type=int, default=1, help="candidates run in parallel")
    parser.add_argument("--fitness", choices=sorted(FITNESS), help="the index minimised "
                        "(default itae)")
    parser.add_argument("--require", action="append", default=[], metavar="INDEX<=VALUE",
                        help="operational requirement on a scored index (repeatable), e.g. "
                        "abs_stopping_error<=0.3: a candidate that breaks one is infeasible and "
                        "ranks after every feasible one, by how far it misses")
    add_objective_arguments(parser)
    parser.add_argument("--population", type=int, help="population size (default: the paper's)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="fixed parameter override for every candidate (repeatable)")
    parser.add_argument("--in-process", action="store_true",
                        help="score candidates with the core code in worker processes, no ROS")
    parser.add_argument("--timeout", type=float, default=300.0,
                        help="wall seconds before a candidate (stack or in-process) counts as hung")
    parser.add_argument("--out", type=Path, required=True, help="output directory")
    parser.add_argument("--resume", action="store_true",
                        help="continue the tuning in --out from its evaluation log")
    parser.add_argument("--cluster", default="", metavar="local:N|tcp://HOST:PORT",
                        help="evaluate on a Dask cluster: local:N starts N worker processes "
                        "here, tcp://HOST:PORT uses a running scheduler (docs/reference.md); "
                        "the same candidates give the same fitness as without")
    parser.add_argument("--no-prune", action="store_true",
                        help="run every in-process candidate to the end (pruning ends those "
                        "that cannot matter; the result is the same)")
    parser.add_argument("--keep-bags", action="store_true",
                        help="keep every stack candidate's bag in OUT/runs (default: deleted "
                        "once scored)")
    parser.add_argument("--quiet", action="store_true")
    parser.add_argument("--external", metavar="ROLE",
                        help="tune a node of your own standing in for ROLE (controller): "
                        "the command after --, its own ROS parameters")
    args = parser.parse_args(ours)
    args.command = command
    return args


def add_objective_arguments(parser: argparse.ArgumentParser) -> None:
    """Several objectives at once, and how a member of the front is chosen."""
    parser.add_argument("--objectives", metavar="NAME,NAME[,...]",
                        help="several objectives at once, each an index of the catalogue "
                        "(e.g. energy,itae,p95_abs_error_kmh), minimised or maximised as it "
                        "should be: the front with nsga2 or nsga3, --require as hard "
                        "constraints (docs/reference.md)")
    parser.add_argument("--trains", type=int, metavar="N",
                        help="judge each candidate over the same N real trains, drawn as "
                        "robustness.py draws them (in-process)")
    parser.add_argument("--train-seed", type=int, default=1,
                        help="with --trains: the trains' seed (robustness.py's --seed; the "
                        "optimizer's is --seed)")
    parser.add_argument("--statistic", default="mean", metavar="mean|worst|qP",
                        help="with --trains: each objective over the trains (qP: the P "
                        "quantile), one for all or one per objective, comma-separated; "
                        "every requirement must hold for every train")
    parser.add_argument("--weights", metavar="W,W[,...]",
                        help="with --objectives: best.yaml is the front's member whose "
                        "pseudo-weights are nearest these (default: the knee); with a swarm "
                        "--algorithm, the weights of the sum it minimises")
    parser.add_argument("--reference", metavar="V,V[,...]",
                        help="with --objectives: the hypervolume's reference point, in the "
                        "objectives' units (default: the front's nadir plus a tenth of its "
                        "span)")


def search_space(args: argparse.Namespace, values: dict) -> SearchSpace:
    """The tuned parameters: the scenario's (--params, else the kind's default space) or,
    with --external, the external node's own, as it declares them."""
    if args.external is None:
        if args.command:
            raise ScenarioError(f"a command after -- ({args.command[0]}) needs --external "
                                "controller")
        return (SearchSpace.parse(args.params, values) if args.params
                else SearchSpace.default(values))
    if args.external != "controller" or not args.command:
        raise ScenarioError("--external tunes a controller node of your own: --external "
                            "controller -- COMMAND")
    check_external(tuple(args.command), args.in_process, args.cluster)
    if shutil.which(args.command[0]) is None:
        raise ScenarioError(f"--external controller: command {args.command[0]} not found")
    from ato_nodes.cli.check_node import declared_parameters
    return SearchSpace.of_node(declared_parameters(args.command, values), args.params)


def tuning_settings(args: argparse.Namespace, space: SearchSpace
                    ) -> tuple[TuningSettings, Choice]:
    """The tuning the arguments ask for, and how a front's member is chosen."""
    options = {"population_size": args.population} if args.population else {}
    objectives = tuple(name.strip() for name in (args.objectives or "").split(",")
                       if name.strip())
    if objectives and args.fitness:
        raise ScenarioError("--fitness is one objective; with --objectives name them all")
    if not objectives and (args.weights or args.reference):
        raise ScenarioError("--weights and --reference choose from a front: give "
                            "--objectives")
    algorithm = args.algorithm or (PARETO_ALGORITHMS[0] if objectives
                                   else DEFAULT_ALGORITHM)
    choice = Choice.parse(args.weights, args.reference, len(objectives))
    summed = algorithm not in PARETO_ALGORITHMS  # a swarm's weighted sum of the objectives
    if objectives and summed and args.reference:
        raise ScenarioError(f"--reference is a front's: {algorithm} gives one best")
    settings = TuningSettings(algorithm, args.scenario, space, args.evaluations,
                              args.seed, args.workers, args.in_process,
                              args.fitness or "itae", args.timeout, options,
                              tuple(Requirement.parse(text) for text in args.require),
                              args.keep_bags, not args.no_prune, args.cluster,
                              tuple(args.command), objectives,
                              TrainSpread(args.trains, args.train_seed, args.statistic)
                              if args.trains is not None else None,
                              choice.weights or () if summed else ())
    return settings, choice


def main() -> None:
    cli.interrupted_quietly(tune)


def tune() -> None:
    args = parse_args()
    if args.evaluations < 1 or args.workers < 1 or (args.population or 2) < 2:
        cli.fail("--evaluations and --workers must be positive and --population at least 2")
    cli.seconds(args.timeout, "--timeout")
    try:  # before OUT is touched: a refused command changes nothing there
        check_counts(workers=args.workers, seed=args.seed,
                     population=args.population or COUNT_BOUNDS["population"][0])
    except ScenarioError as exc:
        cli.fail(str(exc))
    try:
        values = prepare(args.scenario, args.set)
        check_launcher_free(values)
        space = search_space(args, values)
        settings, choice = tuning_settings(args, space)
        objectives = settings.objectives
        if not args.params and not args.quiet:
            print(f"tuning the {'external node' if args.external else 'default'} search "
                  f"space: {space.describe()}")
        if values["line.file"] and not args.require:
            print("warning: tuning on a line without --require: a candidate that stops short "
                  "or overspeeds can win (e.g. --require 'abs_stopping_error<=0.5' --require "
                  "'overspeed_time<=0')", file=sys.stderr)
        if args.out.exists() and any(args.out.iterdir()) and not args.resume:
            raise ScenarioError(f"{args.out} is not empty; use --resume or another --out")
        tuner = (ParetoTuner(values, settings, args.out, choice, resume=args.resume,
                             progress=not args.quiet)
                 if objectives and settings.algorithm in PARETO_ALGORITHMS else
                 Tuner(values, settings, args.out, resume=args.resume, progress=not args.quiet))
        if tuner.finished:
            print(f"the tuning in {args.out} is finished; nothing to run")
        else:
            tuner.run()
    except (ScenarioError, ValueError) as exc:
        cli.fail(str(exc).splitlines()[0])
    except TuningLost as exc:
        cli.fail(str(exc), 1)
    except KeyboardInterrupt:  # Ctrl-C or SIGTERM (cli.interrupted_quietly)
        print(f"interrupted; every finished evaluation is in {args.out / 'evaluations.jsonl'}; "
              "continue with --resume" if args.out.is_dir() else "interrupted",  # else it
              file=sys.stderr)  # was still checking its input: nothing to continue
        sys.exit(130)
    report(json.loads((args.out / "summary.json").read_text()), args.out)


def report(summary: dict, out: Path) -> None:
    """What a finished tuning prints, from its summary.json (a resume of a finished
    tuning prints it again)."""
    if "front_size" in summary:
        report_front(summary, out)
        return
    if summary["best_fitness"] >= PENALTY:
        cli.fail(f"every one of the {summary['evaluations_used']} candidates failed "
                 f"({summary['failed_evaluations']}), so there is no best.yaml; see "
                 f"{out / 'evaluations.jsonl'}", 1)
    print(f"best {fitness_name(summary)} {summary['best_fitness']:.6g} after "
          f"{summary['evaluations_used']} evaluations, {summary['iterations']} iterations "
          f"({summary['stop_reason']})")
    for name, value in summary["best_params"].items():
        print(f"  {name} = {value:.6g}")
    indices = summary["best_indices"]
    if indices:
        print(f"  max |e| {indices['max_abs_error_kmh']:.4f} km/h, ITAE {indices['itae']:.6g}")
    print(f"failed evaluations: {summary['failed_evaluations'] or 'none'}; pruned: "
          f"{summary['pruned_evaluations']}")
    for name in summary["best_at_bounds"]:
        print(f"warning: the best {name} sits on its bound; a wider --params box may do "
              f"better", file=sys.stderr)
    print(f"outputs: {out}/best.yaml, evaluations.jsonl, history.csv, convergence.png")
    print("run the best: " + best_command(out, tuple(summary.get("external", ())),
                                          summary["best_params"]))


def report_front(summary: dict, out: Path) -> None:
    """What a finished multi-objective tuning prints."""
    if not summary["front_size"]:
        cli.fail(f"none of the {summary['evaluations_used']} candidates met every "
                 f"requirement, so there is no front and no best.yaml; see "
                 f"{out / 'evaluations.jsonl'}", 1)
    chosen = summary["chosen"]
    print(f"front of {summary['front_size']} after {summary['evaluations_used']} evaluations "
          f"({summary['feasible_evaluations']} feasible), {summary['generations']} "
          f"generations; hypervolume {summary['hypervolume']:.6g} against "
          f"({', '.join(f'{value:.6g}' for value in summary['reference_point'])})")
    for objective in summary["objectives"]:
        print(f"  {objective['sense']} {objective['index']}: "
              f"{objective['ideal']:.6g} .. {objective['nadir']:.6g} on the front, chosen "
              f"{chosen['objectives'][objective['index']]:.6g}")
    bound = summary.get("energy_bound", {})
    if "running_time" in bound:
        print(f"  no run of the nominal train in {bound['running_time']:g} s takes less than "
              f"{bound['traction_energy_kwh']:.6g} kWh of traction (the dynamic programme)")
    print(f"chosen: row {chosen['row']} ({chosen['by']})")
    for name, value in chosen["params"].items():
        print(f"  {name} = {value:.6g}")
    parquet = ", front.parquet" if (out / "front.parquet").exists() else ""
    print(f"outputs: {out}/best.yaml, front.csv{parquet}, front.json, hypervolume.csv, "
          "pareto.png, evaluations.jsonl")
    print("run the chosen: " + best_command(out, tuple(summary.get("external", ())),
                                            chosen["params"]))
