#!/usr/bin/env python3
"""Seed 002: optimise a driving strategy along a line (when to apply traction, cruise,
coast and brake), and compare it with the flat-out run and the DP energy-optimal limit.

    python scripts/optimize_strategy.py --line lines/lanxin-67km.yaml --train crh5 \\
        --algorithm kh --supplement 0.05 --out bags/strategy-kh

Algorithms: kh and pso search seed 002's switching points (per segment between neutral
sections: cruise speed and coasting point) on G (core/targets/strategy.py: indices, weights),
with --evaluations and --seed; dp is the energy-optimal limit (dynamic programming over
position and speed, the running time enforced by a bisected price of time); mareco is
a cruise-and-coast strategy (one cruise speed, bisected to meet the time, coasting over
the last 15 % of every segment); flatout the minimum-time run. The planned time is the
flat-out run's time x (1 + --supplement). --ignore-neutral plans as if there were no
neutral sections (the paper's comparison); the result is still evaluated on the line.
--share plans at that share of the train's traction and brake envelopes (the switching
strategies brake at 80 % of the envelope, or at the share if lower).

Writes in --out: strategy.csv (the strategy file: a header of `# key: value` lines,
then position m, speed m/s, mode 1 traction / 0 cruise or coast / -1 brake, force
N/kN at each stage start; the header holds --share if below 1 and, for kh, pso, mareco
and flatout, the switching points, which profile.strategy.replan drives again for a
weighed train), indices.json, speed_distance.png (speed against distance
with the caps, the grade profile and the neutral sections shaded), and for kh and pso
convergence.png.
"""

from __future__ import annotations

import argparse
import hashlib
from pathlib import Path

import _cli
import numpy as np

from ato_nodes.results import jsontext
from ato_nodes.core.targets import strategy
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.train.lines import load_line_file
from ato_nodes.core.base.paths import resolve_file
from ato_nodes.core.config.scenario import complete, train_preset
from ato_nodes.core.base.units import MS_TO_KMH



def parse_args() -> argparse.Namespace:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("--line", required=True, help="line file (relative: msg_config/)")
    parser.add_argument("--train", required=True, help="train preset (msg_config/trains)")
    parser.add_argument("--algorithm", required=True, choices=strategy.ALGORITHMS)
    parser.add_argument("--supplement", type=float, default=0.05,
                        help="running-time supplement over the flat-out run (0.05 = 5 %%)")
    parser.add_argument("--time", type=float, help="planned running time, s (default: the "
                        "flat-out run's time x (1 + --supplement))")
    parser.add_argument("--evaluations", type=int, default=1500)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--ds", type=float, default=100.0, help="stage length, m")
    parser.add_argument("--ignore-neutral", action="store_true")
    parser.add_argument("--share", type=float, default=1.0, help="share of the train's "
                        "traction and brake envelopes the plan uses (default 1: all; below 1 "
                        "the rest is a reserve for a heavier or more resisted train)")
    parser.add_argument("--out", type=Path, required=True)
    return parser.parse_args()


def main() -> None:
    args = parse_args()
    if not 0.0 <= args.supplement <= 1.0:
        _cli.fail("--supplement must lie in [0, 1]")
    if args.evaluations < 2 or not 10.0 <= args.ds <= 1000.0:
        _cli.fail("--evaluations must be at least 2 and --ds within 10-1000 m")
    if not 0.1 <= args.share <= 1.0:
        _cli.fail("--share must lie in [0.1, 1]")
    try:
        line_path = resolve_file(args.line, [Path.cwd()])
        line = load_line_file(line_path)
        train_preset(args.train)
        values = complete({"plant.train": args.train}, [])
    except ScenarioError as exc:
        _cli.fail(str(exc))
    if line.stop_position <= 0.0:
        _cli.fail(f"{line_path}: the line has no stop beyond the departure point")
    _cli.seconds(args.time, "--time")
    _cli.new_directory(args.out)
    problem, planning = strategy.problems(line, values, args.ds, args.ignore_neutral,
                                          args.share)
    try:
        outcome = strategy.evaluate(args.algorithm, problem, planning, args.time,
                                    supplement=args.supplement, evaluations=args.evaluations,
                                    seed=args.seed)
    except ValueError as exc:  # shorter than flat-out; or the DP's grid, ~1 % slower
        _cli.fail(f"{exc} on {line_path}")
    write_outputs(args, line, line_path, problem, outcome)


