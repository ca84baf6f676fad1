"""One scorer for recorded and in-process runs: series in, indices out."""

from __future__ import annotations

import numpy as np

from .indices import tracking_indices


def score_series(series: dict[str, np.ndarray]) -> dict[str, float]:
    """Indices of a run. Series of unequal length (an interrupted run) are cut to
    the steps every one of them holds."""
    names = ["t", "target", "speed"] + (["command"] if "command" in series else [])
    length = min(len(series[name]) for name in names)
    return tracking_indices(*(series[name][:length] for name in names))


def format_indices(indices: dict) -> str:
    return "\n".join([
        f"steps            {indices['steps']}",
        f"ITAE             {indices['itae']:.6g}  (m/s) s^2",
        f"IAE              {indices['iae']:.6g}  m",
        f"ISE              {indices['ise']:.6g}  m^2/s",
        f"max |e|          {indices['max_abs_error_kmh']:.4f} km/h"
        f"  ({indices['max_abs_error']:.5f} m/s)",
        f"J (seed 004)     {indices.get('j_seed004', float('nan')):.6g}",
    ])
