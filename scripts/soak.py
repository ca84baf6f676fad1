#!/usr/bin/env python3
"""Soak the promises of a run's end: runs interrupted or killed where the run's own
progress says, not after a guessed delay, and every promise checked where each landed.

    python scripts/soak.py [--sigint 100] [--double 20] [--sigkill 20] [--after-end 0]
                           [--scenario seed000] [--duration 100] [--set NAME=VALUE]
                           [--seed 1] [--jobs 1] [--timeout 300] [--out bags/soak] [--keep]
    python scripts/soak.py --scenario seed004-metro-line --duration 400 \\
        --set profile.journey.dwell_extension=2:30,3:20      # dwells and two re-plans

The run is first simulated in this process (the stack records the same steps, bit for
bit): that says at which steps the train stands in a dwell and at which a journey
re-plans. Each run then draws where its signal is to land: a random step while the loop
steps, and on a journey as many inside a dwell and within 2 s of simulated time of a
re-plan, in turn; --after-end SIGINTs come once the recorder has closed the bag and the
supervisor has ended, while the run is scored. The signal is sent when the bag being
written (the MCAP chunks the recorder hands the operating system every half
run.record_lag) reaches that step, less the lead the earlier runs of that kind measured.
SIGINT goes to run_stack.py, a double SIGINT gets a second one 0.05-1 s later, SIGKILL
goes to a random node (a SIGKILL that finds no node is a failure). The steps the bag
then holds are where the signal landed; the phase (stepping, dwell, re-plan, after end)
is the reference run's there.

Checked after every run: the bag opens in rosbags and in mcap's reader, both hold per
topic the counts summary.json states, and its scored steps are what the bag scores;
summary.json and params.yaml are there; the exit status is 130 for an interrupt (0 or 130
after the end), 1 for a killed node, and agrees with summary.json's status; a killed node
is named; a journey's bag holds its re-plans up to its last step; no process the run
started is left; stderr holds no traceback. One line per run, a table of kind by phase at
the end; exit status 1 if any run broke a promise or its signal missed the run.
Not a test: a run takes 5-40 s of wall time (the --duration, the machine's load).
"""

from __future__ import annotations

import json
import os
import random
import shutil
import signal
import struct
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from statistics import median

import _cli
import numpy as np

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.base.topics import step_topics, topic_map
from ato_nodes.core.config.schema import NODES, recording_steps
from ato_nodes.core.targets.served import STANDSTILL
from ato_nodes.launcher.launch import node_processes

ROOT = Path(__file__).resolve().parents[1]
PHASES = ("stepping", "dwell", "re-plan", "after end")
KINDS = {"sigint": "SIGINT", "double": "double SIGINT", "sigkill": "SIGKILL"}
EXIT_STATUS = {"sigint": 130, "double": 130, "sigkill": 1}
STATUS_OF_EXIT = {0: "completed", 1: "failed", 130: "interrupted"}  # summary.json's
REPLAN_WINDOW = 2.0  # s of simulated time either side of a re-plan's step: 'at' it
POLL = 0.01          # s between looks at the bag being written
SCAN = 0.25          # s between looks for the run's processes
# s the run's processes have to be gone once run_stack.py has exited (its node fork
# server exits on the launcher's end, some 0.2 s later; guarantees.md: no node outlives
# its launcher by more than 5 s)
LEFT_GRACE = 5.0
# a Python traceback, a thread's stack dumped by faulthandler (a stalled teardown), a crash
TRACEBACK_MARKS = ("(most recent call last)", "(most recent call first)", "Fatal Python error")
MCAP_MAGIC = b"\x89MCAP0\r\n"
MCAP_MESSAGE, MCAP_CHUNK = 0x05, 0x06  # record opcodes (the MCAP specification)
STOPPING = threading.Event()  # the soak itself was interrupted: stop the runs


