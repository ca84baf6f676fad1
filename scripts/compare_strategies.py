#!/usr/bin/env python3
"""Seed 002's comparison of driving strategies on one line and train.

    python scripts/compare_strategies.py --out bags/compare-seed002 [--seeds 1 2 3 4 5]

1. The paper's table 2 in kind, at a 5 % running-time supplement over the flat-out
   run: flat-out, PSO, KH, KH planned without neutral sections (then driven on the
   line), MARECO-like cruise-and-coast, DP optimum: energy, running time and error,
   comfort, stopping error, G; KH's energy gap to the DP optimum.
2. KH against PSO at equal evaluation budgets over --seeds (median, best, worst G and
   energy; convergence.png with every run).
3. Energy saved against the flat-out run at 3, 5 and 10 % supplements, DP and KH.
Writes comparison.md and comparison.json in --out; swarm runs in --workers processes.
"""

from __future__ import annotations

import statistics
from pathlib import Path

import _cli

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.base.paths import resolve_file
from ato_nodes.core.config.scenario import complete
from ato_nodes.core.targets import strategy
from ato_nodes.core.train.lines import load_line_file
from ato_nodes.studies.runner import check_counts, in_pool, write_outputs

SUPPLEMENTS = (0.03, 0.05, 0.10)


def evaluate(job: dict) -> dict:
    """One (algorithm, supplement, seed) run; the indices on the real line."""
    line = load_line_file(resolve_file(job["line"], [Path.cwd()]))
    problem, planning = strategy.problems(line, complete({"plant.train": job["train"]}, []),
                                          job["ds"], job.get("ignore_neutral", False))
    outcome = strategy.evaluate(job["algorithm"], problem, planning, None,
                                supplement=job["supplement"], evaluations=job["evaluations"],
                                seed=job["seed"])
    values = outcome.values
    if outcome.history is not None:
        values["convergence"] = [outcome.history.trace("evaluations").tolist(),
                                 outcome.history.trace("best_f").tolist()]
    return {**job, "indices": {k: float(v) if not isinstance(v, list) else v
                               for k, v in values.items()}}


def main() -> None:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("--line", default="lines/lanxin-67km.yaml")
    parser.add_argument("--train", default="crh5")
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5])
    parser.add_argument("--evaluations", type=int, default=1500)
    parser.add_argument("--ds", type=float, default=100.0)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    try:  # the counts, the line and the train, before the pool starts (its workers load them)
        check_counts(workers=args.workers, seeds=args.seeds)
        load_line_file(resolve_file(args.line, [Path.cwd()]))
        complete({"plant.train": args.train}, [])
    except ScenarioError as exc:
        _cli.fail(str(exc))
    _cli.new_directory(args.out)
    base = {"line": args.line, "train": args.train, "ds": args.ds,
            "evaluations": args.evaluations, "seed": args.seeds[0], "supplement": 0.05}
    jobs = [dict(base, algorithm=name) for name in ("flatout", "mareco")]
    jobs += [dict(base, algorithm="dp", supplement=s) for s in SUPPLEMENTS]
    jobs += [dict(base, algorithm="kh", supplement=s) for s in SUPPLEMENTS if s != 0.05]
    jobs += [dict(base, algorithm=a, seed=seed) for a in ("kh", "pso") for seed in args.seeds]
    jobs += [dict(base, algorithm="kh", ignore_neutral=True)]
    results = in_pool(evaluate, jobs, args.workers)
    markdown = "\n".join(report(results, args))
    write_outputs(args.out, "comparison", markdown=markdown, report=results)
    plot(results, args.out / "convergence.png")
    print(markdown)


def pick(results, algorithm, supplement=0.05, seed=None, ignore_neutral=False):
    return [r["indices"] for r in results if r["algorithm"] == algorithm
            and abs(r["supplement"] - supplement) < 1e-9
            and (seed is None or r["seed"] == seed)
            and r.get("ignore_neutral", False) == ignore_neutral]


def report(results, args) -> list[str]:
    first = args.seeds[0]
    rows = [("flat-out (before optimisation)", pick(results, "flatout")[0]),
            (f"PSO (seed {first})", pick(results, "pso", seed=first)[0]),
            (f"KH (seed {first})", pick(results, "kh", seed=first)[0]),
            ("KH planned without neutral sections", pick(results, "kh", ignore_neutral=True)[0]),
            ("MARECO-like cruise and coast", pick(results, "mareco")[0]),
            ("DP optimum", pick(results, "dp")[0])]
    dp = pick(results, "dp")[0]
    lines = [f"## Table 2 in kind: {args.line}, {args.train}, +5 % running time "
             f"(planned {dp['planned']:.1f} s)", "",
             "| strategy | energy kWh | time s | time error s | comfort m/s^3 | stop error m "
             "| G | energy above DP | wall s |", "|---|---|---|---|---|---|---|---|---|"]
    for name, v in rows:
        lines.append(f"| {name} | {v['energy_kwh']:.1f} | {v['time']:.1f} | "
                     f"{v['time_error']:+.1f} | {v['comfort']:.4f} | {v['stopping_error']:.2f} "
                     f"| {v['G']:.4f} | {100 * (v['energy_kwh'] / dp['energy_kwh'] - 1):+.1f} % "
                     f"| {v['seconds']:.1f} |")
    lines += ["", f"## KH against PSO, {args.evaluations} evaluations each, seeds "
              f"{' '.join(map(str, args.seeds))}", "",
              "| algorithm | median G | best G | worst G | median energy kWh | median time "
              "error s |", "|---|---|---|---|---|---|"]
    for algorithm in ("kh", "pso"):
        runs = pick(results, algorithm)
        runs = [r for r in runs if "convergence" in r]
        g = [r["G"] for r in runs]
        lines.append(f"| {algorithm} | {statistics.median(g):.4f} | {min(g):.4f} | "
                     f"{max(g):.4f} | {statistics.median(r['energy_kwh'] for r in runs):.1f} | "
                     f"{statistics.median(r['time_error'] for r in runs):+.1f} |")
    lines += ["", "## Energy saved against the flat-out run", "",
              "| supplement | DP | KH |", "|---|---|---|"]
    for s in SUPPLEMENTS:
        d, k = pick(results, "dp", s)[0], pick(results, "kh", s, seed=first)[0]
        lines.append(f"| +{100 * s:.0f} % | {d['saved_percent']:.1f} % | "
                     f"{k['saved_percent']:.1f} % |")
    return lines


def plot(results, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    figure, axis = plt.subplots(figsize=(8, 4.5))
    colours = {"kh": "tab:blue", "pso": "tab:orange"}
    for r in results:
        if r["algorithm"] in colours and "convergence" in r["indices"] \
                and abs(r["supplement"] - 0.05) < 1e-9 and not r.get("ignore_neutral"):
            evaluations, best = r["indices"]["convergence"]
            axis.plot(evaluations, best, color=colours[r["algorithm"]], lw=0.9,
                      label=f"{r['algorithm']} seed {r['seed']}")
    axis.set(xlabel="evaluations", ylabel="best G", title="KH against PSO (+5 % running time)")
    axis.grid(alpha=0.3)
    axis.legend(fontsize=7, ncol=2)
    figure.tight_layout()
    figure.savefig(path, dpi=110)


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
