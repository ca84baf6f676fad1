"""Node processes forked from a server that has imported rclpy and the node modules.

Importing rclpy, the message packages and a node's modules costs 0.5-1 s of CPU
per process: with five processes on two cores, most of a tuning candidate's
relaunch overhead. So the launcher starts one fork server per launcher process
(`python -m ato_nodes.launcher.nodefork`, started at the first run), which imports them
once, before any ROS context exists, and forks each node on request. A forked node
makes itself what a freshly started `python -m ato_nodes.nodes.ROLE` is (own
session, environment, arguments, working directory, console), then runs the
node's main(), which initialises its own context in its own domain.

Protocol, over a Unix SOCK_SEQPACKET socket pair: the launcher sends a JSON
request {role, argv, env, cwd, death_signal, bag} with the node's stdout, stderr
and lock file descriptors attached; the server answers {"pid": PID} and, once the
node has ended and been reaped, {"exited": PID, "status": CODE} (CODE as
subprocess's returncode: negative for a signal). When the launcher ends (end of
file on the socket) with nodes still running, the server gives them their death
signals, kills those still there after STOP_GRACE and repairs the recorder's bag
if it had to kill the recorder; then it ends. A server killed outright leaves
the nodes their death signals (PR_SET_PDEATHSIG).

The plain start stays supported (`start_plain`): each node a `python -m
ato_nodes.nodes.ROLE` subprocess of the launcher with the same environment,
arguments, working directory, console, session, held stop signals, death signal and
lock descriptor. The launcher uses it when ATO_NODE_START=subprocess is set, and for
a run whose fork server failed to start or died before forking its first node. What
it lacks: nobody outlives a killed launcher to SIGKILL a node deaf to its death
signal or repair the bag of a recorder killed that way.
"""

from __future__ import annotations

import atexit
import ctypes
import importlib
import json
import os
import select
import signal
import socket
import subprocess
import sys
import threading
import time
import traceback
from pathlib import Path

from ato_nodes.core.config.schema import NODES

PR_SET_PDEATHSIG = 1
PR_SET_NAME = 15
NODE_NAME_PREFIX = "ato-"  # a forked node's process name (/proc/PID/comm): ato-ROLE
MESSAGE_SIZE = 1 << 20     # bytes: a request carries the node's whole environment
STOP_SIGNALS = {signal.SIGINT, signal.SIGTERM}
STOP_GRACE = 5.0           # s a node has to exit once told to, before it is killed
LIBC = ctypes.CDLL(None, use_errno=True)  # loaded before any fork: prctl in the child


# Server side ---------------------------------------------------------------
def _exit_status(wait_status: int) -> int:
    return -os.WTERMSIG(wait_status) if os.WIFSIGNALED(wait_status) \
        else os.WEXITSTATUS(wait_status)


def _become_node(connection: socket.socket, request: dict, fds: list[int]) -> None:
    """In the forked child: become the node's process and run it; never returns.
    SIGINT and SIGTERM stay held (the server holds them) until the node has its own
    handlers (run_node unblocks them), so a stop that comes while it starts is kept.
    The lock fd (the domain's lock port) stays open for the process's lifetime: a
    node that outlives its launcher keeps its domain from the next run."""
    status = 1
    try:
        connection.close()
        os.setsid()
        LIBC.prctl(PR_SET_PDEATHSIG, request["death_signal"])
        LIBC.prctl(PR_SET_NAME, f"{NODE_NAME_PREFIX}{request['role']}".encode())
        stdout, stderr, _lock = fds
        os.dup2(stdout, 1)
        os.dup2(stderr, 2)
        os.close(stdout)
        os.close(stderr)
        os.environ.clear()
        os.environ.update(request["env"])
        os.chdir(request["cwd"])
        sys.argv = request["argv"]
        importlib.import_module(f"ato_nodes.nodes.{request['role']}").main()
        status = 0
    except SystemExit as exc:
        status = exc.code if isinstance(exc.code, int) else (exc.code is not None)
        if isinstance(exc.code, str):
            print(exc.code, file=sys.stderr)
    except BaseException:  # what an uncaught exception does to a fresh process
        traceback.print_exc()
    finally:
        atexit._run_exitfuncs()  # as a fresh process's interpreter would at exit
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(status)


def _reap(children: dict[int, dict]) -> list[tuple[int, dict, int]]:
    """The children that have ended, removed from `children`: (pid, request, status)."""
    ended = []
    for pid in list(children):
        done, wait_status = os.waitpid(pid, os.WNOHANG)
        if done:
            ended.append((pid, children.pop(pid), _exit_status(wait_status)))
    return ended


