"""Check a controller node of your own against the contract of the node it stands in for
(docs/external-nodes.md): the node alone, started twice against a small harness (a
clock, target horizons and measured speeds), one verdict line per rule; exit status 0
if every rule is kept, 2 if any is broken.

    ato-check-node controller -- python my_controller.py
    ato-check-node controller --set controller.kind=smc -- python examples/smc-node/smc_node.py

The node gets the ROS arguments run_stack.py --external gives it, with the parameter
file of the scenario (--scenario, --set). The first run sends each horizon two steps
ahead of its measured speed, as the profile does; the second sends it just after: a node
that pairs step k's inputs by count gives the same commands in both.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import rclpy
import yaml
from builtin_interfaces.msg import Time
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64, Float64MultiArray, String

from ato_nodes import cli
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.base.topics import topic_map
from ato_nodes.core.config.scenario import check_launcher_free, prepare, ros_parameter_file
from ato_nodes.core.config.schema import for_node
from ato_nodes.launcher.nodefork import STOP_GRACE
from ato_nodes.nodes.base import QOS, message_class

ROLE = "controller"
STEPS = 40
READY_TIMEOUT = 30.0  # s of wall time for the node to announce itself
STEP_TIMEOUT = 5.0    # s for one step's command
QUIET = 0.5           # s after the last step in which no further command may come
RULES = ("parameters announced", "ready announced", "/clock used",
         "a command per step, paired correctly", "outputs named", "shuts down on request")


def parse_args() -> argparse.Namespace:
    from ato_nodes.launcher.launch import split_command  # its command after --
    ours, command = split_command(sys.argv[1:])
    parser = cli.argument_parser(__doc__)
    parser.add_argument("role", help="the node it stands in for: controller")
    parser.add_argument("--scenario", default="seed000",
                        help="the scenario whose parameter file the node gets (default seed000)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="override a parameter of that file (repeatable)")
    args = parser.parse_args(ours)
    args.command = command
    return args


def checked(args: argparse.Namespace) -> dict:
    """The run's values; the role and the command checked (one line, exit 2)."""
    if args.role != ROLE:
        cli.fail(f"{args.role}: only a {ROLE} node is checked")
    if not args.command:
        cli.fail("give the node's command after --")
    if shutil.which(args.command[0]) is None:
        cli.fail(f"command {args.command[0]} not found")
    try:
        period = prepare(args.scenario, args.set)["run.period"]
        values = prepare(args.scenario, [*args.set, f"run.duration={STEPS * period!r}"])
        check_launcher_free(values)
    except ScenarioError as exc:
        cli.fail(str(exc))
    return values


@dataclass
class Session:
    """What the harness saw of one start of the node."""

    parameters: list[str] = field(default_factory=list)  # the JSON it announced
    ready: bool = False
    ready_before_parameters: bool = False
    clock_subscribed: bool = False
    commands: list[float] = field(default_factory=list)
    labels: list[str] = field(default_factory=list)
    sizes: list[tuple[int, int]] = field(default_factory=list)  # (names, values) per message
    missing_step: int | None = None  # the step whose command never came
    exit_status: int | None = None  # after 'shutdown'; None: still running


def main() -> None:
    cli.interrupted_quietly(check_node)


def check_node() -> None:
    args = parse_args()
    values = checked(args)
    from ato_nodes.launcher.launch import DomainLock, isolate_to_this_host
    lock = DomainLock()
    isolate_to_this_host(os.environ)  # the harness discovers as the run's nodes do
    folder = Path(tempfile.mkdtemp(prefix="ato-check-node-"))
    try:
        params = folder / "params.yaml"
        params.write_text(yaml.safe_dump(ros_parameter_file(values), sort_keys=False))
        sessions = [Harness(values, lock, True).check(args.command, params)]
        if sessions[0].ready:  # started again: its horizons come just in time
            sessions.append(Harness(values, lock, False).check(args.command, params))
    finally:
        shutil.rmtree(folder, ignore_errors=True)
        lock.release()
    broken = 0
    for rule, problem in zip(RULES, verdicts(sessions, values), strict=True):
        print(f"{'broken' if problem else 'kept':6}  {rule}{': ' + problem if problem else ''}")
        broken += bool(problem)
    sys.exit(2 if broken else 0)


def verdicts(sessions: list[Session], values: dict) -> list[str]:
    """Per rule, what broke it ("" kept)."""
    first, second = sessions[0], sessions[-1]
    return [parameters_verdict(first, values), ready_verdict(first),
            clock_verdict(first),
            steps_verdict(first, second), outputs_verdict(first),
            shutdown_verdict(first)]


def parameters_verdict(session: Session, values: dict) -> str:
    if not session.parameters:
        return f"no 'parameters {ROLE} {{JSON}}' on the run events"
    try:
        announced = json.loads(session.parameters[0])
    except ValueError as exc:
        return f"not JSON: {exc}"
    if not isinstance(announced, dict):
        return f"a JSON {type(announced).__name__}, not an object"
    if session.ready_before_parameters:
        return "announced after 'ready'"
    differ = [name for name, value in announced.items()
              if name in values and value != values[name]]
    return f"{differ[0]} is {announced[differ[0]]!r}, the run's {values[differ[0]]!r}" \
        if differ else ""


