#!/usr/bin/env python3
"""Soak the recorder's promises: runs interrupted at random (seeded) moments.

    python scripts/soak.py [--sigint 100] [--double 20] [--sigkill 20] [--seed 1]
                           [--out bags/soak]

Each SIGINT run is `run_stack.py --duration 100` interrupted after a random delay
(start-up, stepping, the end of the run, the final scoring); each double run gets a
second SIGINT 0.05-1 s after the first, while a 600 s run steps; each SIGKILL run
has one random node killed while stepping. Every bag must open in rosbags and in
mcap's reader with the same messages, and hold exactly what its summary.json says
(per-topic counts, scored steps); an interrupted run exits 130, and no node
outlives its launcher. Prints one line per run and a tally; exit status 1 if any
run broke a promise. Not a test: it takes minutes.
"""

from __future__ import annotations

import json
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import _cli

from ato_nodes.bagio import BagError, message_counts, read_run
from ato_nodes.core.config.schema import NODES
from ato_nodes.launch import node_processes

ROOT = Path(__file__).resolve().parents[1]


def check(bag: Path) -> tuple[bool, str]:
    """(promise kept, what the bag holds)."""
    from mcap.reader import make_reader
    from rosbags.highlevel import AnyReader
    try:
        counts = message_counts(bag)
        with AnyReader([bag]) as reader:
            in_rosbags = sum(1 for _ in reader.messages())
        (mcap_file,) = bag.glob("*.mcap")
        with mcap_file.open("rb") as handle:
            in_mcap = sum(1 for _ in make_reader(handle).iter_messages())
        summary = json.loads((bag / "summary.json").read_text())
        scored = len(read_run(bag).series["t"]) if all(counts.values()) else 0
    except (BagError, OSError, ValueError, KeyError) as exc:
        return False, f"unreadable: {exc}"
    kept = (in_rosbags == in_mcap == sum(counts.values()) and summary.get("recorded") == counts
            and summary.get("scored_steps") == scored)
    spread = f"{min(counts.values())}-{max(counts.values())}" if counts else "0"
    return kept, (f"{len(counts)} topics, {spread} messages each, {scored} steps scored, "
                  f"summary {'agrees' if kept else 'DISAGREES'}")


def one_run(bag: Path, rng: random.Random, kind: str) -> tuple[bool, str]:
    """kind: 'sigint', 'double' (two SIGINTs) or 'sigkill' (of a random node)."""
    # a double SIGINT comes while stepping (a 600 s run steps from ~2 s to ~8 s here)
    duration, delay = ("600", rng.uniform(2.5, 6.0)) if kind == "double" else \
        ("100", rng.uniform(0.2, 4.5))
    process = subprocess.Popen([sys.executable, str(ROOT / "scripts" / "run_stack.py"),
                                "--duration", duration, "--out", str(bag)],
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                               cwd=ROOT)
    victim = rng.choice(NODES)
    spacing = rng.uniform(0.05, 1.0)
    deadline = time.monotonic() + delay
    while time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.01)
    what = {"sigint": "SIGINT", "double": "2 SIGINTs", "sigkill": f"SIGKILL {victim}"}[kind]
    what += f" at {delay:.2f} s" + (f" +{spacing:.2f} s" if kind == "double" else "")
    nodes = node_processes(process.pid)
    if process.poll() is None:
        if kind == "sigkill":
            if victim not in nodes:
                what += " (not running)"
            else:
                os.kill(nodes[victim], signal.SIGKILL)
        else:
            process.send_signal(signal.SIGINT)
            if kind == "double":
                time.sleep(spacing)
                if process.poll() is None:
                    process.send_signal(signal.SIGINT)
    else:
        what += " (run already over)"
    _, stderr = process.communicate(timeout=120)
    outlived = [role for role, pid in nodes.items() if Path(f"/proc/{pid}").exists()
                and Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"]
    if "Traceback" in stderr:
        return False, f"{what}: exit {process.returncode}, TRACEBACK"
    if outlived:
        return False, f"{what}: exit {process.returncode}, {', '.join(outlived)} outlived it"
    summary = bag / "summary.json"
    completed = process.returncode == 0 and summary.exists() and json.loads(
        summary.read_text()).get("status") == "completed"
    if kind != "sigkill" and process.returncode != 130 and not completed:
        # 130, or 0 when the signal came once the run had completed (its outcome decided)
        return False, f"{what}: exit {process.returncode}, not 130"
    if not bag.exists():
        return True, (f"{what}: exit {process.returncode}, no bag "
                      "(interrupted before the recorder started)")
    kept, holds = check(bag)
    return kept, f"{what}: exit {process.returncode}, {holds}"


def main() -> None:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("--sigint", type=int, default=100)
    parser.add_argument("--double", type=int, default=20)
    parser.add_argument("--sigkill", type=int, default=20)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--out", type=Path, default=Path("bags/soak"))
    parser.add_argument("--keep", action="store_true", help="keep the bags")
    args = parser.parse_args()
    _cli.new_directory(args.out)
    args.out.mkdir()
    rng = random.Random(args.seed)
    broken = 0
    plan = ["sigint"] * args.sigint + ["double"] * args.double + ["sigkill"] * args.sigkill
    for index, kind in enumerate(plan):
        bag = args.out / f"run-{index:03d}"
        kept, line = one_run(bag, rng, kind)
        broken += not kept
        print(f"{index:3d} {'ok    ' if kept else 'BROKEN'} {line}", flush=True)
        if kept and not args.keep:
            shutil.rmtree(bag, ignore_errors=True)
    print(f"{len(plan) - broken} of {len(plan)} runs kept every promise "
          f"({args.sigint} SIGINT, {args.double} double SIGINT, {args.sigkill} SIGKILL of a "
          f"random node, seed {args.seed})")
    sys.exit(1 if broken else 0)


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