def _outlive_launcher(children: dict[int, dict], wake_read: int) -> None:
    """The launcher died without stopping its nodes (SIGKILL, a crash): stop them as it
    would have, SIGKILL any that did not go within STOP_GRACE (a hung node is deaf
    to its death signal), and repair a bag whose recorder had to be killed, so that no
    node outlives the launcher by more than that and the bag opens."""
    for pid, request in children.items():
        os.kill(pid, request["death_signal"])
    deadline = time.monotonic() + STOP_GRACE
    killed = False
    unclosed = []
    while True:
        for _pid, request, status in _reap(children):
            if request.get("bag") and status != 0:
                unclosed.append(request["bag"])
        if not children:
            break
        left = deadline - time.monotonic()
        if left <= 0 and not killed:
            for pid in children:
                os.kill(pid, signal.SIGKILL)
            killed = True
        if select.select([wake_read], [], [], None if killed else max(left, 0.0))[0]:
            os.read(wake_read, 4096)  # a SIGCHLD
    for bag in unclosed:
        from ato_nodes.bags.bagrepair import RepairError, needs_repair, repair
        try:
            if needs_repair(Path(bag)):
                print(f"launcher gone, recorder stopped: {repair(Path(bag)).describe()}",
                      file=sys.stderr)
        except (RepairError, OSError) as exc:
            print(f"launcher gone, recorder stopped; bag {bag} not repaired: {exc}",
                  file=sys.stderr)


def serve(connection: socket.socket) -> None:
    """Fork a node per request until the launcher closes its end; report each node's
    end as soon as SIGCHLD tells of it."""
    signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)  # inherited by every node
    wake_read, wake_write = os.pipe()
    os.set_blocking(wake_write, False)
    signal.signal(signal.SIGCHLD, lambda signum, frame: None)  # the wakeup fd does the work
    signal.set_wakeup_fd(wake_write)
    children: dict[int, dict] = {}  # pid: its request
    try:
        while True:
            readable, _, _ = select.select([connection, wake_read], [], [])
            if wake_read in readable:
                os.read(wake_read, 4096)
            if connection in readable:
                message, fds, _, _ = socket.recv_fds(connection, MESSAGE_SIZE, 3)
                if not message:
                    break
                request = json.loads(message)
                pid = os.fork()
                if pid == 0:
                    signal.set_wakeup_fd(-1)
                    signal.signal(signal.SIGCHLD, signal.SIG_DFL)
                    os.close(wake_read)
                    os.close(wake_write)
                    _become_node(connection, request, fds)
                for fd in fds:
                    os.close(fd)
                children[pid] = request
                connection.send(json.dumps({"pid": pid}).encode())
            for pid, _request, status in _reap(children):
                connection.send(json.dumps({"exited": pid, "status": status}).encode())
    except OSError:  # reset or broken: the launcher died with messages in flight
        pass
    _outlive_launcher(children, wake_read)


# Interfaces every node's rclpy.Node uses besides the topic map's: its parameter
# services and events, /rosout, /clock, the type description service.
NODE_INTERFACES = (
    "std_msgs/msg/String", "rcl_interfaces/msg/ParameterEvent", "rcl_interfaces/msg/Log",
    "rosgraph_msgs/msg/Clock", *(f"rcl_interfaces/srv/{name}" for name in (
        "DescribeParameters", "GetParameters", "GetParameterTypes", "ListParameters",
        "SetParameters", "SetParametersAtomically")),
    "type_description_interfaces/srv/GetTypeDescription")


def warm_up() -> None:
    """Before any fork: import the node modules and what a node otherwise loads on
    its first steps (the parsed topic map, every message and service type support,
    numpy.random), so that no forked node pays for it."""
    import numpy.random  # noqa: F401  (the plant's sensor noise)
    from rclpy.type_support import check_for_type_support
    from ato_nodes.core.base.topics import topic_map
    for role in NODES:
        try:
            importlib.import_module(f"ato_nodes.nodes.{role}")
        except Exception:  # the forked node imports it again and fails as a node would
            pass
    for name in {topic.type for topic in topic_map().values()} | set(NODE_INTERFACES):
        package, kind, type_name = name.split("/")
        check_for_type_support(getattr(importlib.import_module(f"{package}.{kind}"),
                                       type_name))


def main() -> None:
    warm_up()
    serve(socket.socket(fileno=int(sys.argv[1])))


# Launcher side -------------------------------------------------------------
NODE_START = "ATO_NODE_START"  # =subprocess: every node started by start_plain()


def plain_start_requested() -> bool:
    return os.environ.get(NODE_START) == "subprocess"