def ready_verdict(session: Session) -> str:
    return "" if session.ready else f"no 'ready {ROLE}' within {READY_TIMEOUT:g} s"


def clock_verdict(session: Session) -> str:
    if not session.ready:
        return "not checked (never ready)"
    return "" if session.clock_subscribed else "no subscription of /clock (use_sim_time)"


def steps_verdict(first: Session, second: Session) -> str:
    for session in (first, second):
        if not session.ready:
            return "not checked (never ready)"
        if session.missing_step is not None:
            return f"no command for step {session.missing_step} within {STEP_TIMEOUT:g} s"
        if len(session.commands) != STEPS:
            return f"{len(session.commands)} commands for {STEPS} steps"
        if not all(math.isfinite(u) for u in session.commands):
            return "a command that is not finite"
    if first.commands != second.commands:
        step = next(k for k, (a, b) in enumerate(zip(first.commands, second.commands,
                                                      strict=True)) if a != b)
        return (f"step {step}'s command depends on when its horizon came "
                f"({first.commands[step]!r} with it two steps ahead, {second.commands[step]!r} "
                "just after y_k): pair the k-th measured speed with the k-th horizon")
    return ""


def outputs_verdict(session: Session) -> str:
    if not session.ready:
        return "not checked (never ready)"
    if len(session.labels) != len(session.commands):
        return f"{len(session.labels)} /ato/controller_state messages for " \
               f"{len(session.commands)} commands"
    for label, (names, count) in zip(session.labels, session.sizes, strict=True):
        if names != count:
            return f"{count} values under {names} names (layout.dim[0].label {label!r})"
        if label != session.labels[0]:
            return f"the names changed from {session.labels[0]!r} to {label!r}"
    return ""


def shutdown_verdict(session: Session) -> str:
    if not session.ready:
        return "not checked (never ready)"
    if session.exit_status is None:
        return "still running 5 s after 'shutdown' (killed)"
    return "" if session.exit_status == 0 else f"exit status {session.exit_status}"


def horizon(values: dict, k: int) -> list[float]:
    """The harness's horizon of step k: a ramp, so that each step's differs."""
    return [12.0 + 0.25 * j for j in range(k, k + values["controller.preview"] + 1)]


def measured(k: int) -> float:
    """The harness's measured speed y_k (open loop: the commands change nothing)."""
    return 10.0 + math.sin(0.3 * k)