@dataclass
class Reference:
    """The run as simulated in this process: where each phase is, in steps."""

    period: float            # run.period, s
    total: int               # steps of the whole run
    standing: np.ndarray     # per step: the train stands at a stop (a dwell)
    replans: list[dict]      # the re-plans as the profile publishes them (with "step")
    window: int              # steps either side of a re-plan that are 'at' it
    first: int               # no signal aims before the bag's first block of steps
    margin: int              # nor, while stepping, this close to the end
    lag: int                 # steps the plant may run ahead of the bag on disk

    def phase(self, landed: int) -> str:
        """The phase of a run whose bag holds `landed` steps."""
        if landed >= self.total:
            return "after end"
        if any(abs(landed - replan["step"]) <= self.window for replan in self.replans):
            return "re-plan"
        return "dwell" if self.standing[landed] else "stepping"

    def candidates(self, aim: str) -> list[int]:
        """The steps a signal aimed at phase `aim` may aim at: inside it, away from its
        edges where a landing a little early or late would leave it."""
        if aim == "re-plan":
            half = self.window // 2
            return [replan["step"] + offset for replan in self.replans
                    for offset in range(-half, half + 1)]
        inside = [k for k in range(self.first, self.total - self.margin)
                  if self.phase(k) == aim]
        if aim == "dwell":  # the dwell's every step within a window either side
            kernel = np.ones(2 * self.window + 1)
            deep = np.convolve(self.standing, kernel, mode="same") == kernel.size
            inside = [k for k in inside if deep[k]]
        return inside


