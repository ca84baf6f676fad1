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
import math
import time
from pathlib import Path

import _cli
import numpy as np

from ato_nodes import jsontext
from ato_nodes.bagio import BagError, read_run
from ato_nodes.core.control import identification as ident
from ato_nodes.core.control import lssvm
from ato_nodes.core.control.gpc import MultiModel
from ato_nodes.core.train.plant import TrainParameters
from ato_nodes.core.config.schema import defaults
from ato_nodes.core.base.units import MS_TO_KMH

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


def load(path: Path):
    """(measured speeds, effective commands, parameters) of a recorded run."""
    try:
        run = read_run(path)
    except BagError as exc:
        _cli.fail(str(exc))
    speeds = run.series["measured_speed"]
    train = TrainParameters.from_values({**defaults(), **run.parameters})
    return (speeds, ident.effective_commands(train, speeds, run.series["command"]),
            run.parameters)


def ranges(errors: np.ndarray) -> dict:
    errors = errors * MS_TO_KMH
    return {"min_kmh": float(errors.min()), "max_kmh": float(errors.max()),
            "rms_kmh": float(np.sqrt(np.mean(errors ** 2)))}


def within_ctcs3(errors: np.ndarray, speeds: np.ndarray) -> float:
    """Share of samples inside the CTCS-3 speed-measurement tolerance: 2 km/h below
    30 km/h, 2 % of the speed above."""
    tolerance = np.where(speeds * MS_TO_KMH < 30.0, 2.0, 0.02 * speeds * MS_TO_KMH)
    return float(np.mean(np.abs(errors * MS_TO_KMH) <= tolerance))


def free_run_error(model_step, layout, speeds, commands) -> dict:
    predicted = ident.free_run(model_step, layout, speeds, commands)
    return ranges(predicted - speeds)


AHEAD = 20  # steps: the shipped GPC's prediction horizon


def prediction_errors(model_step, layout, speeds, commands) -> dict:
    """The free run over the whole run and the AHEAD-step-ahead predictions."""
    return {"free_run": free_run_error(model_step, layout, speeds, commands),
            f"ahead_{AHEAD}": ranges(ident.ahead(model_step, layout, speeds, commands, AHEAD))}


def lssvm_step(model):
    return lambda x: x[0] + float(model.increment(x)[0])


def arx_step(layout, centres, width, coefficients):
    model = MultiModel(layout, centres, width, coefficients)  # as the GPC blends them

    def step(x):
        row = model.row(x[0])
        return float(row[0] + row[1:] @ x)
    return step


def main() -> None:
    args = parse_args()
    try:
        layout = lssvm.Layout(args.speed_lags, args.command_lags, args.delay)
    except ValueError as exc:
        _cli.fail(str(exc))
    if not 2 <= args.train < args.samples:
        _cli.fail("--train must be at least 2 and below --samples")
    if args.out.suffix != ".npz":
        _cli.fail("--out must name a .npz file")
    runs = [load(path) for path in args.bags]
    parameters = runs[0][2]
    period = parameters["run.period"]
    train_values = {name: value for name, value in parameters.items()
                    if name.startswith("plant.") and not name.startswith("plant.disturbance")}
    for path, (_, _, other) in zip(args.bags, runs, strict=True):
        if other["run.period"] != period or other.get("plant.train") != parameters.get(
                "plant.train"):
            _cli.fail(f"{path}: another train or period than {args.bags[0]}")

    # 1,500 samples spread over the runs in proportion to their length
    lengths = np.array([len(speeds) for speeds, _, _ in runs])
    counts = np.diff(np.round(np.concatenate([[0], np.cumsum(lengths)])
                              * args.samples / lengths.sum()).astype(int))
    xs, ts, vs = [], [], []
    try:
        for (speeds, commands, _), count in zip(runs, counts, strict=True):
            x, t = layout.samples(speeds, commands, ident.sample_steps(len(speeds), layout,
                                                                       count))
            xs.append(x), ts.append(t), vs.append(x[:, 0])
    except ValueError as exc:
        _cli.fail(str(exc))
    x, t, v = np.concatenate(xs), np.concatenate(ts), np.concatenate(vs)
    train_rows, test_rows = ident.split(len(t), args.train)

    started = time.monotonic()
    search = ident.search_hyperparameters(layout, x[train_rows], t[train_rows], seed=args.seed,
                                          population=args.particles,
                                          iterations=args.iterations)
    search_seconds = time.monotonic() - started
    mus, deltas, grid = ident.grid_around(layout, x[train_rows], t[train_rows], search.mu,
                                          search.delta)
    model = lssvm.fit(layout, x[train_rows], t[train_rows], search.mu, search.delta)
    width = (v.max() - v.min()) / max(args.centres - 1, 1)
    centres = np.linspace(v.min(), v.max(), args.centres)
    arx = ident.fit_multimodel(layout, x[train_rows], t[train_rows], centres, width)
    errors = {part: model.increment(x[rows]) - t[rows]
              for part, rows in (("train", train_rows), ("test", test_rows))}
    report = {
        "bags": [str(p) for p in args.bags], "period_s": period,
        "train": parameters.get("plant.train"),
        "layout": {"speed_lags": layout.speed_lags, "command_lags": layout.command_lags,
                   "delay": layout.delay},
        "samples": {"total": int(len(t)), "train": int(len(train_rows)),
                    "test": int(len(test_rows))},
        "search": {"mu": search.mu, "delta": search.delta, "validation_rmse_kmh":
                   search.rmse * MS_TO_KMH, "evaluations": search.result.evaluations,
                   "seconds": search_seconds,
                   "convergence_kmh": (search.result.trace("best_f") * MS_TO_KMH).tolist(),
                   "grid_mu": mus.tolist(), "grid_delta": deltas.tolist(),
                   "grid_rmse_kmh": (grid * MS_TO_KMH).tolist(),
                   "grid_is_local_optimum": bool(grid.min() >= grid[2, 2] - 1e-12),
                   "at_bound": [name for name, value, (low, high) in (
                       ("mu", math.log10(search.mu), ident.LOG_MU),
                       ("delta", search.delta, ident.DELTA))
                       if not low + 1e-3 * (high - low) < value < high - 1e-3 * (high - low)]},
        "one_step": {part: {**ranges(e), "within_ctcs3": within_ctcs3(e, v[rows])}
                     for (part, e), rows in zip(errors.items(), (train_rows, test_rows),
                                                strict=True)},
        "paper": PAPER,
    }
    if args.validation:
        speeds, commands, _ = load(args.validation)
        report["validation"] = {
            "lssvm": prediction_errors(lssvm_step(model), layout, speeds, commands),
            "multimodel": prediction_errors(arx_step(layout, centres, width, arx), layout,
                                            speeds, commands)}
    if args.correction:
        report["correction"] = correction(args, layout, model, load(args.correction),
                                          parameters)
    lssvm.ModelFile(model, period, train_values, centres, float(width), arx).save(args.out)
    report["model"] = {"file": str(args.out), "sha256": lssvm.file_digest(args.out)}
    args.out.with_suffix(".json").write_text(jsontext.dumps(report, indent=2))
    figure(args.out.with_suffix(".png"), model, x, t, test_rows, search, report)
    print_report(report)


