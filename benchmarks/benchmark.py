#!/usr/bin/env python3
"""Speed of the stack on this machine (prints figures; asserts nothing).

    python benchmarks/benchmark.py [--duration 2400] [--round-trips 10000] [--profile]

Measures, in one run: the two-process rclpy ping-pong round-trip rate (plain
rclpy, std_msgs/Float64, the stack's QoS), the stack's lockstep steps per
second with every node in the loop and the recorder recording, their ratio,
the real-time factor and wall time of the full seed-000 run through the
stack, and the in-process simulation of the same run, warm: the median of
--in-process-repeats calls after one that loads the compiled loop and computes
the horizons (as every call of a tuning's worker after its first). --profile
adds a run of the stack with $ATO_NODE_TIMING (ato_nodes/nodes/timing.py) and
prints where each node's time goes, in microseconds per step.
"""

from __future__ import annotations

import json
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
from ato_nodes.core.config.schema import NODES
from ato_nodes.launcher.launch import DomainLock, Stack, node_environment
from ato_nodes.nodes.timing import VARIABLE as TIMING_VARIABLE


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


def in_process(values: dict, repeats: int) -> tuple[float, float, dict]:
    """(the first call's wall time, the median of `repeats` calls after it, a run's
    series): the first loads the compiled loop (or compiles it) and computes the
    horizons of a time-indexed plan, which every later run in the process reuses."""
    started = time.perf_counter()
    series = simulate(values)
    first = time.perf_counter() - started
    walls = []
    for _ in range(repeats):
        started = time.perf_counter()
        series = simulate(values)
        walls.append(time.perf_counter() - started)
    return first, statistics.median(walls), series


def profiled_run(values: dict) -> tuple[dict, dict[str, dict]]:
    """One more run of the stack with every node timing its parts: its report and each
    node's timing (see ato_nodes/nodes/timing.py)."""
    with tempfile.TemporaryDirectory() as tmp:
        os.environ[TIMING_VARIABLE] = tmp  # the nodes' environment is this one's
        try:
            outcome = Stack(values, Path(tmp) / "bag", quiet=True).run()
        finally:
            del os.environ[TIMING_VARIABLE]
        if not outcome.ok:
            _cli.fail(f"profiled stack run failed: {outcome.message}", 1)
        return outcome.report, {role: json.loads((Path(tmp) / f"{role}.json").read_text())
                                for role in NODES if (Path(tmp) / f"{role}.json").exists()}


def profile_table(timings: dict[str, dict]) -> list[str]:
    """Microseconds of CPU per step, each node's parts (wall time in brackets where
    it differs much: a thread that waits for the CPU or for data). The callbacks' own
    work is their time without the publishes and bag writes they make; the rest of the
    process's CPU is mostly DDS's threads (receiving, acknowledging)."""
    def per_step(role, names, column):
        timing = timings[role]
        return sum(timing["parts"][name][column] for name in names
                   if name in timing["parts"]) / timing["steps"] / 1e3

    roles = [role for role in NODES if role in timings]
    rows = {}
    for role in roles:
        parts = timings[role]["parts"]
        publishes = [name for name in parts if name.startswith("publish ")]
        handles = [name for name in parts if name.startswith("handle ")]
        main_thread = [*handles, "take", "wait", "housekeeping"]
        components = {
            "publish /clock": ["publish /clock"],
            "publish, other topics": [name for name in publishes if name != "publish /clock"],
            "take": ["take"],
            "wait set (waiting)": ["wait"],
            "housekeeping (executor)": ["housekeeping"],
            "bag writes": ["bag write"],
        }
        for label, names in components.items():
            cpu, wall = per_step(role, names, 1), per_step(role, names, 0)
            rows.setdefault(label, {})[role] = (cpu, wall)
        own = per_step(role, handles, 1) - per_step(role, publishes + ["bag write"], 1)
        rows.setdefault("callbacks' own work", {})[role] = (own, None)
        total = timings[role]["process_cpu_ns"] / timings[role]["steps"] / 1e3
        rows.setdefault("DDS threads, the rest", {})[role] = (
            total - per_step(role, main_thread, 1), None)
        rows.setdefault("process CPU", {})[role] = (total, None)

    def cell(value):
        if value is None:
            return "-"
        cpu, wall = value
        if not cpu and not wall:
            return "-"
        return f"{cpu:.0f}" + (f" ({wall:.0f})" if wall is not None and wall > 1.5 * cpu + 2
                               else "")
    lines = [f"{'us/step, CPU (wall)':26}" + "".join(f"{role:>14}" for role in roles)]
    for label, cells in rows.items():
        lines.append(f"{label:26}" + "".join(f"{cell(cells.get(role)):>14}" for role in roles))
    return lines


def main() -> None:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("--scenario", default="seed000")
    parser.add_argument("--duration", type=float, default=2400.0, help="simulated seconds")
    parser.add_argument("--round-trips", type=int, default=10000)
    parser.add_argument("--repeats", type=int, default=3, help="ping-pong repeats (median)")
    parser.add_argument("--in-process-repeats", type=int, default=5,
                        help="warm in-process runs (median)")
    parser.add_argument("--profile", action="store_true",
                        help="one more stack run, timing each node's parts")
    args = parser.parse_args()
    values = apply_overrides(load_scenario(args.scenario), [f"run.duration={args.duration}"])
    print(f"machine: {os.cpu_count()} cores, {platform.processor() or platform.machine()}, "
          f"Python {platform.python_version()}")

    first, in_process_wall, series = in_process(values, args.in_process_repeats)
    n = steps(values)
    print(f"in-process, warm (median of {args.in_process_repeats} after a warm-up call): {n} "
          f"steps in {in_process_wall:.3f} s = {n / in_process_wall:,.0f} steps/s "
          f"(ITAE {score_series(series)['itae']:.6g}); the first call in the process, which "
          f"loads the compiled loop and computes the horizons, {first:.2f} s")

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
    print(f"in-process full run, warm: {in_process_wall:.3f} s (target < 1 s)")
    if args.profile:
        report, timings = profiled_run(values)
        print(f"profile: one more stack run, every node timing its parts "
              f"(${TIMING_VARIABLE}), {report['steps_per_second']:,.0f} steps/s (the timing "
              "slows it)")
        for line in profile_table(timings):
            print("  " + line)


if __name__ == "__main__":
    main()
