#!/usr/bin/env python3
"""Identify seed 001's LSSVM train model from recorded runs.

    python scripts/identify.py bags/seed001-data/identification \\
        --validation bags/seed001-data/validation --correction bags/seed001-data/heavier \\
        --out msg_config/models/crh380al-lssvm.npz

From the identification bags, 1,500 samples evenly spread over the runs, split
(interleaved) into 900 training and 600 test samples, as the paper does. The
hyperparameters (mu, delta) come from the adaptive-inertia PSO (N 40, M 100,
c1 = c2 = 2, w in [0.4, 0.9]) minimising the RMSE on a validation part of the
training samples; a grid around the optimum checks it. Prints the one-step error
ranges (train, test) in km/h beside the paper's and the CTCS-3 tolerance, the
free-run error over the validation run, and, with --correction, what online
correction does on a changed train: error before and after, samples added, cost
per update and the drift from a fresh solve. Writes the model, MODEL.json (every
figure printed) and MODEL.png (predicted against measured, free run, search).
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass
from pathlib import Path

import _cli
import numpy as np

from ato_nodes.results import jsontext
from ato_nodes.bags.bagio import BagError, Run, read_run
from ato_nodes.core.base.units import MS_TO_KMH
from ato_nodes.core.config.schema import defaults
from ato_nodes.core.control import identification as ident
from ato_nodes.core.control import lssvm
from ato_nodes.core.train.plant import TrainParameters

PAPER = {"train": (-1.2627, 1.0568), "test": (-1.9182, 1.8369), "mu": 6599.8,
         "delta": 0.0597 ** 0.5}


def parse_args() -> argparse.Namespace:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("bags", nargs="+", type=Path, help="identification bags")
    parser.add_argument("--out", type=Path, required=True, help="model file to write (.npz)")
    parser.add_argument("--validation", type=Path, help="a bag for the free-run check")
    parser.add_argument("--correction", type=Path, help="a bag of a changed train: online "
                        "correction with its samples")
    layout = lssvm.Layout()
    parser.add_argument("--speed-lags", type=int, default=layout.speed_lags)
    parser.add_argument("--command-lags", type=int, default=layout.command_lags)
    parser.add_argument("--delay", type=int, default=layout.delay,
                        help="input delay, whole periods (the train's dead time)")
    parser.add_argument("--samples", type=int, default=1500)
    parser.add_argument("--train", type=int, default=900)
    parser.add_argument("--correction-samples", type=int, default=500)
    parser.add_argument("--threshold", type=float, default=2.0,
                        help="online-correction threshold, km/h (the paper's 2)")
    parser.add_argument("--window", type=int, default=500,
                        help="corrections the model keeps (the oldest leaves first)")
    parser.add_argument("--iterations", type=int, default=100, help="PSO iterations (M)")
    parser.add_argument("--particles", type=int, default=40, help="PSO particles (N)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--centres", type=int, default=7,
                        help="operating speeds of the linear multi-model")
    return parser.parse_args()


def checked_layout(args: argparse.Namespace) -> lssvm.Layout:
    """The regressor layout, after every option is checked (one line, exit 2)."""
    try:
        layout = lssvm.Layout(args.speed_lags, args.command_lags, args.delay)
    except ValueError as exc:
        _cli.fail(str(exc))
    if not 2 <= args.train < args.samples:
        _cli.fail("--train must be at least 2 and below --samples")
    if args.out.suffix != ".npz":
        _cli.fail("--out must name a .npz file")
    return layout


def load(path: Path) -> Run:
    try:
        return read_run(path)
    except BagError as exc:
        _cli.fail(str(exc))


def recording(run: Run) -> ident.Recording:
    """The run's measured speeds and effective commands."""
    speeds = run.series["measured_speed"]
    train = TrainParameters.from_values({**defaults(), **run.parameters})
    return ident.Recording(speeds, ident.effective_commands(train, speeds,
                                                            run.series["command"]))


def check_one_train(paths: list[Path], runs: list[Run]) -> None:
    first = runs[0].parameters
    for path, run in zip(paths, runs, strict=True):
        if run.parameters["run.period"] != first["run.period"] or run.parameters.get(
                "plant.train") != first.get("plant.train"):
            _cli.fail(f"{path}: another train or period than {paths[0]}")


@dataclass(frozen=True)
class Identified:
    """The models fitted on the training samples and how their search went."""
    model: lssvm.LSSVM
    search: ident.Search
    search_seconds: float
    grid: tuple[np.ndarray, np.ndarray, np.ndarray]  # grid_around(): mu, delta, RMSE
    centres: np.ndarray  # the multi-model's operating speeds, m/s
    width: float
    multimodel: np.ndarray  # its coefficients, one row per centre


