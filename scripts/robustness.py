#!/usr/bin/env python3
"""Robustness of a controller: one scenario over a seeded spread of real trains.

    python scripts/robustness.py seed004-metro-tuned --samples 50 --out bags/robust-metro

Each sample draws, uniformly in the given ranges, the real train's mass (its load,
as a share of the nominal plant.mass), running resistance and actuator lag (shares of
the nominal ones), a speed-sensor noise seed and a load-weighing seed (with
odometry.enabled, a seed of its sensors' errors: the wheel's diameter, the radar's and
accelerometer's, the balises' and beacons'; with plant.adhesion set, the adhesion within
its condition, --adhesion); the controller
and the profile keep the nominal train (plant.mass_factor, plant.resistance_factor,
plant.lag_factor are the plant node's alone), at the weighed mass when the scenario
weighs its load (train.load_weighing). Runs in-process in --workers processes or on a
Dask cluster (--cluster); each sample's row goes to samples.csv as it finishes (a
Ctrl-C or a kill keeps every finished one: --resume runs only the rest); at the end it
prints and writes (robustness.json, robustness.png) the median and worst of max abs(e), p95
abs(e), abs(stopping error), max jerk over 1 s and ITAE, and how many samples keep
within 1 km/h, stop within 0.1 m and arrive within 5 s of the planned time. On a
journey (profile.kind journey) also the worst stop and arrival over its stations
(core/scoring/journey.py) and how many samples stop within 0.1 m and arrive within
5 s of the timetable at every station (a station missed or not reached: neither).
With --external ROLE -- COMMAND every sample runs through the stack with a node of your
own standing in for the controller or the profile (docs/external-nodes.md), --workers
at once, each in a ROS domain of its own:

    python scripts/robustness.py seed000 --samples 20 --out bags/robust-smc \
        --external controller -- python examples/smc-node/smc_node.py
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import _cli

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.studies.backend import Backend, ClusterLost, Progress, check_cluster
from ato_nodes.studies.robustness import (FACTORS, INDICES, RAIL, RAIL_RANGE, RANGES,
                                          run_sample, run_sample_in_stack, study_columns,
                                          summarise)
from ato_nodes.studies.runner import Variant, check_counts, prepare_variants
from ato_nodes.studies.samples import SampleFailed, SampleStudy, write_json_with_rows


def span(text: str, name: str) -> tuple[float, float]:
    try:
        low, high = (float(v) for v in text.split(":"))
    except ValueError:
        _cli.fail(f"--{name} expects LOW:HIGH, got {text!r}")
    if not (math.isfinite(low) and math.isfinite(high) and 0 < low <= high):
        _cli.fail(f"--{name} needs 0 < LOW <= HIGH, got {text!r}")
    return low, high


def parse_args() -> argparse.Namespace:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("scenario")
    parser.add_argument("--samples", type=int, default=50)
    default = {option: "{:g}:{:g}".format(*RANGES[name]) for name, option in FACTORS.items()}
    parser.add_argument("--mass", default=default["mass"], help="mass range, share of the "
                        "nominal (default %(default)s: empty to crush load)")
    parser.add_argument("--resistance", default=default["resistance"],
                        help="resistance range (default %(default)s)")
    parser.add_argument("--lag", default=default["lag"], help="actuator lag range (default "
                        "%(default)s)")
    parser.add_argument("--adhesion", default="{:g}:{:g}".format(*RAIL_RANGE),
                        help="the rail's adhesion, a share of its condition's curve, on a "
                        "run with plant.adhesion set (default %(default)s)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--cluster", default="", metavar="local:N|tcp://HOST:PORT",
                        help="run the samples on a Dask cluster (as tune.py --cluster): "
                        "local:N starts N worker processes here, tcp://HOST:PORT uses a "
                        "running scheduler; the same samples give the same rows")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--resume", action="store_true", help="continue the study in --out: "
                        "run only the samples its samples.csv lacks (the same settings only)")
    parser.add_argument("--external", metavar="ROLE", help="a node of your own stands in "
                        "for ROLE (controller or profile), the command after --: every "
                        "sample runs through the stack on this host")
    from ato_nodes.launcher.launch import external_nodes, split_command
    ours, command = split_command(sys.argv[1:])  # the external node's command after --
    args = parser.parse_args(ours)
    try:
        args.nodes = external_nodes(args.external, command)
    except ScenarioError as exc:
        _cli.fail(str(exc))
    if args.nodes and args.cluster:
        _cli.fail("--external runs the samples through the stack on this host, not with "
                  "--cluster")
    return args


def checked(args: argparse.Namespace) -> tuple[dict, dict]:
    """(the scenario's values with --set, the ranges), or one line and exit 2: every
    check that can refuse the study, before anything is written or started."""
    try:
        check_counts(samples=args.samples, workers=args.workers, seed=args.seed)
        if args.cluster:
            check_cluster(args.cluster)
    except ScenarioError as exc:
        _cli.fail(str(exc))
    ranges = {name: span(getattr(args, option), option) for name, option in FACTORS.items()}
    try:  # the base, and both ends of each range inside the schema's range
        prepared = prepare_variants({"": Variant(args.scenario), **{
            f"--{FACTORS[name]} {getattr(args, FACTORS[name])}, {end}":
            Variant(args.scenario, {name: bound}) for name, bounds in ranges.items()
            for end, bound in zip(("LOW", "HIGH"), bounds, strict=True)}}, args.set)
    except ScenarioError as exc:
        _cli.fail(str(exc))
    base = prepared[""]
    if base["plant.adhesion"] != "unlimited":  # the rail's draw, its ends checked too
        ranges[RAIL] = span(args.adhesion, "adhesion")
        try:
            prepare_variants({f"--adhesion {args.adhesion}, {end}": Variant(
                args.scenario, {RAIL: bound}) for end, bound in zip(
                    ("LOW", "HIGH"), ranges[RAIL], strict=True)}, args.set)
        except ScenarioError as exc:
            _cli.fail(str(exc))
    if not args.resume or not args.out.exists():
        _cli.new_directory(args.out)
    elif not (args.out / SampleStudy.SETTINGS).exists() and any(args.out.iterdir()):
        _cli.fail(f"{args.out} holds no study to resume; use a new --out")
    return base, ranges


def main() -> None:
    args = parse_args()
    base, ranges = checked(args)
    settings = {"scenario": args.scenario, "set": args.set, "ranges": ranges,
                "seed": args.seed, "samples": args.samples,
                **({"external": args.nodes} if args.nodes else {})}
    study = None
    try:
        study = SampleStudy(args.out, settings, base, study_columns(base), args.samples,
                            args.resume)
        run_missing(study, base, ranges, args)
    except ScenarioError as exc:  # refused before anything was written
        _cli.fail(str(exc))
    except KeyboardInterrupt:
        print(f"interrupted{kept(study)}", file=sys.stderr)
        sys.exit(130)
    except (ClusterLost, SampleFailed) as exc:
        _cli.fail(f"{exc}{' mid-study' if isinstance(exc, ClusterLost) else ''}{kept(study)}", 1)
    finally:
        if study is not None:
            study.close()
    report(study, settings, args)


def kept(study: SampleStudy | None) -> str:
    """What a stopped study says of its samples: where the finished ones are, if it had
    begun (else nothing was written)."""
    if study is None or not study.started:
        return ""
    return f"; every finished sample is in {study.file.path}; continue with --resume"


def run_missing(study: SampleStudy, base: dict, ranges: dict, args: argparse.Namespace) -> None:
    """The samples the study lacks, each row appended as it finishes (the cluster is
    opened, and refused, before the study's directory is written)."""
    with Backend(args.workers, args.cluster, threads=bool(args.nodes)) as backend:
        study.begin()
        progress = Progress(args.samples, len(study.file.done), "samples")
        tasks = ((number, (base, ranges, args.seed, number, *([args.nodes] if args.nodes
                                                               else [])))
                 for number in study.missing())
        try:
            for _, row in backend.stream(run_sample_in_stack if args.nodes else run_sample,
                                         tasks):
                study.file.append(row)
                progress.advance()
        finally:
            progress.end()


def report(study: SampleStudy, settings: dict, args: argparse.Namespace) -> None:
    """robustness.json and robustness.png from the samples' file, and the summary."""
    values, present = study.file.table()
    columns = list(study.file.columns)
    summary, within = summarise(values, present, columns)
    for key, heading in INDICES:
        if key in summary:
            print(f"{heading:24s} median {summary[key]['median']:.4g}  worst "
                  f"{summary[key]['worst']:.4g}")
    print("; ".join(f"{text}: {count} of {len(values)}" for text, count in within.items()))
    report = {**{key: settings[key] for key in ("scenario", "set", "ranges", "seed")},
              "summary": summary, "within": within}
    write_json_with_rows(args.out / "robustness.json", report, "samples",
                         study.file.rows(values, present))
    plot({name: values[:, columns.index(name)] for name in (*FACTORS, "max_abs_error_kmh")},
         args.out / "robustness.png", args.scenario)
    print(f"{args.samples} samples; outputs: {args.out}/robustness.json, robustness.png, "
          "samples.csv")


def plot(columns: dict, path: Path, scenario: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    figure, axes = plt.subplots(1, 3, figsize=(13, 3.8), sharey=True)
    for axis, name in zip(axes, FACTORS, strict=True):
        axis.plot(columns[name], columns["max_abs_error_kmh"], "o", ms=3)
        axis.set(xlabel=name.split(".")[1].replace("_", " "))
        axis.grid(alpha=0.3)
    axes[0].set_ylabel("max abs(e), km/h")
    figure.suptitle(f"{scenario}: max tracking error over "
                    f"{len(columns['max_abs_error_kmh'])} real trains")
    figure.tight_layout()
    figure.savefig(path, dpi=110)


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