def reference(scenario: str, overrides: list[str]) -> Reference:
    """The run simulated in this process; bad input is one line and exit 2."""
    from ato_nodes.core.config.context import RunContext
    from ato_nodes.core.config.scenario import prepare
    from ato_nodes.core.run.loop import simulate
    from ato_nodes.core.targets.served import JourneyPlan, replans
    try:
        values = prepare(scenario, overrides)
    except ScenarioError as exc:
        _cli.fail(str(exc))
    series = simulate(values)
    period = values["run.period"]
    plan = RunContext(values).plan
    made = replans(plan, period, series["position"]) if isinstance(plan, JourneyPlan) else []
    standing = series["speed"] < STANDSTILL
    moving = np.flatnonzero(~standing)
    standing[:moving[0] if len(moving) else len(standing)] = False  # not before it leaves
    block, lag = recording_steps(values)
    total = len(series["t"])
    lag = lag or 2 * block
    return Reference(period=period, total=total, standing=standing,
                     replans=[json.loads(json.dumps({"step": round(replan.time / period),
                                                     **replan._asdict()})) for replan in made],
                     window=round(REPLAN_WINDOW / period), first=2 * block,
                     margin=max(4 * lag, total // 20), lag=lag)


def scan_records(data: bytes) -> tuple[int, int]:
    """(the bytes of the whole MCAP records at the start of `data`, the latest log time
    of the messages in them, ns; -1 if none). A record still being written waits."""
    used, latest = 0, -1
    while used + 9 <= len(data):
        opcode = data[used]
        (length,) = struct.unpack_from("<Q", data, used + 1)
        end = used + 9 + length
        if end > len(data):
            break
        if opcode == MCAP_CHUNK:  # message_start_time, message_end_time, ...
            first, last = struct.unpack_from("<QQ", data, used + 9)
            latest = max(latest, last) if first <= last else latest  # else no message
        elif opcode == MCAP_MESSAGE:  # channel_id u16, sequence u32, log_time, ...
            latest = max(latest, struct.unpack_from("<Q", data, used + 15)[0])
        used = end
    return used, latest


class BagProgress:
    """How far the bag being written has got, from the records on disk, read as they
    come: the steps up to its latest message (stamped k run.period)."""

    def __init__(self, bag: Path, period: float):
        self.bag, self.period_ns = bag, period * 1e9
        self.handle = None
        self.pending = b""
        self.started = False  # past the file's leading magic
        self.latest = -1

    def steps(self) -> int:
        if self.handle is None:
            found = sorted(self.bag.glob("*.mcap")) if self.bag.is_dir() else []
            if not found:
                return 0
            self.handle = found[0].open("rb")
        self.pending += self.handle.read()
        if not self.started:
            if len(self.pending) < len(MCAP_MAGIC):
                return 0
            self.pending, self.started = self.pending[len(MCAP_MAGIC):], True
        used, latest = scan_records(self.pending)
        self.pending = self.pending[used:]
        self.latest = max(self.latest, latest)
        return round(self.latest / self.period_ns) + 1 if self.latest >= 0 else 0

    def closed(self) -> bool:
        """The recorder has closed the bag (its metadata.yaml is written then)."""
        return (self.bag / "metadata.yaml").exists()

    def close(self) -> None:
        if self.handle is not None:
            self.handle.close()


@dataclass
class Draw:
    index: int
    kind: str           # a key of KINDS
    aim: str            # the phase aimed at
    target: int | None  # the step aimed at; None: once the bag is closed
    victim: str         # the node a SIGKILL goes to
    spacing: float      # s between a double SIGINT's two


def draws(counts: dict[str, int], after_end: int, ref: Reference,
          rng: random.Random) -> list[Draw]:
    """Every run's draw, in order (the same for a seed whatever the timing): the runs
    of a kind aim at the phases the run has in turn, each at a random step of it."""
    pools = {aim: ref.candidates(aim) for aim in ("stepping", "dwell", "re-plan")}
    aims = [aim for aim, steps in pools.items() if steps]
    plan = [(kind, aims[turn % len(aims)]) for kind, count in counts.items()
            for turn in range(count)]
    made = []
    for index, (kind, aim) in enumerate(plan + [("sigint", "after end")] * after_end):
        target = None if aim == "after end" else rng.choice(pools[aim])
        made.append(Draw(index, kind, aim, target, rng.choice(NODES),
                         round(rng.uniform(0.05, 1.0), 2)))
    return made


class Leads:
    """How many steps past the bag's progress at the signal each kind lands (the launcher
    and the nodes take a moment to stop): the median so far, aimed that much early."""

    def __init__(self, start: int):
        self.start, self.seen, self.lock = start, {}, threading.Lock()

    def steps(self, kind: str) -> int:
        with self.lock:
            seen = self.seen.get(kind)
            return round(median(seen)) if seen else self.start

    def add(self, kind: str, overshoot: int) -> None:
        with self.lock:
            self.seen.setdefault(kind, []).append(max(0, overshoot))


def process_table() -> dict[int, list[str]]:
    """{pid: the fields of /proc/PID/stat after the name} of every process."""
    table = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                table[int(entry.name)] = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except (OSError, IndexError):
                continue
    return table


def descendants(root: int) -> dict[int, str]:
    """{pid: start time} of every process under `root`."""
    table = process_table()
    found, parents = {}, {root}
    while parents:
        children = {pid for pid, fields in table.items() if int(fields[1]) in parents}
        found.update({pid: table[pid][19] for pid in children - found.keys()})
        parents = children - {root}
        table = {pid: fields for pid, fields in table.items() if pid not in children}
    return found


def left_behind(seen: dict[int, str], group: int) -> list[int]:
    """The processes of a run that has exited still there after LEFT_GRACE (not
    zombies): those seen under it (the same start time, not a reused pid) and those in
    its process group."""
    deadline = time.monotonic() + LEFT_GRACE
    while True:
        left = sorted(pid for pid, fields in process_table().items() if fields[0] != "Z" and (
            seen.get(pid) == fields[19] or int(fields[2]) == group))
        if not left or time.monotonic() > deadline:
            return left
        time.sleep(SCAN)


def named(pid: int) -> str:
    """A process as `ps` names it: its name and pid."""
    try:
        return f"{Path(f'/proc/{pid}/comm').read_text().strip()} ({pid})"
    except OSError:
        return str(pid)


@dataclass
class Outcome:
    draw: Draw
    sent_at: int | None = None  # the bag's steps when the signal went
    landed: int = 0             # the steps the bag holds
    phase: str = "after end"
    code: int | None = None
    wall: float = 0.0
    checked: list[str] = field(default_factory=list)
    failed: list[str] = field(default_factory=list)

    def held(self) -> bool:
        return not self.failed


def signal_run(process: subprocess.Popen, draw: Draw, nodes: dict[str, int]) -> str:
    """Send the draw's signal (a SIGKILL to its victim among the run's `nodes`); what
    went wrong, if anything."""
    if draw.kind == "sigkill":
        try:
            os.kill(nodes[draw.victim], signal.SIGKILL)
            return ""
        except (KeyError, ProcessLookupError):
            return f"signal: SIGKILL found no {draw.victim} node (nodes: {', '.join(nodes)})"
    process.send_signal(signal.SIGINT)
    if draw.kind == "double":
        time.sleep(draw.spacing)
        process.send_signal(signal.SIGINT)  # nothing if it has exited meanwhile
    return ""


def trigger_step(target: int, lead: int) -> int:
    """The bag's steps at which a signal aimed at step `target` goes: `lead` early, but
    never before the bag holds a step (before, the run may still be starting Python, where
    a SIGINT is Python's own; guarantees.md)."""
    return max(1, target - lead)


def due(progress: BagProgress, trigger: int | None, launcher: int) -> bool:
    """The signal is due: the bag has reached the trigger's step, or (None) the run is
    over, its bag closed and its supervisor gone, and the launcher finishes it. A run over
    before its step came gets its signal then too."""
    if not progress.closed():
        return trigger is not None and progress.steps() >= trigger
    return trigger is not None or "supervisor" not in node_processes(launcher)


def watch(process: subprocess.Popen, bag: Path, draw: Draw, lead: int, period: float,
          seen: dict[int, str]) -> tuple[int | None, str]:
    """Follow the run until its signal is due, then send it: (the bag's steps then, or
    None if the run ended first; what went wrong). `seen` collects its processes."""
    progress = BagProgress(bag, period)
    trigger = None if draw.target is None else trigger_step(draw.target, lead)
    next_scan = 0.0
    try:
        while process.poll() is None and not STOPPING.is_set():
            if time.monotonic() >= next_scan:
                seen.update(descendants(process.pid))
                next_scan = time.monotonic() + SCAN
            if due(progress, trigger, process.pid):
                seen.update(descendants(process.pid))
                # the nodes looked up first: the bag's steps are read just as it goes
                nodes = node_processes(process.pid) if draw.kind == "sigkill" else {}
                return progress.steps(), signal_run(process, draw, nodes)
            time.sleep(POLL)
    finally:
        progress.close()
    if STOPPING.is_set():  # the soak is interrupted: so is the run, as a user would
        process.send_signal(signal.SIGINT)
        return None, "signal: the soak was interrupted"
    return None, "signal: the run was over before its signal was due"


@dataclass
class Soak:
    """What every run of the soak shares."""

    command: list[str]  # run_stack.py and its options, but --out
    ref: Reference
    out: Path
    leads: Leads
    timeout: float      # s of wall time a run may take


def one_run(draw: Draw, soak: Soak) -> Outcome:
    """One run signalled as drawn, and its promises checked."""
    bag = soak.out / f"run-{draw.index:03d}"
    outcome, seen = Outcome(draw), {}
    started = time.monotonic()
    with (soak.out / f"{bag.name}.stderr").open("w+") as stderr:
        process = subprocess.Popen([*soak.command, "--out", str(bag)], cwd=ROOT,
                                   stdout=subprocess.DEVNULL, stderr=stderr,
                                   start_new_session=True)
        try:
            outcome.sent_at, problem = watch(process, bag, draw, soak.leads.steps(draw.kind),
                                             soak.ref.period, seen)
            outcome.code = process.wait(soak.timeout)
        except subprocess.TimeoutExpired:
            problem = f"exit: still running after {soak.timeout:g} s (its group killed)"
            os.killpg(process.pid, signal.SIGKILL)
        finally:
            if process.poll() is None:  # the soak is stopping: the run goes with it
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()
        outcome.wall = time.monotonic() - started
        stderr.seek(0)
        errors = stderr.read()
    outcome.failed += [problem] if problem else []
    check_run(outcome, bag, soak.ref, errors, left_behind(seen, process.pid))
    if outcome.sent_at is not None and outcome.phase != "after end" and not problem:
        soak.leads.add(draw.kind, outcome.landed - outcome.sent_at)
    return outcome


def bag_counts(bag: Path) -> tuple[dict[str, int], dict[str, int], list[dict]]:
    """(messages per topic in rosbags, in mcap's reader, the re-plans the bag holds)."""
    from mcap.reader import make_reader
    from rosbags.highlevel import AnyReader
    replans_topic = topic_map()["replans"].name
    with AnyReader([bag]) as reader:
        in_rosbags = {connection.topic: 0 for connection in reader.connections}
        held = []
        for connection, _, raw in reader.messages():
            in_rosbags[connection.topic] += 1
            if connection.topic == replans_topic:
                held.append(json.loads(reader.deserialize(raw, connection.msgtype).data))
    (mcap_file,) = bag.glob("*.mcap")
    with mcap_file.open("rb") as handle:
        mcap = make_reader(handle)
        in_mcap = {channel.topic: 0 for channel in mcap.get_summary().channels.values()}
        for _, channel, _ in mcap.iter_messages():
            in_mcap[channel.topic] += 1
    return in_rosbags, in_mcap, held


def check_bag(outcome: Outcome, bag: Path, ref: Reference) -> dict:
    """The bag's promises; summary.json's contents ({} if it has none)."""
    from ato_nodes.bags.bagio import read_run
    outcome.checked.append("readers")
    try:
        in_rosbags, in_mcap, held = bag_counts(bag)
        outcome.landed = min(in_rosbags.get(topic.name, 0) for topic in step_topics())
        scored = len(read_run(bag).series["t"]) if outcome.landed else 0
        summary = json.loads((bag / "summary.json").read_text())
    except Exception as exc:  # whatever a reader raises is what the soak reports
        outcome.failed.append(f"readers: {type(exc).__name__}: {exc}")
        return {}
    if in_rosbags != in_mcap:
        outcome.failed.append(f"readers: rosbags {in_rosbags} but mcap {in_mcap}")
    outcome.checked.append("counts")
    if summary.get("recorded") != in_rosbags or summary.get("scored_steps") != scored:
        outcome.failed.append(f"counts: summary.json {summary.get('recorded')}, "
                              f"{summary.get('scored_steps')} scored; the bag {in_rosbags}, "
                              f"{scored} scored")
    outcome.checked.append("files")
    if not (bag / "params.yaml").exists():
        outcome.failed.append("files: no params.yaml")
    if ref.replans:
        outcome.checked.append("re-plans")
        due = [replan for replan in ref.replans if replan["step"] < outcome.landed]
        if held != ref.replans[:len(held)] or len(held) < len(due):
            outcome.failed.append(f"re-plans: the bag holds steps {[r['step'] for r in held]}, "
                                  f"due {[r['step'] for r in due]}")
    return summary


def check_run(outcome: Outcome, bag: Path, ref: Reference, errors: str,
              left: list[int]) -> None:
    """Every promise of the run's end, where its signal landed."""
    draw = outcome.draw
    summary = check_bag(outcome, bag, ref) if bag.is_dir() else {}
    if not bag.is_dir():
        outcome.failed.append("readers: no bag")
    outcome.phase = ref.phase(outcome.landed)
    expected = {0, 130} if outcome.phase == "after end" and draw.kind != "sigkill" \
        else {EXIT_STATUS[draw.kind]}
    outcome.checked.append("exit")
    if outcome.code not in expected or summary.get("status") != STATUS_OF_EXIT.get(outcome.code):
        wanted = " or ".join(map(str, sorted(expected)))
        outcome.failed.append(f"exit: status {outcome.code} (expected {wanted}; it goes with "
                              f"{STATUS_OF_EXIT.get(outcome.code)!r}), summary.json's status "
                              f"{summary.get('status')!r}")
    if draw.kind == "sigkill":
        outcome.checked.append("named")
        if f"'{draw.victim}'" not in summary.get("message", ""):
            outcome.failed.append(f"named: {draw.victim} not in {summary.get('message')!r}")
    outcome.checked += ["processes", "stderr"]
    if left:
        outcome.failed.append(f"processes: {', '.join(map(named, left))} left")
    marks = [line for line in errors.splitlines()
             if any(mark in line for mark in TRACEBACK_MARKS)]
    if marks:
        outcome.failed.append(f"stderr: {marks[0]}")


def line(outcome: Outcome) -> str:
    """One run: where it aimed, where the signal went and landed, what was checked."""
    draw = outcome.draw
    what = KINDS[draw.kind] + (f" {draw.victim}" if draw.kind == "sigkill" else "") + \
        (f" +{draw.spacing:.2f} s" if draw.kind == "double" else "")
    aimed = draw.aim + ("" if draw.target is None else f" {draw.target}")
    sent = "not sent" if outcome.sent_at is None else f"sent at {outcome.sent_at}"
    text = (f"{draw.index:3d} {'held  ' if outcome.held() else 'FAILED'} {what:<24} aimed "
            f"{aimed:<14} {sent:<13} landed {outcome.landed:>5} {outcome.phase:<9} exit "
            f"{outcome.code}  {outcome.wall:5.1f} s  checked {', '.join(outcome.checked)}")
    return text + "".join(f"\n      {failure}" for failure in outcome.failed)


def table(outcomes: list[Outcome]) -> str:
    """Runs by kind (rows) and the phase they landed in (columns): held / failed."""
    width = 20
    rows = [f"{'kind / landed':<16}" + "".join(f"{phase:>{width}}" for phase in PHASES)]
    for kind, name in KINDS.items():
        cells = []
        for phase in PHASES:
            here = [o for o in outcomes if o.draw.kind == kind and o.phase == phase]
            held = sum(o.held() for o in here)
            cells.append(f"{held} held, {len(here) - held} failed" if here else "-")
        rows.append(f"{name:<16}" + "".join(f"{cell:>{width}}" for cell in cells))
    if not outcomes:
        return "\n".join(rows)
    aimed = sum(o.phase == o.draw.aim for o in outcomes)
    walls = sorted(o.wall for o in outcomes)
    rows.append(f"{aimed} of {len(outcomes)} landed in the phase they aimed at; wall time per "
                f"run: median {median(walls):.1f} s, longest {walls[-1]:.1f} s, "
                f"{sum(walls):.0f} s in all")
    return "\n".join(rows)


def parse_args():
    parser = _cli.argument_parser(__doc__)
    for kind in KINDS:
        parser.add_argument(f"--{kind}", type=int, default=20 if kind != "sigint" else 100,
                            help=f"runs that get a {KINDS[kind]} (default %(default)s)")
    parser.add_argument("--after-end", type=int, default=0,
                        help="runs that get a SIGINT once they have ended (the bag closed), while "
                             "they are scored (default 0)")
    parser.add_argument("--scenario", default="seed000", help="as run_stack.py takes it "
                        "(default seed000)")
    parser.add_argument("--duration", type=float, default=100.0,
                        help="simulated seconds of each run (default 100)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="a parameter of every run, as run_stack.py takes it")
    parser.add_argument("--seed", type=int, default=1, help="of the draws (default 1)")
    parser.add_argument("--jobs", type=int, default=1, help="runs at a time (default 1)")
    parser.add_argument("--timeout", type=float, default=300.0,
                        help="wall seconds a run may take before it counts as hung "
                             "(default 300)")
    parser.add_argument("--out", type=Path, default=Path("bags/soak"),
                        help="directory to create for the runs' bags (default bags/soak)")
    parser.add_argument("--keep", action="store_true", help="keep the bags of held runs")
    args = parser.parse_args()
    for name in (*KINDS, "after_end"):
        if getattr(args, name) < 0:
            _cli.fail(f"--{name.replace('_', '-')} {getattr(args, name)} is negative")
    if args.jobs < 1:
        _cli.fail(f"--jobs {args.jobs} is not a positive number of runs")
    _cli.seconds(args.timeout, "--timeout")
    return args


def run_all(plan: list[Draw], soak: Soak, jobs: int, keep: bool) -> list[Outcome]:
    """Every run, `jobs` at a time, each printed as it ends."""
    outcomes = []
    with ThreadPoolExecutor(jobs) as pool:
        futures = [pool.submit(one_run, draw, soak) for draw in plan]
        try:
            for future in as_completed(futures):
                outcome = future.result()
                outcomes.append(outcome)
                print(line(outcome), flush=True)
                if outcome.held() and not keep:
                    name = f"run-{outcome.draw.index:03d}"
                    shutil.rmtree(soak.out / name, ignore_errors=True)
                    (soak.out / f"{name}.stderr").unlink(missing_ok=True)
        except KeyboardInterrupt:
            STOPPING.set()  # the running ones are interrupted; the others never start
            for future in futures:
                future.cancel()
            raise
    return sorted(outcomes, key=lambda outcome: outcome.draw.index)


def main() -> None:
    args = parse_args()
    overrides = [*args.set, f"run.duration={args.duration}"]
    _cli.new_directory(args.out)
    ref = reference(args.scenario, overrides)
    args.out.mkdir(parents=True)
    command = [sys.executable, str(ROOT / "scripts" / "run_stack.py"), "--scenario",
               args.scenario, "--duration", str(args.duration),
               *[option for value in args.set for option in ("--set", value)]]
    counts = {kind: getattr(args, kind) for kind in KINDS}
    plan = draws(counts, args.after_end, ref, random.Random(args.seed))
    print(f"{args.scenario}, {ref.total} steps of {ref.period:g} s; dwells: "
          f"{int(ref.standing.sum())} steps; re-plans at steps "
          f"{[replan['step'] for replan in ref.replans] or 'none'}", flush=True)
    soak = Soak(command, ref, args.out, Leads(ref.lag), args.timeout)
    outcomes = run_all(plan, soak, args.jobs, args.keep)
    print(table(outcomes))
    failed = sum(not outcome.held() for outcome in outcomes)
    print(f"{len(outcomes) - failed} of {len(outcomes)} runs kept every promise checked "
          f"({', '.join(f'{count} {KINDS[kind]}' for kind, count in counts.items())}, "
          f"{args.after_end} SIGINT after the end; {args.scenario}, seed {args.seed})")
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