class Harness:
    """The node's neighbours in one start of it: the plant's clock and measured speed,
    the profile's horizons, the supervisor's run events, the recorder's subscriptions."""

    def __init__(self, values: dict, lock, ahead: bool):
        """`lock` the DomainLock of the harness's domain (the node keeps it open)."""
        self.values, self.lock, self.ahead = values, lock, ahead
        self.session = Session()

    def check(self, command: list[str], params: Path) -> Session:
        """Start the node, run the steps, tell it to shut down; what was seen."""
        from ato_nodes.launcher.launch import external_arguments, node_environment, start_external
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=self.lock.domain_id)
        self.node = Node("ato_check_node", context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self._edges()
        ended = threading.Event()
        process = start_external(ROLE, [*command, *external_arguments(ROLE, params)],
                                 node_environment(self.lock.domain_id), (2, 2),
                                 self.lock.fileno(), ended)
        try:
            self.spin_until(lambda: self.session.ready or ended.is_set(), READY_TIMEOUT)
            if self.session.ready:
                # the node's readers matched our writers too (discovery goes each way
                # apart): a step sent before would be lost, the node starved of inputs
                self.spin_until(self.inputs_matched, READY_TIMEOUT)
                self.session.clock_subscribed = self.clock.get_subscription_count() > 0
                self.run_steps()
                self.announce("shutdown")
            self.session.exit_status = stop(process, STOP_GRACE)
        finally:
            stop(process, 0.0)
            self.node.destroy_node()
            rclpy.shutdown(context=context)
        return self.session

    def _edges(self) -> None:
        topics, node = topic_map(), self.node
        def publisher(key):
            topic = topics[key]
            return node.create_publisher(message_class(topic.type), topic.name, QOS[topic.qos])
        def subscriptions(key, callback):  # one per subscriber the topic map lists
            topic = topics[key]
            for index in range(len(topic.subscribers)):
                node.create_subscription(message_class(topic.type), topic.name,
                                         callback if index == 0 else lambda msg: None,
                                         QOS[topic.qos])
        self.clock, self.speeds = publisher("clock"), publisher("measured_speed")
        self.horizons, self.events = publisher("target_preview"), publisher("events")
        subscriptions("command", lambda msg: self.session.commands.append(msg.data))
        subscriptions("controller_state", self.on_outputs)
        subscriptions("parameter_changes", lambda msg: None)
        node.create_subscription(String, topics["events"].name, self.on_event,
                                 QOS["events"])

    def inputs_matched(self) -> bool:
        """Whether the node subscribes the measured speed and the horizons we send."""
        return self.speeds.get_subscription_count() > 0 and \
            self.horizons.get_subscription_count() > 0

    def on_outputs(self, msg) -> None:
        label = msg.layout.dim[0].label if msg.layout.dim else ""
        self.session.labels.append(label)
        self.session.sizes.append((len(label.split(",")) if label else 0, len(msg.data)))

    def on_event(self, msg) -> None:
        word, _, argument = msg.data.partition(" ")
        node, _, rest = argument.partition(" ")
        if word == "parameters" and node == ROLE:
            self.session.parameters.append(rest)
            self.session.ready_before_parameters = self.session.ready
        elif word == "ready" and node == ROLE:
            self.session.ready = True

    def announce(self, text: str) -> None:
        self.events.publish(String(data=text))

    def spin_until(self, condition, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while not condition():
            left = deadline - time.monotonic()
            if left <= 0:
                return False
            self.executor.spin_once(timeout_sec=min(left, 0.05))
        return True

    def run_steps(self) -> None:
        """Step k: /clock t_k, y_k and the horizon of step k (two steps ahead, or just
        after y_k); then its command."""
        self.announce("start")
        period, send = self.values["run.period"], self.send_horizon
        if self.ahead:
            for k in range(min(3, STEPS)):
                send(k)
        for k in range(STEPS):
            if self.ahead and 0 < k and k + 2 < STEPS:
                send(k + 2)
            seconds, nanoseconds = divmod(round(k * period * 1e9), 10**9)
            self.clock.publish(Clock(clock=Time(sec=seconds, nanosec=nanoseconds)))
            self.speeds.publish(Float64(data=measured(k)))
            if not self.ahead:
                send(k)
            if not self.spin_until(lambda step=k: len(self.session.commands) > step,
                                   STEP_TIMEOUT):
                self.session.missing_step = k
                return
        self.announce(f"finished {STEPS}")
        self.spin_until(lambda: False, QUIET)  # a command too many comes now, or never

    def send_horizon(self, k: int) -> None:
        self.horizons.publish(Float64MultiArray(data=horizon(self.values, k)))


def declared_parameters(command: list[str], values: dict) -> dict[str, tuple[float, float, float]]:
    """The parameters an external controller node declares of its own, live, with a
    FloatingPointRange: {name: (low, high, value)}, asked of the node (started alone with
    the run's parameter file, then stopped) through its parameter services. A node that
    does not answer within READY_TIMEOUT is a ScenarioError."""
    from rclpy.parameter import parameter_value_to_python
    from rclpy.parameter_client import AsyncParameterClient
    from ato_nodes.launcher.launch import (DomainLock, external_arguments, node_environment,
                                           start_external)
    lock = DomainLock()
    folder = Path(tempfile.mkdtemp(prefix="ato-node-parameters-"))
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=lock.domain_id)
    process = None
    try:
        params = folder / "params.yaml"
        params.write_text(yaml.safe_dump(ros_parameter_file(values), sort_keys=False))
        process = start_external(ROLE, [*command, *external_arguments(ROLE, params)],
                                 node_environment(lock.domain_id), (2, 2), lock.fileno(),
                                 threading.Event())
        node = Node("ato_node_parameters", context=context)
        client = AsyncParameterClient(node, f"/{ROLE}")
        if not client.wait_for_services(timeout_sec=READY_TIMEOUT):
            raise ScenarioError(f"the external {ROLE} ({command[0]}) did not answer for its "
                                f"parameters within {READY_TIMEOUT:g} s")
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        def ask(future):
            executor.spin_until_future_complete(future, timeout_sec=READY_TIMEOUT)
            return future.result()
        # the node's own: not what the run's controller declares (a plug-in's parameters
        # of a kind the run does not use are the node's to tune)
        run = {spec.name for spec in for_node(ROLE, values)}
        names = [name for name in ask(client.list_parameters()).result.names
                 if name not in run and name != "use_sim_time"]
        described = ask(client.describe_parameters(names)).descriptors
        current = ask(client.get_parameters(names)).values
        return {d.name: (d.floating_point_range[0].from_value, d.floating_point_range[0].to_value,
                         float(parameter_value_to_python(value)))
                for d, value in zip(described, current, strict=True)
                if d.floating_point_range and not d.read_only}
    finally:
        if process is not None:
            stop(process, 0.0)
        rclpy.shutdown(context=context)
        shutil.rmtree(folder, ignore_errors=True)
        lock.release()


def stop(process, grace: float) -> int | None:
    """The node's exit status if it exits within `grace` s; else its group stopped as the
    launcher stops it (SIGINT, SIGTERM, SIGKILL) and None. Nothing of it is left."""
    try:
        return process.wait(grace)
    except subprocess.TimeoutExpired:
        pass
    for number in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
        process.send_signal(number)
        try:
            process.wait(grace)
            break
        except subprocess.TimeoutExpired:
            continue
    process.signal_group(signal.SIGKILL)
    return None


if __name__ == "__main__":
    main()