def start_plain(role: str, argv: list[str], env: dict[str, str], cwd: Path,
                death_signal: int, output: tuple[int, int], lock_fd: int,
                notify: threading.Event) -> subprocess.Popen:
    """A node started as `python -m ato_nodes.nodes.ROLE ARGV...` (argv as the fork
    server takes it: module name first), made what a forked node makes itself: own
    session, SIGINT and SIGTERM held until the node's handlers are in (run_node), the
    death signal, the lock descriptor kept. `notify` is set when it ends."""
    def in_the_child() -> None:  # after fork, before exec; survives the exec
        signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
        LIBC.prctl(PR_SET_PDEATHSIG, int(death_signal))

    # PR_SET_PDEATHSIG fires when the thread that started the node ends: the Stack's
    # thread, which waits for its nodes before it ends.
    process = subprocess.Popen(  # preexec_fn takes no lock (safe with threads running)
        [sys.executable, "-m", *argv], env=env, cwd=cwd, stdin=subprocess.DEVNULL,
        stdout=output[0], stderr=output[1], pass_fds=(lock_fd,), start_new_session=True,
        preexec_fn=in_the_child)

    def watch() -> None:
        process.wait()
        notify.set()

    threading.Thread(target=watch, name=f"node-{role}", daemon=True).start()
    return process


class NodeStartError(RuntimeError):
    """The fork server could not start a node (it died: see its stderr)."""


class ForkedNode:
    """A node process forked by the server, with the part of subprocess.Popen's
    interface the launcher uses (pid, poll, wait, send_signal)."""

    def __init__(self, pid: int, notify: threading.Event):
        self.pid = pid
        self.returncode: int | None = None
        self._ended = threading.Event()
        self._notify = notify  # set too when this node ends (a launcher watching several)

    def _exited(self, status: int) -> None:
        self.returncode = status
        self._ended.set()
        self._notify.set()

    def poll(self) -> int | None:
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        if not self._ended.wait(timeout):
            raise subprocess.TimeoutExpired(f"node process {self.pid}", timeout)
        return self.returncode

    def send_signal(self, signum: int) -> None:
        """Signal the node unless it has ended (reaped, its end not yet heard: gone)."""
        if self.returncode is None:
            try:
                os.kill(self.pid, signum)
            except ProcessLookupError:
                pass


class ForkServer:
    """The launcher process's connection to its fork server (one per process, shared
    by every run of every thread: see `fork_server()`)."""

    def __init__(self, env: dict[str, str], cwd: Path):
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        self.process = subprocess.Popen(
            [sys.executable, "-m", "ato_nodes.launcher.nodefork", str(theirs.fileno())], env=env,
            cwd=cwd, stdin=subprocess.DEVNULL, pass_fds=(theirs.fileno(),),
            start_new_session=True)  # a Ctrl-C at the terminal is the launcher's to pass on
        theirs.close()
        self.connection = ours
        self.requests = threading.Lock()  # one request at a time: replies come in order
        self.replies: list[int] = []
        self.replied = threading.Condition()
        self.nodes: dict[int, ForkedNode] = {}
        self.early_exits: dict[int, int] = {}  # exited before its pid reply was handled
        self.alive = True
        threading.Thread(target=self._read, name="fork-server", daemon=True).start()

    def _read(self) -> None:
        while True:
            try:
                message = self.connection.recv(MESSAGE_SIZE)
            except OSError:  # reset by a server that died
                message = b""
            with self.replied:
                if not message:  # the server died: its nodes went with it
                    self.alive = False
                    for node in self.nodes.values():
                        if node.returncode is None:
                            node._exited(-signal.SIGKILL)
                    self.replied.notify_all()
                    return
                reply = json.loads(message)
                if "pid" in reply:
                    self.replies.append(reply["pid"])
                    self.replied.notify_all()
                elif reply["exited"] in self.nodes:
                    self.nodes.pop(reply["exited"])._exited(reply["status"])
                else:
                    self.early_exits[reply["exited"]] = reply["status"]

    def fork(self, role: str, argv: list[str], env: dict[str, str], cwd: Path,
             death_signal: int, output: tuple[int, int], lock_fd: int,
             notify: threading.Event, bag: Path | None = None) -> ForkedNode:
        """Start a node; `bag` is the recorder's, repaired by the server if it has to
        kill the recorder after the launcher died."""
        request = json.dumps({"role": role, "argv": argv, "env": env, "cwd": str(cwd),
                              "death_signal": int(death_signal),
                              "bag": str(bag) if bag else None}).encode()
        with self.requests:
            try:
                socket.send_fds(self.connection, [request], [*output, lock_fd])
            except OSError:  # the server has gone; the reply wait below says so
                pass
            with self.replied:
                self.replied.wait_for(lambda: self.replies or not self.alive)
                if not self.alive:
                    raise NodeStartError("the node fork server (python -m "
                                         "ato_nodes.launcher.nodefork) ended with status "
                                         f"{self.process.wait()}")
                node = ForkedNode(self.replies.pop(0), notify)
                self.nodes[node.pid] = node
                if node.pid in self.early_exits:
                    self.nodes.pop(node.pid)._exited(self.early_exits.pop(node.pid))
        return node


_server: ForkServer | None = None
_server_lock = threading.Lock()


def fork_server(env: dict[str, str], cwd: Path) -> ForkServer:
    """This process's fork server, started at the first call (again if it died)."""
    global _server
    with _server_lock:
        if _server is None or not _server.alive:
            _server = ForkServer(env, cwd)
        return _server


if __name__ == "__main__":
    main()
