#!/usr/bin/env python3
"""Speed of the stack on this machine (prints figures; asserts nothing).

    python benchmarks/benchmark.py [--duration 2400] [--round-trips 10000]

Measures, in one run: the two-process rclpy ping-pong round-trip rate (plain
rclpy, std_msgs/Float64, the stack's QoS), the stack's lockstep steps per
second with every node in the loop and the recorder recording, their ratio,
the real-time factor and wall time of the full seed-000 run through the
stack, and the in-process simulation of the same run.
"""

from __future__ import annotations

import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import _cli

from ato_nodes.core.run.loop import simulate
from ato_nodes.core.config.scenario import apply_overrides, load_scenario
from ato_nodes.core.config.schema import steps
from ato_nodes.core.run.scoring import score_series
from ato_nodes.launch import DomainLock, Stack, node_environment


def ping_pong(round_trips: int) -> float:
    """Round trips per second between two fresh rclpy processes."""
    lock = DomainLock()
    env = node_environment(lock.domain_id)
    script = [sys.executable, str(Path(__file__).with_name("pingpong.py"))]
    echo = subprocess.Popen([*script, "echo"], env=env, stdout=subprocess.DEVNULL)
    try:
        result = subprocess.run([*script, "ping", str(round_trips)], env=env, capture_output=True,
                                text=True, timeout=600, check=True)
    finally:
        echo.terminate()
        echo.wait()
        lock.release()
    return float(result.stdout.strip())


def main() -> None:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("--scenario", default="seed000")
    parser.add_argument("--duration", type=float, default=2400.0, help="simulated seconds")
    parser.add_argument("--round-trips", type=int, default=10000)
    parser.add_argument("--repeats", type=int, default=3, help="ping-pong repeats (median)")
    args = parser.parse_args()
    values = apply_overrides(load_scenario(args.scenario), [f"run.duration={args.duration}"])
    print(f"machine: {os.cpu_count()} cores, {platform.processor() or platform.machine()}, "
          f"Python {platform.python_version()}")

    started = time.perf_counter()
    series = simulate(values)
    in_process_wall = time.perf_counter() - started
    n = steps(values)
    print(f"in-process: {n} steps in {in_process_wall:.3f} s = {n / in_process_wall:,.0f} steps/s "
          f"(ITAE {score_series(series)['itae']:.6g})")

    pings = [ping_pong(args.round_trips) for _ in range(args.repeats)]
    with tempfile.TemporaryDirectory() as tmp:
        stack = Stack(values, Path(tmp) / "bench", quiet=True)
        outcome = stack.run()
    if not outcome.ok:
        _cli.fail(f"stack run failed: {outcome.message}", 1)
    pings += [ping_pong(args.round_trips) for _ in range(args.repeats)]
    ping_rate = statistics.median(pings)
    report = outcome.report
    rate = report["steps_per_second"]
    print(f"ping-pong: median {ping_rate:,.0f} round trips/s "
          f"(runs before and after the stack: {', '.join(f'{p:,.0f}' for p in pings)})")
    print(f"stack: {report['steps']} steps in {report['loop_wall_time']:.2f} s = "
          f"{rate:,.0f} steps/s "
          f"with all nodes in the loop and the recorder on")
    print(f"stack / ping-pong: {100 * rate / ping_rate:.0f} %  (target >= 40 %)")
    print(f"full run through the stack: real-time factor {report['real_time_factor']:.1f}, "
          f"{outcome.wall_time:.1f} s wall including start-up "
          f"({report['startup_wall_time']:.2f} s to all nodes matched) and shutdown "
          f"(target < 60 s for 2400 s)")
    print(f"in-process full run: {in_process_wall:.3f} s (target < 1 s)")


if __name__ == "__main__":
    main()