def write_outputs(args, line, line_path, problem, outcome) -> None:
    """The strategy file (with its header), indices.json, the plots and the summary line."""
    result, history, values = outcome.result, outcome.history, outcome.values
    planned = values["planned"]
    values["traction_in_neutral_sections"] = result.traction_in(line.neutral_sections)
    args.out.mkdir()
    header = {"line": args.line,
              "line_sha256": hashlib.sha256(Path(line_path).read_bytes()).hexdigest(),
              "train": args.train, "planned_time_s": f"{planned:.3f}",
              "algorithm": args.algorithm, "supplement": args.supplement}
    if args.share != 1.0:
        header["share"] = repr(args.share)
    if result.switching is not None:  # what profile.strategy.replan drives again
        header["switching"] = ",".join(repr(float(value)) for value in result.switching)
    strategy.write_strategy(args.out / "strategy.csv", header, result)
    summary = {"header": header, "indices": values, "flat_out": outcome.reference}
    if history is not None:
        summary["convergence"] = {"evaluations": history.trace("evaluations").tolist(),
                                  "best_G": history.trace("best_f").tolist()}
        plot_convergence(args.out / "convergence.png", history, args.algorithm)
    (args.out / "indices.json").write_text(jsontext.dumps(summary, indent=2, default=float))
    plot_strategy(args.out / "speed_distance.png", line, problem.track, result,
                  args.algorithm)
    print(f"{args.algorithm}: energy {values['energy_kwh']:.1f} kWh "
          f"({values['saved_percent']:.1f} % below flat-out's "
          f"{values['flat_out_energy_kwh']:.1f}), time {result.time:.1f} s (planned "
          f"{planned:.1f}, error {values['time_error']:+.1f}), comfort "
          f"{values['comfort']:.4f} m/s^3, stop error {values['stopping_error']:.2f} m, "
          f"G {values['G']:.4f}, {values['seconds']:.1f} s")
    print(f"outputs: {args.out}/strategy.csv, indices.json, speed_distance.png")


def plot_strategy(path: Path, line, track, result, name: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    figure, (speed, grade) = plt.subplots(2, 1, figsize=(12, 6.5), sharex=True,
                                          gridspec_kw={"height_ratios": [3, 1]})
    km = result.positions / 1000.0
    speed.plot(km, result.speeds * MS_TO_KMH, lw=1.2, label=f"{name} strategy")
    speed.step(track.positions / 1000.0, track.cap * MS_TO_KMH, where="post", color="r", lw=0.8,
               label="limit - 7 km/h")
    for axis in (speed, grade):
        for section in line.neutral_sections:
            axis.axvspan(section.start / 1000, section.end / 1000, color="orange", alpha=0.3)
    colours = {1: "tab:green", 0: "tab:gray", -1: "tab:red"}
    for mode, colour in colours.items():
        mask = result.modes == mode
        speed.scatter(km[:-1][mask], np.full(mask.sum(), 5.0 + 5 * mode), s=2, color=colour)
    speed.set(ylabel="speed (km/h)")
    speed.set_title(f"{name} strategy, {line.name}\nmodes at the bottom: green traction, "
                    "grey cruise or coast, red brake; orange: neutral sections", fontsize=9)
    speed.legend(loc="upper right")
    speed.grid(alpha=0.3)
    for section in line.gradients:
        grade.plot([section.start / 1000, section.end / 1000], [section.value] * 2, "k")
    grade.set(xlabel="distance (km)", ylabel="grade (per mille)")
    grade.grid(alpha=0.3)
    figure.tight_layout()
    figure.savefig(path, dpi=110)


def plot_convergence(path: Path, history, name: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    figure, axis = plt.subplots(figsize=(8, 4))
    axis.plot(history.trace("evaluations"), history.trace("best_f"), label=name)
    axis.set(xlabel="evaluations", ylabel="best G", title="convergence")
    axis.grid(alpha=0.3)
    axis.legend()
    figure.tight_layout()
    figure.savefig(path, dpi=110)


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
