"""Launching the node graph: one process per node, in its own ROS domain.

Used by scripts/run_stack.py and by the tuner. It writes the run's ROS
parameter file, starts the five node processes, watches them, and stops
every one of them on the way out, whatever happened (end of run, a node
that died, Ctrl-C, a timeout).

The node processes are forked from a server that has imported rclpy and the
node modules once (ato_nodes.launcher.nodefork): importing them was most of a tuning
candidate's relaunch overhead. With ATO_NODE_START=subprocess, and for a run
whose fork server fails to start or dies before forking its first node (one line
on stderr says so), each node is a plain `python -m ato_nodes.nodes.ROLE`
subprocess instead (nodefork.start_plain).

A user's own node may stand in for the controller or the profile (`external`,
docs/external-nodes.md): the launcher starts its command in the run's domain and
environment, its own process group, with ROS arguments naming the run's parameter
file, or waits for a node the user starts.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ato_nodes.bags.bagrepair import RepairError, needs_repair, repair
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import ros_parameter_file
from ato_nodes.core.config.schema import NODES
from ato_nodes.launcher.nodefork import (LIBC, NODE_NAME_PREFIX, PR_SET_PDEATHSIG, STOP_GRACE,
                                         ForkedNode, NodeStartError, fork_server,
                                         plain_start_requested, start_plain)

REPO_ROOT = Path(__file__).resolve().parents[1]
# TCP port base + domain id held while a run uses that domain: below Linux's ephemeral
# range (32768-60999), where an outgoing connection could be handed the port (seen: the
# old base 47300 made a fault test fail in a fresh-clone CI run)
DOMAIN_LOCK_PORT = 30300
DOMAIN_IDS = range(1, 102)  # 0 is left for the user's own ROS graph
POLL = 0.05                # s between checks of the children (an exit is seen at once)
STOP_SIGNALS = {signal.SIGINT, signal.SIGTERM}


def node_processes(launcher: int) -> dict[str, int]:
    """The node processes a launcher process started, {role: pid} (from /proc: named
    ato-ROLE, children of the launcher's fork server; or, started plain, children of
    the launcher running `python -m ato_nodes.nodes.ROLE`)."""
    def parent(pid: str) -> int:
        return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])
    found = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            name = (entry / "comm").read_text().strip()
            if name.startswith(NODE_NAME_PREFIX) and parent(str(parent(entry.name))) == launcher:
                found[name[len(NODE_NAME_PREFIX):]] = int(entry.name)
            elif parent(entry.name) == launcher:
                argv = (entry / "cmdline").read_bytes().split(b"\0")
                module = argv[2].decode() if len(argv) > 2 and argv[1] == b"-m" else ""
                if module.startswith("ato_nodes.nodes."):
                    found[module.rsplit(".", 1)[1]] = int(entry.name)
        except (OSError, ValueError):
            continue
    return found


def _stopped(pid: int) -> bool:
    """The process is stopped by a signal (state T) or traced (t)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] in ("T", "t")
    except (OSError, IndexError):
        return False


# A domain lock handed down by the process that started this one: the number of an
# inherited file descriptor, the lock's socket (see DomainLock).
HANDED_DOWN_LOCK = "ATO_DOMAIN_LOCK_FD"


def _handed_down(domain_id: int) -> socket.socket | None:
    """The lock of `domain_id` this process inherited, if $ATO_DOMAIN_LOCK_FD names it."""
    number = os.environ.get(HANDED_DOWN_LOCK, "")
    if not number.isdigit():
        return None
    try:
        sock = socket.socket(fileno=os.dup(int(number)))
    except OSError:  # not open, or not a socket
        return None
    try:
        if sock.getsockname() == ("127.0.0.1", DOMAIN_LOCK_PORT + domain_id):
            return sock
    except OSError:
        pass
    sock.close()
    return None