def identify(args: argparse.Namespace, layout: lssvm.Layout, x: np.ndarray, t: np.ndarray,
             train_rows: np.ndarray) -> Identified:
    """Both models fitted on the training samples; the multi-model's centres spread
    over the speeds of all samples."""
    x_train, t_train = x[train_rows], t[train_rows]
    started = time.monotonic()
    search = ident.search_hyperparameters(layout, x_train, t_train, seed=args.seed,
                                          population=args.particles,
                                          iterations=args.iterations)
    search_seconds = time.monotonic() - started
    grid = ident.grid_around(layout, x_train, t_train, search.mu, search.delta)
    model = lssvm.fit(layout, x_train, t_train, search.mu, search.delta)
    speeds = x[:, 0]
    width = (speeds.max() - speeds.min()) / max(args.centres - 1, 1)
    centres = np.linspace(speeds.min(), speeds.max(), args.centres)
    return Identified(model, search, search_seconds, grid, centres, width,
                      ident.fit_multimodel(layout, x_train, t_train, centres, width))


def search_report(identified: Identified) -> dict:
    search, (mus, deltas, grid) = identified.search, identified.grid
    return {"mu": search.mu, "delta": search.delta,
            "validation_rmse_kmh": search.rmse * MS_TO_KMH,
            "evaluations": search.result.evaluations, "seconds": identified.search_seconds,
            "convergence_kmh": (search.result.trace("best_f") * MS_TO_KMH).tolist(),
            "grid_mu": mus.tolist(), "grid_delta": deltas.tolist(),
            "grid_rmse_kmh": (grid * MS_TO_KMH).tolist(),
            "grid_is_local_optimum": bool(grid.min() >= grid[2, 2] - 1e-12),
            "at_bound": ident.at_bound(search)}


def main() -> None:
    args = parse_args()
    layout = checked_layout(args)
    runs = [load(path) for path in args.bags]
    check_one_train(args.bags, runs)
    validation_run = load(args.validation) if args.validation else None
    correction_run = load(args.correction) if args.correction else None
    parameters = runs[0].parameters
    try:  # the samples, spread over the runs in proportion to their length
        x, t = ident.spread_samples(layout, [recording(run) for run in runs], args.samples)
    except ValueError as exc:
        _cli.fail(str(exc))
    train_rows, test_rows = ident.split(len(t), args.train)
    identified = identify(args, layout, x, t, train_rows)
    model = identified.model
    report = {
        "bags": [str(p) for p in args.bags], "period_s": parameters["run.period"],
        "train": parameters.get("plant.train"),
        "layout": {"speed_lags": layout.speed_lags, "command_lags": layout.command_lags,
                   "delay": layout.delay},
        "samples": {"total": int(len(t)), "train": int(len(train_rows)),
                    "test": int(len(test_rows))},
        "search": search_report(identified),
        "one_step": {part: ident.one_step_errors(model, x[rows], t[rows])
                     for part, rows in (("train", train_rows), ("test", test_rows))},
        "paper": PAPER,
    }
    if validation_run is not None:
        report["validation"] = validation(layout, identified, recording(validation_run))
    if correction_run is not None:
        report["correction"] = correction(args, layout, model, correction_run, parameters)
    save(args.out, identified, parameters, report)
    figure(args.out.with_suffix(".png"), model, x, t, test_rows, identified.search)
    print_report(report)


def validation(layout: lssvm.Layout, identified: Identified, run: ident.Recording) -> dict:
    """Both models' free run and AHEAD-step predictions over a run they never saw."""
    multimodel = ident.multimodel_step(layout, identified.centres, identified.width,
                                       identified.multimodel)
    return {"lssvm": ident.prediction_errors(ident.lssvm_step(identified.model), layout, run),
            "multimodel": ident.prediction_errors(multimodel, layout, run)}


def correction(args: argparse.Namespace, layout: lssvm.Layout, offline: lssvm.LSSVM,
               run: Run, identified: dict) -> dict:
    """The online-correction study on a changed train's run, and what changed."""
    return {"train_change": {name: [identified.get(name), value]
                             for name, value in run.parameters.items()
                             if name.startswith("plant.") and name != "plant.noise_seed"
                             and identified.get(name) != value},
            **ident.correction_study(offline, layout, recording(run),
                                     samples=args.correction_samples, window=args.window,
                                     threshold_kmh=args.threshold)}


