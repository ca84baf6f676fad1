#!/usr/bin/env python3
"""Record seed 001's identification data: the CRH380AL run through the stack.

    python scripts/identification_data.py --out bags/seed001-data

Three runs of the seed001-excitation scenario, each with its own seeded random
staircase target (core/control/identification.py: why this excitation) and sensor seed,
recorded to ordinary bags under OUT:
  identification/  3,000 s: the 1,500 samples (900 training, 600 test)
  validation/      3,000 s: a run the model never saw (free-run prediction)
  resistance/      1,500 s of a train whose running resistance is 30 % above the
                   nominal (plant.resistance_factor; the online-correction samples).
                   Not a heavier train: the command is a specific force (N/kN), so
                   mass alone changes nothing but the envelope
Then `scripts/identify.py OUT/identification --validation OUT/validation
--correction OUT/resistance --out MODEL.npz`.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import _cli

from ato_nodes.core.control.identification import excitation_table

TOP_SPEED = 320.0 / 3.6  # m/s, the excitation's highest level
RUNS = (  # name, staircase seed, duration s, extra overrides
    ("identification", 1, 3000.0, ()),
    ("validation", 2, 3000.0, ()),
    ("resistance", 3, 1500.0, ("plant.resistance_factor=1.3",)),
)


def main() -> None:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("--out", type=Path, required=True, help="directory to create")
    args = parser.parse_args()
    _cli.new_directory(args.out)
    args.out.mkdir()
    for name, seed, duration, extra in RUNS:
        table = args.out / f"{name}-target.csv"
        rows = excitation_table(seed, duration - 60.0, TOP_SPEED)
        table.write_text("time,speed\n" + "".join(f"{t:.3f},{v:.4f}\n" for t, v in rows))
        command = [sys.executable, str(Path(__file__).with_name("run_stack.py")),
                   "--scenario", "seed001-excitation", "--out", str(args.out / name),
                   "--quiet", "--duration", str(max(duration, rows[-1][0] + 10.0)),
                   "--set", f"profile.table.file={table.resolve()}",
                   "--set", f"plant.noise_seed={seed}",
                   *(arg for item in extra for arg in ("--set", item))]
        print(" ".join(command[1:]), file=sys.stderr)
        result = subprocess.run(command, stdout=subprocess.DEVNULL)
        if result.returncode:
            _cli.fail(f"the {name} run failed (exit {result.returncode}); bags so far in "
                      f"{args.out}", result.returncode)
    print(f"bags: {', '.join(str(args.out / name) for name, *_ in RUNS)}")


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