class DomainLock:
    """A ROS domain id reserved for one run by holding a localhost TCP port.

    A process holding a domain's lock can hand it to a command it starts for that
    domain (`--domain-id N`): pass the lock's descriptor (subprocess's pass_fds) and
    its number in $ATO_DOMAIN_LOCK_FD; the command's DomainLock(N) then shares the
    lock instead of refusing the domain. Releasing the lock just before the command
    takes it would leave a moment when nobody holds the domain (another run could
    take it) and, once the command ends, the domain unheld while the parent still
    has participants in it (a test's probe)."""

    def __init__(self, domain_id: int | None = None):
        candidates = [domain_id] if domain_id is not None else list(DOMAIN_IDS)
        for candidate in candidates:
            sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            try:
                sock.bind(("127.0.0.1", DOMAIN_LOCK_PORT + candidate))
            except OSError:
                sock.close()
                continue
            self.domain_id, self._socket = candidate, sock
            return
        if domain_id is not None:
            inherited = _handed_down(domain_id)
            if inherited is not None:
                self.domain_id, self._socket = domain_id, inherited
                return
            raise RuntimeError(f"ROS domain {domain_id} is in use by another run")
        raise RuntimeError("no free ROS domain id")

    def handed_down(self, env: dict[str, str] | None = None) -> dict[str, Any]:
        """subprocess keyword arguments that hand this lock to the command started with
        them (given `--domain-id` this lock's domain_id): pass_fds, and `env` (default
        this process's environment) naming the descriptor."""
        return {"pass_fds": (self.fileno(),),
                "env": {**(os.environ if env is None else env),
                        HANDED_DOWN_LOCK: str(self.fileno())}}

    def fileno(self) -> int:
        return self._socket.fileno()

    def release(self) -> None:
        self._socket.close()


# If the launcher dies (even by SIGKILL), its fork server gives the nodes these signals
# (as the kernel does if the server dies too): SIGKILL for those with nothing to save,
# SIGTERM for the recorder, which then drains and closes its bag.
DEATH_SIGNAL = {role: signal.SIGTERM if role == "recorder" else signal.SIGKILL
                for role in NODES}
WORKDIR_PREFIX = "ato-run-"


def _remove_stale_workdirs() -> None:
    """Temporary run directories of launchers that were killed (their pid is gone)."""
    for path in Path(tempfile.gettempdir()).glob(f"{WORKDIR_PREFIX}*-*"):
        pid = path.name[len(WORKDIR_PREFIX):].split("-", 1)[0]
        if pid.isdigit() and not Path(f"/proc/{pid}").exists():
            shutil.rmtree(path, ignore_errors=True)


# Variables of the user's shell that would change where a run's traffic goes or how
# its middleware is configured, removed from every node's environment (the run then
# behaves the same whatever the shell has), with the reason for each.
IGNORED_ENVIRONMENT = {
    "ROS_STATIC_PEERS": "adds discovery peers off this host",
    "ROS_DISCOVERY_SERVER": "replaces simple discovery with a server, maybe on another host",
    "ROS_SUPER_CLIENT": "goes with ROS_DISCOVERY_SERVER",
    "ROS_LOCALHOST_ONLY": "deprecated; ROS_AUTOMATIC_DISCOVERY_RANGE is set instead",
    "FASTDDS_ENVIRONMENT_FILE": "a JSON file of these same variables, read by Fast DDS",
    "FASTRTPS_DEFAULT_PROFILES_FILE": "an XML profile: transports, peers, QoS",
    "FASTDDS_DEFAULT_PROFILES_FILE": "the same under its Fast DDS 3 name",
    "RMW_FASTRTPS_USE_QOS_FROM_XML": "QoS from the XML profile instead of the topic map's",
    "RMW_FASTRTPS_PUBLICATION_MODE": "synchronous/asynchronous writers: changes the timing",
    "FASTDDS_BUILTIN_TRANSPORTS": "replaces the default transports (shared memory, UDP)",
    "RMW_IMPLEMENTATION": "the wheels ship Fast DDS only",
    "ROS_SECURITY_ENABLE": "SROS 2 enclaves the run's nodes have no keys for",
    "ROS_SECURITY_STRATEGY": "goes with ROS_SECURITY_ENABLE",
    "ROS_SECURITY_KEYSTORE": "goes with ROS_SECURITY_ENABLE",
    "ROS_SECURITY_ENCLAVE_OVERRIDE": "goes with ROS_SECURITY_ENABLE",
}
# Set for every node: discovery on this host only, and no DEFAULT_FASTRTPS_PROFILES.xml
# picked up from the working directory.
FORCED_ENVIRONMENT = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "SKIP_DEFAULT_XML_FILE": "1"}