def save(path: Path, identified: Identified, parameters: dict, report: dict) -> None:
    """The model file (with the identified train's plant values), then MODEL.json."""
    train_values = {name: value for name, value in parameters.items()
                    if name.startswith("plant.") and not name.startswith("plant.disturbance")}
    lssvm.ModelFile(identified.model, parameters["run.period"], train_values,
                    identified.centres, float(identified.width), identified.multimodel).save(path)
    report["model"] = {"file": str(path), "sha256": lssvm.file_digest(path)}
    path.with_suffix(".json").write_text(jsontext.dumps(report, indent=2))


def print_report(report: dict) -> None:
    s, one = report["search"], report["one_step"]
    print(f"layout {report['layout']}, {report['samples']['train']} training / "
          f"{report['samples']['test']} test samples at {report['period_s']:g} s")
    print(f"aw-pso: mu = {s['mu']:.4g}, delta = {s['delta']:.4g} (delta^2 = {s['delta']**2:.4g}; "
          f"paper mu = 6599.8, delta^2 = 0.0597), validation RMSE {s['validation_rmse_kmh']:.4f}"
          f" km/h, {s['evaluations']} fits in {s['seconds']:.0f} s; a 5 x 5 grid around it (inside "
          f"the box{''.join(f', {name} at its bound' for name in s['at_bound'])}): "
          f"{'a local optimum' if s['grid_is_local_optimum'] else 'NOT a local optimum'}")
    for part in ("train", "test"):
        e, paper = one[part], report["paper"][part]
        print(f"one-step {part}: {e['min_kmh']:+.3f} .. {e['max_kmh']:+.3f} km/h, RMS "
              f"{e['rms_kmh']:.3f} (paper {paper[0]:+.3f} .. {paper[1]:+.3f}); inside the CTCS-3 "
              f"tolerance: {100 * e['within_ctcs3']:.1f} %")
    for name, errors in report.get("validation", {}).items():
        print(f"validation run, {name}: {describe(errors)}")
    c = report.get("correction")
    if c:
        print(f"online correction ({c['train_change']}, threshold {c['threshold_kmh']} km/h, "
              f"window {c['window']}): {c['added']} of {c['samples_streamed']} samples added "
              f"({c['rejected_by_guard']} rejected by the guard, {c['forgotten']} forgotten)")
        for when in ("before", "after"):
            one = c[f"one_step_{when}"]
            print(f"  {when}: one-step RMS {one['rms_kmh']:.3f} km/h ({one['min_kmh']:+.3f} .. "
                  f"{one['max_kmh']:+.3f}); {describe(c[when])}")
        if "update_ms" in c:
            print(f"  update cost median {c['update_ms']['median']:.2f} ms, p99 "
                  f"{c['update_ms']['p99']:.2f} ms")
        for d in c["drift_from_fresh_solve"].values():
            print(f"  after {d['updates']} updates ({d['forgotten']} forgotten): predictions "
                  f"within {d['max_kmh']:.1e} km/h of a fresh solve")
    print(f"model: {report['model']['file']} (sha256 {report['model']['sha256'][:16]})")


def describe(errors: dict) -> str:
    free, ahead = errors["free_run"], errors[f"ahead_{ident.AHEAD}"]
    return (f"free run {free['min_kmh']:+.2f} .. {free['max_kmh']:+.2f} km/h (RMS "
            f"{free['rms_kmh']:.2f}), {ident.AHEAD} steps ahead {ahead['min_kmh']:+.2f} .. "
            f"{ahead['max_kmh']:+.2f} km/h (RMS {ahead['rms_kmh']:.3f})")


def figure(path: Path, model, x, t, test_rows, search) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    predicted = (x[test_rows, 0] + model.increment(x[test_rows])) * MS_TO_KMH
    measured = (x[test_rows, 0] + t[test_rows]) * MS_TO_KMH
    axes[0].plot(measured, predicted, ".", ms=2)
    axes[0].set(xlabel="measured y(k), km/h", ylabel="predicted y(k), km/h",
                title="one-step prediction, test samples")
    axes[1].plot(measured, predicted - measured, ".", ms=2)
    axes[1].axhline(2.0, color="r", lw=0.8)
    axes[1].axhline(-2.0, color="r", lw=0.8)
    axes[1].set(xlabel="measured speed, km/h", ylabel="error, km/h",
                title="one-step error (red: +-2 km/h)")
    axes[2].plot(search.result.trace("evaluations"), search.result.trace("best_f") * MS_TO_KMH)
    axes[2].set(xlabel="evaluations", ylabel="best validation RMSE, km/h",
                title=f"aw-pso: mu={search.mu:.3g}, delta={search.delta:.3g}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
