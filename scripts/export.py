#!/usr/bin/env python3
"""Export a recorded run as a table, one row per step (t, target, speed, ... in SI units).

    python scripts/export.py BAG --csv run.csv
    python scripts/export.py BAG --parquet run.parquet     # needs pyarrow

Columns: t (simulated s from the run's start), every series the bag gives (target,
speed, measured_speed, acceleration, disturbance, force, resistance, line_resistance,
speed_limit, position, command, the controller's outputs) and preview_0 .. preview_N
(the target horizon). The same table in Python: ato_nodes.bags.bagio.read_frame(BAG).
"""

from __future__ import annotations

import csv
from pathlib import Path

import _cli

from ato_nodes.bags.bagio import BagError, parse_mapping, read_frame, read_run, run_columns


def main() -> None:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("bag", help="rosbag2 directory or a lone .mcap file")
    target = parser.add_mutually_exclusive_group(required=True)
    target.add_argument("--csv", type=Path, metavar="FILE")
    target.add_argument("--parquet", type=Path, metavar="FILE")
    parser.add_argument("--map", action="append", default=[], metavar="ROLE=/TOPIC",
                        help="read a role from another topic (see analyze.py --help)")
    args = parser.parse_args()
    out = args.csv or args.parquet
    if out.exists():
        _cli.fail(f"{out} exists already; choose another")
    try:
        mapping = parse_mapping(args.map)
        if args.csv:
            columns = run_columns(read_run(args.bag, mapping))
            with out.open("w", newline="") as handle:
                writer = csv.writer(handle)
                writer.writerow(columns)
                writer.writerows(zip(*(map(repr, values.tolist())
                                       for values in columns.values()), strict=True))
            rows = len(columns["t"])
        else:
            frame = read_frame(args.bag, mapping)
            try:
                frame.to_parquet(out)
            except ImportError:
                _cli.fail("--parquet needs pyarrow: pip install pyarrow")
            rows = len(frame)
    except BagError as exc:
        _cli.fail(str(exc))
    except OSError as exc:
        _cli.fail(f"cannot write {out}: {exc.strerror or exc}")
    print(f"{out}: {rows} rows")


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