def correction(args, layout, offline, run, identified: dict) -> dict:
    """Stream --correction-samples samples of a changed train through the online
    correction; compare the one-step error on the other samples of that run and the
    free run before and after; time every update; check against a fresh solve."""
    speeds, commands, parameters = run
    steps = ident.sample_steps(len(speeds), layout, 2 * args.correction_samples)
    x, t = layout.samples(speeds, commands, steps)
    stream, held_out = np.arange(0, len(t), 2), np.arange(1, len(t), 2)
    model = offline.with_window(args.window)
    threshold = args.threshold / MS_TO_KMH
    costs = []
    for i in stream:
        error = float(model.increment(x[i])[0]) - t[i]
        if abs(error) > threshold:
            started = time.perf_counter()
            model.add(x[i], t[i])
            costs.append(time.perf_counter() - started)
    drift = {}
    for window in (len(stream), len(stream) // 5):  # every sample joins; then with forgetting
        forced = offline.with_window(window)
        for i in stream:
            forced.add(x[i], t[i])
        fresh = forced.refit()
        drift[f"window_{window}"] = {
            "updates": forced.added, "forgotten": forced.forgotten,
            "max_kmh": float(np.abs(fresh.increment(x) - forced.increment(x)).max()) * MS_TO_KMH}
    result = {
        "train_change": {name: [identified.get(name), value] for name, value in
                         parameters.items() if name.startswith("plant.") and name not in (
                             "plant.noise_seed",) and identified.get(name) != value},
        "threshold_kmh": args.threshold, "window": args.window,
        "samples_streamed": int(len(stream)), "added": model.added,
        "rejected_by_guard": model.rejected, "forgotten": model.forgotten,
        "one_step_before": ranges(offline.increment(x[held_out]) - t[held_out]),
        "one_step_after": ranges(model.increment(x[held_out]) - t[held_out]),
        "before": prediction_errors(lssvm_step(offline), layout, speeds, commands),
        "after": prediction_errors(lssvm_step(model), layout, speeds, commands),
        "drift_from_fresh_solve": drift,
    }
    if costs:
        costs = np.array(costs) * 1e3
        result["update_ms"] = {"median": float(np.median(costs)),
                               "p99": float(np.percentile(costs, 99))}
    return result


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
    free, ahead = errors["free_run"], errors[f"ahead_{AHEAD}"]
    return (f"free run {free['min_kmh']:+.2f} .. {free['max_kmh']:+.2f} km/h (RMS "
            f"{free['rms_kmh']:.2f}), {AHEAD} steps ahead {ahead['min_kmh']:+.2f} .. "
            f"{ahead['max_kmh']:+.2f} km/h (RMS {ahead['rms_kmh']:.3f})")


def figure(path: Path, model, x, t, test_rows, search, report) -> None:
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