def isolate_to_this_host(env: dict[str, str]) -> None:
    """Runs stay on this host with the middleware's defaults, whatever the environment
    says: discovery on localhost only, none of the settings that add peers, transports
    or profiles."""
    for name in IGNORED_ENVIRONMENT:
        env.pop(name, None)
    env.update(FORCED_ENVIRONMENT)


def node_environment(domain_id: int) -> dict[str, str]:
    env = dict(os.environ)
    env.pop(HANDED_DOWN_LOCK, None)  # the launcher's; the nodes get their run's lock fd
    env["ROS_DOMAIN_ID"] = str(domain_id)
    isolate_to_this_host(env)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO_ROOT), env.get("PYTHONPATH")]))
    env["PYTHONUNBUFFERED"] = "1"
    return env


# The nodes a user's own node may stand in for (docs/external-nodes.md)
EXTERNAL_ROLES = ("controller", "profile")
EXTERNAL_CONTRACT = "docs/external-nodes.md"


def split_command(argv: list[str]) -> tuple[list[str], list[str]]:
    """A command line's own arguments and the external node's command after its first
    `--` (none without one)."""
    if "--" not in argv:
        return argv, []
    return argv[:argv.index("--")], argv[argv.index("--") + 1:]


def external_nodes(role: str | None, command: list[str]) -> dict[str, list[str]]:
    """--external ROLE and the command after --, checked before anything starts (a
    ScenarioError, one line): {role: command}, {} without --external."""
    if role is None:
        if command:
            raise ScenarioError(f"a command after -- ({command[0]}) needs --external ROLE")
        return {}
    if role not in EXTERNAL_ROLES:
        raise ScenarioError(f"--external {role}: a node of your own may stand in for "
                            f"{' or '.join(EXTERNAL_ROLES)}")
    if command and shutil.which(command[0]) is None:
        raise ScenarioError(f"--external {role}: command {command[0]} not found")
    return {role: command}


def external_arguments(role: str, params_path: Path) -> list[str]:
    """The ROS arguments an external node is given: its role's node name (the run's
    parameter file and run events address it so), simulated time, the parameter file."""
    return ["--ros-args", "-r", f"__node:={role}", "-p", "use_sim_time:=true",
            "--params-file", str(params_path)]


class ExternalNode(subprocess.Popen):
    """A user's command standing in for a node, in a session and process group of its
    own: signals go to the whole group (as a terminal's Ctrl-C would), and what is left
    of the group once the run is over is killed (`ros2 run` or a shell script runs the
    node in a child of its own)."""

    def send_signal(self, signum: int) -> None:
        self.signal_group(signum)

    def signal_group(self, signum: int) -> None:
        try:
            os.killpg(self.pid, signum)
        except (ProcessLookupError, PermissionError):  # the group is gone
            pass


def start_external(role: str, command: list[str], env: dict[str, str],
                   output: tuple[int, int], lock_fd: int, notify: threading.Event
                   ) -> ExternalNode:
    """Start `command` as the run's `role` (the domain's lock kept open while it lives,
    SIGTERM if the launcher's thread ends first); `notify` is set when it ends. A command
    that cannot start raises NodeStartError."""
    def in_the_child() -> None:  # the launcher may hold the stop signals: the node may not
        signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)
        LIBC.prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM))

    try:
        process = ExternalNode(command, env=env, stdin=subprocess.DEVNULL, stdout=output[0],
                               stderr=output[1], pass_fds=(lock_fd,), start_new_session=True,
                               preexec_fn=in_the_child)
    except OSError as exc:
        raise NodeStartError(f"the external {role} ({command[0]}) cannot start: "
                             f"{exc.strerror or exc}") from None

    def watch() -> None:
        process.wait()
        notify.set()

    threading.Thread(target=watch, name=f"external-{role}", daemon=True).start()
    return process


@dataclass
class RunOutcome:
    status: str  # "completed", "diverged", "pruned", "failed", "interrupted", "timeout"
    message: str = ""
    report: dict[str, Any] = field(default_factory=dict)
    domain_id: int = 0
    wall_time: float = 0.0

    @property
    def ok(self) -> bool:
        return self.status == "completed"


