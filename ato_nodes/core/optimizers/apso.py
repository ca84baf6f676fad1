"""Adaptive PSO of seed 003 (online tuning of the maglev NLADRC).

The PSO update of pso.py with adaptive coefficients and a chaotic-opposition
start; the patent's formulas are images, so the forms below are the standard
ones that match its text.

* Start: chaotic population and its opposition, keep the fitter half
  (sampling.py; 2 n evaluations). Velocities uniform in [-vmax, vmax] (the
  patent's vs = rand (vmax - vmin) + vmin with vmin = -vmax).
* Inertia: w = 1 in the first iteration (the patent's initial value), then
      w = 1 / (1 + 1.5 exp(-2.6 E(t)))
  which rises with the entropy and maps E in [0, 1] exactly onto the stated
  range w in [0.4, 0.9] (0.4 at E = 0, 0.8998 at E = 1); it is the sigmoid of
  Zhan et al.'s adaptive PSO (2009), whose exploration/exploitation wording
  the patent follows.
* Entropy E(t): the swarm's current fitness values are sorted into k bins
  (the patent's partition of the fitness set into disjoint subsets of s_i
  elements), p_i = s_i / n and E = -sum p_i ln p_i / ln k, in [0, 1]; k = 10.
  The bins are fixed at the start: equal-frequency bins of the initial swarm's
  values (bin edges at their k-quantiles; lower values fall in the first bin,
  higher ones in the last). So E = 1 for the initial swarm and falls as the
  swarm gathers in the lowest bins: it measures the spread relative to where
  the search began, and quantile edges are not squeezed by one huge (e.g.
  diverged-simulation) value. Bins recomputed from each iteration's own
  [min, max] would measure only the shape of the distribution: measured on a
  10-D sphere, E then stays near 0.8 while the swarm converges, holding
  w ~ 0.87 for the whole run and preventing convergence. Non-finite values
  count as the worst finite value.
* Learning factors move linearly from their initial to their final values,
  rate-limited so that |c(g+1) - c(g)| <= delta:
      c(g) = c_start + (c_end - c_start) min(g / G, delta g / |c_end - c_start|)
  c1 = c2 = 2 initially (patent). The final values are not given; the text
  says to increase c1 and decrease c2 (particles search around their own
  bests, against premature convergence): c1 -> 2.5, c2 -> 1.5, delta = 0.05.
* Population 50 (patent); its 50 iterations become what the budget allows.
  Velocity clamping and bounds as the PSO.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import Run, finite_or_worst
from .pso import VELOCITY_LIMIT, Swarm, SwarmOptimizer
from .sampling import chaotic_opposition_start


@dataclass
class AdaptiveSwarm(Swarm):
    entropy_edges: np.ndarray | None = None  # set by AdaptivePSO._start


def entropy_bin_edges(values: np.ndarray, bins: int) -> np.ndarray:
    """Interior edges of `bins` equal-frequency bins of `values`."""
    return np.quantile(finite_or_worst(values), np.arange(1, bins) / bins)


def fitness_entropy(values: np.ndarray, edges: np.ndarray) -> float:
    """Normalised Shannon entropy of the values' counts in the bins of `edges`."""
    bins = len(edges) + 1
    counts = np.bincount(np.searchsorted(edges, finite_or_worst(values), side="right"),
                         minlength=bins)
    p = counts[counts > 0] / len(values)
    return float(-(p * np.log(p)).sum() / np.log(bins))


def rate_limited_ramp(start: float, end: float, g: int, total: int, delta: float) -> float:
    """Linear move from start (g = 0) to end (g = total), at most delta per step."""
    distance = end - start
    if distance == 0:
        return start
    return start + distance * min(g / total, delta * g / abs(distance), 1.0)


class AdaptivePSO(SwarmOptimizer):
    name = "apso"

    def __init__(self, population_size: int = 50, w_first: float = 1.0,
                 c1_start: float = 2.0, c1_end: float = 2.5,
                 c2_start: float = 2.0, c2_end: float = 1.5, delta: float = 0.05,
                 entropy_bins: int = 10, velocity_limit: float = VELOCITY_LIMIT):
        super().__init__(population_size, velocity_limit)
        if entropy_bins < 2 or delta <= 0:
            raise ValueError("entropy_bins must be >= 2 and delta positive")
        self.w_first = w_first
        self.c1_ramp, self.c2_ramp = (c1_start, c1_end), (c2_start, c2_end)
        self.delta = delta
        self.entropy_bins = entropy_bins

    def initial_evaluations(self) -> int:
        return 2 * self.population_size

    def _start(self, run: Run) -> AdaptiveSwarm:
        x, f = chaotic_opposition_start(run, self.population_size)
        swarm = AdaptiveSwarm.at(x, f, self._initial_velocities(run))
        swarm.entropy_edges = entropy_bin_edges(f, self.entropy_bins)
        return swarm

    def _coefficients(self, run: Run, swarm: AdaptiveSwarm) -> tuple[float, float, float]:
        if run.iteration == 1:
            w = self.w_first
        else:
            w = 1.0 / (1.0 + 1.5 * np.exp(-2.6 * fitness_entropy(swarm.f, swarm.entropy_edges)))
        g, total = run.iteration - 1, run.planned_iterations
        c1 = rate_limited_ramp(*self.c1_ramp, g, total, self.delta)
        c2 = rate_limited_ramp(*self.c2_ramp, g, total, self.delta)
        return w, c1, c2
