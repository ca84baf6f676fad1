#!/usr/bin/env python3
"""TTOBench's real tracks (CH_*, CN_*, SE_* in msg_config/ttobench/tracks/) in one table:
length, stops, lowest and highest gradient and speed limit, and the minimum running time
of every TTOBench train on each.

    python scripts/ttobench_table.py
    python scripts/ttobench_table.py --data DIR   # a folder with tracks/ and trains/

The minimum running time is the project's (core/targets/timetable.minimum_running_time:
the ATO curve at the train's full envelope, from standstill to standstill), summed over
the track's sections from stop to stop (stopping at every stop, dwells not counted), for
the train's plant values and comfort limits (core/train/ttobench.py), with no margin
under the speed limits (TTOBench's limits are the bounds) and, where the library gives
no comfort limit, the loosest planned rate the project accepts. A train whose maximum
speed is below the track's highest limit runs at most at its maximum speed: its time is
marked *. Bad input (a file, a field): one line, exit 2.
"""

from __future__ import annotations

from pathlib import Path

import _cli

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.base.paths import config_dir
from ato_nodes.core.base.units import MS_TO_KMH
from ato_nodes.core.config.schema import SPEC_BY_NAME, defaults
from ato_nodes.core.targets.timetable import minimum_running_time, section_line
from ato_nodes.core.train import ttobench
from ato_nodes.core.train.line import Line
from ato_nodes.core.train.lines import capped

REAL_TRACKS = ("CH_*.json", "CN_*.json", "SE_*.json")
PLANNED_RATES = ("profile.ato.acceleration", "profile.ato.deceleration")


def parse_args():
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("--data", type=Path, default=config_dir() / "ttobench",
                        help="the TTOBench folder (tracks/, trains/; default "
                        "msg_config/ttobench)")
    return parser.parse_args()


def run_values(train: ttobench.Train) -> dict:
    """A run's values for the train's minimum running time, each checked by its spec."""
    values = defaults()
    given = {**{name: SPEC_BY_NAME[name].high for name in PLANNED_RATES},
             **train.plant_values(values["plant.gravity"]), **train.planning_values(),
             "profile.ato.margin": 0.0}
    for name, value in given.items():
        values[name] = SPEC_BY_NAME[name].check(value, f"{train.path} as {name}")
    return values


def minimum_time(line: Line, train: ttobench.Train, values: dict) -> tuple[float, bool]:
    """(the train's minimum running time over the line's sections, s; whether its
    maximum speed is below the line's highest limit)."""
    slower = train.max_speed < max(section.value for section in line.speed_limits)
    line = capped(line, values["plant.max_running_speed"])  # as a run's line is
    stops = [station.position for station in line.stations]
    return sum(minimum_running_time(section_line(line, start, end), values)
               for start, end in zip(stops, stops[1:], strict=False)), slower


def load(data: Path) -> tuple[list[ttobench.Track], list[ttobench.Train]]:
    tracks = sorted({path for pattern in REAL_TRACKS
                     for path in (data / "tracks").glob(pattern)})
    trains = sorted((data / "trains").glob("*.json"))
    if not tracks or not trains:
        raise ScenarioError(f"{data}: no real tracks (tracks/CH_*, CN_*, SE_*) or no trains "
                            "(trains/*.json)")
    return [ttobench.load_track(path) for path in tracks], \
        [ttobench.load_train(path) for path in trains]


def main() -> None:
    args = parse_args()
    try:
        tracks, trains = load(args.data)
        values = {train.id: run_values(train) for train in trains}
    except ScenarioError as exc:
        _cli.fail(str(exc))
    print("| track | km | stops | gradient per mille | limit km/h | "
          + " | ".join(f"{train.id} s" for train in trains) + " |")
    print("|---|---|---|---|---|" + "---|" * len(trains))
    for track in tracks:
        line = track.line()
        grades = [section.value for section in line.gradients] or [0.0]
        limits = [section.value * MS_TO_KMH for section in line.speed_limits]
        times = [minimum_time(line, train, values[train.id]) for train in trains]
        print(f"| {track.id} | {track.length / 1000:.2f} | {len(line.stations)} | "
              f"{min(grades):g} to {max(grades):g} | {min(limits):.0f} to {max(limits):.0f} | "
              + " | ".join(f"{time:.1f}{' *' if slower else ''}" for time, slower in times)
              + " |")


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