class Stack:
    """One run of the node graph. Use as a context manager or call run()."""

    def __init__(self, values: dict[str, Any], bag: Path, domain_id: int | None = None,
                 quiet: bool = False, timeout: float | None = None,
                 cancel: threading.Event | None = None,
                 external: dict[str, list[str]] | None = None):
        """`external`: {role: command} for each node a user's own stands in for (an
        empty command: the launcher waits for a node the user starts)."""
        self.values = dict(values)
        self.external = dict(external or {})
        self.bag = Path(bag)
        self.quiet = quiet
        self.timeout = timeout
        self.cancel = cancel  # set by another thread (a tuner stopping): stop now
        self.lock = DomainLock(domain_id)
        self.processes: dict[str, ForkedNode] = {}
        self.node_ended = threading.Event()  # set whenever one of them ends
        self.signalled = False  # SIGINT or SIGTERM while the run goes on: stop it
        _remove_stale_workdirs()
        self.workdir = Path(tempfile.mkdtemp(prefix=f"{WORKDIR_PREFIX}{os.getpid()}-"))
        self.report_path = self.workdir / "report.json"
        self.params_path = self.workdir / "params.yaml"
        self.values["recorder.output"] = str(self.bag.resolve())
        self.values["supervisor.report"] = str(self.report_path)
        self.params_yaml = yaml.safe_dump(ros_parameter_file(self.values), sort_keys=False)

    def interrupt(self, signum=None, frame=None) -> None:
        """Stop the run (a signal handler: run() installs it for SIGINT and SIGTERM; a
        launcher may install it before, so that a stop before run() is not lost)."""
        self.signalled = True

    def _start(self) -> None:
        self.params_path.write_text(self.params_yaml)
        env = node_environment(self.lock.domain_id)
        console = (open(os.devnull, "wb") if self.quiet else None)
        output = (console.fileno(),) * 2 if console else (1, 2)
        server = None
        if not plain_start_requested():
            try:
                server = fork_server(env, REPO_ROOT)
            except OSError as exc:
                print(f"node fork server not started ({exc}): starting the nodes as plain "
                      "processes", file=sys.stderr)
        try:
            for role in NODES:
                if role in self.external:
                    self._start_external(role, env, output)
                    continue
                # the nodes log to /rosout; the console keeps the launcher's concise lines
                argv = [f"ato_nodes.nodes.{role}", "--ros-args", "--params-file",
                        str(self.params_path), "--disable-stdout-logs"]
                start = (role, argv, env, REPO_ROOT, DEATH_SIGNAL[role], output,
                         self.lock.fileno(), self.node_ended)
                if server is not None:
                    try:
                        self.processes[role] = server.fork(
                            *start, bag=self.bag.resolve() if role == "recorder" else None)
                        continue
                    except NodeStartError as exc:
                        if any(isinstance(process, ForkedNode) for process in
                               self.processes.values()):  # forked nodes went with it: failed
                            raise
                        print(f"{exc} before forking a node: starting the nodes as plain "
                              "processes", file=sys.stderr)
                        server = None
                self.processes[role] = start_plain(*start)
        finally:
            if console:
                console.close()

    def _start_external(self, role: str, env: dict[str, str], output: tuple[int, int]) -> None:
        """The user's command as `role`, with the ROS arguments that make it the run's
        node; without a command, what to start and where, on stderr."""
        arguments = external_arguments(role, self.params_path)
        if self.external[role]:
            self.processes[role] = start_external(role, [*self.external[role], *arguments], env,
                                                  output, self.lock.fileno(), self.node_ended)
            return
        print(f"waiting {self.values['supervisor.ready_timeout']:g} s "
              f"(supervisor.ready_timeout) for the external {role}: start it with "
              f"ROS_DOMAIN_ID={self.lock.domain_id} ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST "
              f"and the arguments {' '.join(arguments)} ({EXTERNAL_CONTRACT})",
              file=sys.stderr, flush=True)

    def stop(self, ended: bool = False) -> None:
        """SIGINT every live node (the recorder drains and closes its bag), SIGCONT so a
        frozen one handles it too, then escalate. After a run the supervisor `ended`, the
        nodes first get STOP_GRACE to exit on its 'shutdown' (a signal would cut their
        last /rosout records short)."""
        if ended:
            self._still_running(STOP_GRACE)
        for process in self.processes.values():
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
                process.send_signal(signal.SIGCONT)
        for sig, within in ((signal.SIGTERM, STOP_GRACE), (signal.SIGKILL, 2.0)):
            for process in self._still_running(within):
                process.send_signal(sig)
        for process in self.processes.values():
            process.wait()
            if isinstance(process, ExternalNode):  # what its command left behind
                process.signal_group(signal.SIGKILL)

    def _still_running(self, within: float) -> list[ForkedNode]:
        """The nodes that have not exited within `within` s (one deadline for all)."""
        deadline = time.monotonic() + within
        running = []
        for process in self.processes.values():
            try:
                process.wait(max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                running.append(process)
        return running

    def _watch(self) -> RunOutcome:
        started = time.monotonic()
        early_exit: dict[str, float] = {}
        stopped_since: dict[str, float] = {}
        while True:
            self.node_ended.clear()
            codes = {role: process.poll() for role, process in self.processes.items()}
            if codes["supervisor"] == 0 or (codes["supervisor"] is not None
                                            and "failed" in self._report()):
                return self._finish()
            for role, process in self.processes.items():  # frozen: SIGSTOP, a debugger
                if _stopped(process.pid):
                    if time.monotonic() - stopped_since.setdefault(role, time.monotonic()) \
                            > STOP_GRACE:
                        return RunOutcome("failed", f"node '{role}' is stopped (SIGSTOP or a "
                                          "debugger) and the run cannot go on")
                else:
                    stopped_since.pop(role, None)
            for role, code in codes.items():
                if code not in (None, 0):
                    return RunOutcome("failed", f"node '{role}' exited with status {code}")
                # A clean exit is normal only once the supervisor has ended the run.
                if code == 0 and time.monotonic() - early_exit.setdefault(role, time.monotonic()) \
                        > STOP_GRACE:
                    return RunOutcome("failed", f"node '{role}' exited before the run ended")
            if self.timeout is not None and time.monotonic() - started > self.timeout:
                return RunOutcome("timeout", f"run did not finish within {self.timeout:g} s")
            if self.cancel is not None and self.cancel.is_set():
                return RunOutcome("interrupted", "stopped by its tuning")
            if self.signalled:
                return RunOutcome("interrupted", "; ".join([
                    "interrupted by the user", *(f"node '{role}' was stopped (SIGSTOP or a "
                                                 "debugger)" for role in stopped_since)]))
            self.node_ended.wait(POLL)

    def _stall(self) -> str:
        """Where a run that timed out stood: the topic with the fewest recorded messages
        names the node the loop waited for (the recorder, when every topic is level:
        the plant waits for it, run.record_lag)."""
        from ato_nodes.bags.bagio import BagError, message_counts
        from ato_nodes.core.base.topics import step_topics
        publishers = {topic.name: topic.publishers[0] for topic in step_topics(self.values)}
        try:  # per-step topics only (live parameter changes are few, or none)
            counts = {name: count for name, count in message_counts(self.bag).items()
                      if name in publishers}
        except BagError:
            return ""
        if not counts:
            return ""
        fewest = min(counts.values())
        if max(counts.values()) - fewest <= 2:
            return f"; every topic stops near step {fewest}: the recorder stopped taking steps"
        behind = sorted({publishers.get(name, "?") for name, count in counts.items()
                         if count == fewest})
        return (f"; the loop stalled at step {fewest}, waiting for "
                f"{', '.join(behind)} (its topics have the fewest messages)")

    def _repair(self) -> str:
        """A bag whose recorder was killed is made complete again; what that kept."""
        if not needs_repair(self.bag):
            return ""
        try:
            return repair(self.bag).describe()
        except RepairError as exc:
            return f"bag not repaired: {exc}"

    def _report(self) -> dict:
        """The supervisor's report ({} before it is written)."""
        return json.loads(self.report_path.read_text()) if self.report_path.exists() else {}

    def _finish(self) -> RunOutcome:
        """The supervisor ended the run; the other nodes are exiting on 'shutdown'."""
        if not self.report_path.exists():
            return RunOutcome("failed", "the supervisor stopped the run before it completed "
                              "(a node never became ready)")
        report = json.loads(self.report_path.read_text())
        if report.get("failed"):  # the supervisor's reason (a node that never became ready)
            return RunOutcome("failed", report["failed"] + self._external_hint(
                report.get("not_ready", [])))
        if report.get("pruned"):
            return RunOutcome("pruned", f"pruned at step {report['steps']}: the running "
                              f"fitness {report['fitness']:.9g} passed its bound", report=report)
        if report.get("diverged"):
            return RunOutcome("diverged", f"the run diverged at step {report['steps']} (speed not "
                              "finite or beyond plant.max_speed)", report=report)
        return RunOutcome("completed", report=report)

    def _external_hint(self, not_ready: list[str]) -> str:
        """What the external nodes among those never ready must do."""
        return "".join(
            f" (the external {role} never announced 'ready {role}': see {EXTERNAL_CONTRACT})"
            if role in not_ready else f" (the external {role} was ready: they wait for one "
            f"of its topics, see {EXTERNAL_CONTRACT})" for role in self.external if not_ready)

    def run(self) -> RunOutcome:
        """Start, watch, stop. SIGTERM interrupts a run as Ctrl-C does; once the run is
        stopping, further signals wait until every node is stopped and the bag is
        complete (repaired if its writer died). The outcome is decided here, once: a
        stop that comes after the supervisor reported the run's end changes nothing."""
        started = time.monotonic()
        main = threading.current_thread() is threading.main_thread()
        # A signal only sets a flag that the watch loop reads (within POLL): raised as an
        # exception it could land anywhere, a second one inside the handling of the first.
        previous = {number: signal.signal(number, self.interrupt) for number in STOP_SIGNALS} \
            if main else {}
        try:
            try:
                self._start()
                outcome = self._watch()
            except NodeStartError as exc:
                outcome = RunOutcome("failed", str(exc))
            finally:
                blocked = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS) if main else None
                try:
                    outcome = self._stop_and_decide(outcome)
                finally:
                    if main:  # a Ctrl-C pressed while stopping is spent, not re-raised;
                        # the caller's handlers are back before any signal can come
                        for number in previous:
                            signal.signal(number, signal.SIG_IGN)
                        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
                        for number, handler in previous.items():
                            signal.signal(number, handler)
        finally:
            shutil.rmtree(self.workdir, ignore_errors=True)  # thousands of runs when tuning
        outcome.domain_id = self.lock.domain_id
        outcome.wall_time = time.monotonic() - started
        return outcome

    def _stop_and_decide(self, outcome: RunOutcome) -> RunOutcome:
        """Every node stopped, the domain released, the bag complete; the run's outcome.
        A run interrupted after the supervisor had reported its end (it writes its report
        once the recorder holds every step) ended as reported: its bag is complete."""
        supervisor = self.processes.get("supervisor")
        self.stop(ended=supervisor is not None and supervisor.poll() == 0)
        self.lock.release()
        if outcome.status == "interrupted" and self.report_path.exists():
            outcome = self._finish()
        outcome.message = "; ".join(filter(None, [outcome.message, self._repair()]))
        if outcome.status == "timeout":
            outcome.message += self._stall()
        if self.report_path.exists() and not outcome.report:
            outcome.report = json.loads(self.report_path.read_text())
        return outcome


def run_checked(values: dict[str, Any], bag: Path, timeout: float = 900.0,
                external: dict[str, list[str]] | None = None
                ) -> tuple[dict[str, Any], bool | None]:
    """One run through the stack, scored from its bag, and the same run in-process:
    (the bag's indices, whether the two agree bit for bit; None with an `external` node,
    whose law only it runs). A failed run raises RuntimeError with the launcher's
    one-line message."""
    from ato_nodes.bags.bagio import read_run
    from ato_nodes.core.run.loop import simulate
    from ato_nodes.core.run.scoring import score_series
    outcome = Stack(values, bag, quiet=True, timeout=timeout, external=external).run()
    if not outcome.ok:
        raise RuntimeError(f"{bag}: {outcome.message}")
    run = read_run(bag)
    if external:
        return score_series(run.series, run.parameters), None
    identical = all(np.array_equal(run.series[name], series, equal_nan=True)
                    for name, series in simulate(values).items() if name != "t")
    return score_series(run.series, run.parameters), identical
