"""What every ATO node shares: parameters from the schema, the topic map's QoS,
the readiness gate and the run-event protocol, and a clean life cycle."""

from __future__ import annotations

import faulthandler
import importlib
import importlib.metadata
import json
import os
import resource
import signal
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Callable

import rclpy
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, Log, ParameterDescriptor
from rclpy.callback_groups import CallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor, TimeoutException
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy._rclpy_pybind11 import RCLError
from std_msgs.msg import String

from ato_nodes.core.base import yamlfile
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.faults import parse_fault
from ato_nodes.core.config.scenario import complete, parameter_spec
from ato_nodes.core.config.schema import (SPEC_BY_NAME, NodeValues, ParamSpec, for_node,
                                          load_plugins)
from ato_nodes.core.run.scoring import LINE_BASE64, encode_line, kept_files
from ato_nodes.core.base.topics import Topic, topic_map
from ato_nodes.nodes import watchdog
from ato_nodes.nodes.watchdog import TEARDOWN_LIMIT
from ato_nodes.nodes.timing import install as install_timing

QOS = {
    "data": QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE),
    "clock": QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.VOLATILE),
    "events": QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL),
}
# rcl's own /rosout profile (rcl_qos_profile_rosout_default), which `ros2 topic echo`
# and rqt_console expect of a /rosout publisher
ROSOUT_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                        reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL,
                        lifespan=Duration(seconds=10))
READINESS_POLL = 0.01  # s of wall time between checks of the graph
INTRUDER_POLL = 0.5    # s of wall time between checks for foreign publishers during a run
# The lockstep data path bypasses the executor (see spin_lockstep); everything
# else (/clock for the node's sim time, timers, parameter services) is served by the
# standard executor at least this often, s of wall time: until the run starts (the
# readiness gate polls the graph from a timer), then at the longer period (a pass
# costs 0.4-0.6 ms of CPU, rclpy building a wait set of all the node's entities:
# every 20 ms in five nodes, about an eighth of a core taken from the loop).
HOUSEKEEPING_PERIOD = 0.02
RUNNING_HOUSEKEEPING_PERIOD = 0.1
HOUSEKEEPING_CALLBACKS = 16
FLUSH_TIMEOUT = 2.0  # s a stopping node waits for its subscribers to acknowledge its data
# Run events logged (INFO, /rosout): each node logs the start it hears and its own
# shutdown; the end of the run once, by the node that announces it (the plant's
# 'finished', the recorder's 'recorded'): a node hears events of different nodes in no
# fixed order, so another might not have heard it before the shutdown, and the fewer
# records come at once at the end, the fewer a keep-last-10 `ros2 topic echo` drops.
# During the run, a journey's re-plans by the profile that makes them ('replanned ...').
HEARD_EVENTS = ("start",)
ANNOUNCED_EVENTS = ("finished", "recorded", "replanned")
# What rclpy.node.Node declares itself (start_type_description_service read-only already)
RCLPY_PARAMETERS = ("use_sim_time", "start_type_description_service")
# The lockstep fast path's private rclpy calls (SubscriptionWaitSet) were written and
# tested against this release of this distribution; with any other the standard executor
# serves the per-step inputs instead (slower, the same callbacks in the same order).
FAST_PATH_RCLPY = ("ros-jazzy-rclpy", "7.1.6")
STANDARD_EXECUTOR = "ATO_STANDARD_EXECUTOR"  # =1 in a node's environment: force that


class DeliveredLogger:
    """The node's logger, whose /rosout records reach their subscribers before the node
    exits. rcl's own /rosout writer (off for these nodes) dies with the node's context,
    taking the last records with it (a `ros2 topic echo /rosout` missed a run's
    end-of-run lines); this one is the node's, so flush() can wait for them to be
    acknowledged. Records are what rcl writes: system-time stamp, level, logger name,
    text and the caller's file, function and line; the console output (unless
    --disable-stdout-logs) and the log file are rcl's as usual."""

    def __init__(self, node: Node):
        self._logger = node.get_logger()
        self._rosout = node.create_publisher(Log, "/rosout", ROSOUT_QOS)

    def info(self, text: str) -> None:
        # one call site per severity: rclpy refuses a call site whose severity changes
        if self._logger.info(text):
            self._publish(Log.INFO, text)

    def warning(self, text: str) -> None:
        if self._logger.warning(text):
            self._publish(Log.WARN, text)

    def error(self, text: str) -> None:
        if self._logger.error(text):
            self._publish(Log.ERROR, text)

    def _publish(self, level: int, text: str) -> None:
        caller = sys._getframe(2)
        now = time.time_ns()
        record = Log(level=level, name=self._logger.name, msg=text,
                     file=caller.f_code.co_filename, function=caller.f_code.co_name,
                     line=caller.f_lineno)
        record.stamp.sec, record.stamp.nanosec = divmod(now, 10**9)
        self._rosout.publish(record)

    def flush(self) -> None:
        """Wait (FLUSH_TIMEOUT at most) until every record reached every subscriber."""
        self._rosout.wait_for_all_acked(Duration(seconds=FLUSH_TIMEOUT))


def parameter_files() -> list[Path]:
    """The --params-file arguments this process was given."""
    argv = sys.argv
    return [Path(argv[i + 1]).resolve() for i, arg in enumerate(argv[:-1])
            if arg == "--params-file"]


def parameter_file_folders() -> list[Path]:
    """Their folders (relative file parameters in a scenario are relative to the
    scenario's folder)."""
    return [path.parent for path in parameter_files()]


def message_class(type_name: str) -> type:
    package, _, name = type_name.split("/")
    return getattr(importlib.import_module(f"{package}.msg"), name)


def _descriptor(spec: ParamSpec, live: bool) -> ParameterDescriptor:
    # read-only unless live: a run's values are fixed when it starts (the stages are built
    # from them), so `ros2 param set` is refused with the standard message, not ignored
    descriptor = ParameterDescriptor(name=spec.name, description=spec.description,
                                     read_only=not live)
    if spec.low is not None and spec.value_type is float:
        descriptor.floating_point_range = [FloatingPointRange(
            from_value=float(spec.low), to_value=float(spec.high))]
    elif spec.low is not None and spec.value_type is int:
        descriptor.integer_range = [IntegerRange(
            from_value=int(spec.low), to_value=int(spec.high), step=1)]
    if spec.choices:
        descriptor.additional_constraints = "one of: " + ", ".join(spec.choices)
    return descriptor


class AtoNode(Node):
    """Base of the five nodes. Subclasses call `ready_when_matched()` once their
    publishers and subscriptions exist, and override `on_event()`."""

    role: str = ""
    exit_status = 0  # set by a node that ends the run for a reason of its own
    stop_requested = False  # SIGINT or SIGTERM: leave the spin loop, then on_stop()
    run_started = False  # the run's 'start' heard

    def __init__(self, use_sim_time: bool = True):
        super().__init__(self.role, enable_rosout=False)  # self.log publishes /rosout
        self.log = DeliveredLogger(self)
        self._shut_down = False
        self.values = self._declare_parameters(use_sim_time)
        self.topics = topic_map()
        self._outgoing: list[tuple[Any, Topic]] = []
        self._incoming: list[tuple[Any, Topic]] = []
        self.lockstep_inputs: list[tuple[Any, Callable, Callable[[], bool] | None]] = []
        self.fast_path_unavailable = SubscriptionWaitSet.unavailable()  # why, or ""
        # what the lockstep wait set serves, the executor leaves alone (LockstepGroup)
        self.lockstep_group = None if self.fast_path_unavailable else LockstepGroup()
        events = self.topics["events"]
        self.events_out = self.create_publisher(String, events.name, QOS["events"])
        self.events_in = self.create_subscription(String, events.name, self._on_event_message,
                                                  QOS["events"],
                                                  callback_group=self.lockstep_group)
        # on the fast path too: a run's start and end wait on few events, each of which
        # would otherwise wait up to HOUSEKEEPING_PERIOD for the executor
        self.lockstep_inputs.append((self.events_in, self._on_event_message, None))
        self._ready_timer = None
        self._wall_clock = Clock(clock_type=ClockType.STEADY_TIME)
        fault = parse_fault(self.values["run.fault"])
        self._fault = fault[1:] if fault and fault[0] == self.role else None
        self.announce_parameters()

    # Parameters -----------------------------------------------------------
    def _declare_parameters(self, use_sim_time: bool) -> NodeValues:
        """Declare the parameters this node uses in this run (none of the controller or
        profile kinds it does not run), then complete them as a scenario is completed
        (core.scenario.complete): a train preset fills the plant.* values not given, and
        relative file paths resolve from the parameter file's folder, else msg_config/; a
        given parameter of a kind the run does not use is refused. So a node started from
        a scenario file by any launcher runs the same train; the completed values are set
        back, so `ros2 param get` shows what the node uses. rclpy's own use_sim_time is
        set to what the node needs and, like every other, fixed for the run."""
        overrides = self._parameter_overrides
        where = ", ".join(str(path) for path in parameter_files()) or "--ros-args"
        # first, the run's plug-ins (and the installed ones): their kinds' parameters are
        # then the schema's
        named = overrides.get("run.plugins")
        load_plugins(SPEC_BY_NAME["run.plugins"].check(named.value, where) if named else "")
        for name in sorted(set(overrides) - set(SPEC_BY_NAME) - set(RCLPY_PARAMETERS)):
            parameter_spec(name, overrides[name].value, where)  # refused as a scenario's
        given = {spec.name: spec.check(overrides[spec.name].value, self.role)
                 for spec in for_node(self.role) if spec.name in overrides}
        # an unknown train or a bad train file: one line, exit 2 (scenario.complete)
        values = NodeValues(self.role, complete(given, [*parameter_file_folders(), Path.cwd()]))
        live = self.live_parameters(values)
        for spec in for_node(self.role, values):  # declared with what the node runs with
            self.declare_parameter(spec.name, values[spec.name],
                                   _descriptor(spec, spec.name in live), ignore_override=True)
        self.set_parameters([Parameter("use_sim_time", Parameter.Type.BOOL, use_sim_time)])
        self.set_descriptor("use_sim_time", ParameterDescriptor(
            type=Parameter.Type.BOOL.value, read_only=True,
            description="follow /clock (the plant's simulated time), fixed for the run"))
        return values

    def live_parameters(self, values: NodeValues) -> tuple[str, ...]:
        """The parameters `ros2 param set` may change during the run (none: read-only)."""
        return ()

    def announce_parameters(self) -> None:
        """Tell the run which values this node runs with: the supervisor checks that the
        shared ones agree across nodes, the recorder keeps them in the bag (with the
        line's text, so the bag scores anywhere)."""
        values = dict(self.values)
        if values.get("line.file"):
            values[LINE_BASE64] = encode_line(Path(values["line.file"]).read_text())
        values.update(kept_files(values))
        self.announce(f"parameters {self.role} {json.dumps(values)}")

    # Topics ---------------------------------------------------------------
    def publisher(self, key: str):
        topic = self.topics[key]
        pub = self.create_publisher(message_class(topic.type), topic.name, QOS[topic.qos])
        self._outgoing.append((pub, topic))
        return pub

    def subscription(self, key: str, callback: Callable, raw: bool = False,
                     wakes: Callable[[], bool] | None = None):
        """A per-step input: served on the lockstep fast path. With `wakes`, the node
        waits for this input only while wakes() is true; otherwise its messages are
        taken whenever the node wakes for another input (or its housekeeping), each
        topic's in arrival order as always."""
        topic = self.topics[key]
        sub = self.create_subscription(message_class(topic.type), topic.name, callback,
                                       QOS[topic.qos], raw=raw,
                                       callback_group=self.lockstep_group)
        self._incoming.append((sub, topic))
        self.lockstep_inputs.append((sub, callback, wakes))
        return sub

    # Readiness gate -------------------------------------------------------
    def ready_when_matched(self) -> None:
        """Announce 'ready' once every edge of this node is matched (wall-clock poll:
        sim-time timers do not fire before the first /clock)."""
        self._ready_timer = self.create_timer(READINESS_POLL, self._check_ready,
                                              clock=self._wall_clock)

    def unmatched_edges(self) -> list[str]:
        missing = []
        for pub, topic in self._outgoing:
            if pub.get_subscription_count() < len(topic.subscribers):
                missing.append(f"{topic.name} (subscribers)")
        for sub, topic in self._incoming:
            if sub.get_publisher_count() < 1:
                missing.append(f"{topic.name} (publisher)")
        return missing

    def intruders(self) -> list[str]:
        """Per-step inputs with more publishers than the topic map has: another process
        publishes into this run's domain (its data would mix into the run)."""
        return [f"{topic.name} has {sub.get_publisher_count()} publishers, not "
                f"{len(topic.publishers)}" for sub, topic in self._incoming
                if sub.get_publisher_count() > len(topic.publishers)]

    def _check_ready(self) -> None:
        if self._check_intruders():
            return
        if not self.unmatched_edges():
            self._ready_timer.cancel()
            self.destroy_timer(self._ready_timer)
            self.announce(f"ready {self.role}")
            self.log.info("every edge of the topic map matched: ready")
            self.create_timer(INTRUDER_POLL, self._check_intruders, clock=self._wall_clock)

    def _check_intruders(self) -> bool:
        """Stop the run (this node exits with status 1, named by the launcher) if another
        process publishes on one of its inputs."""
        found = self.intruders()
        if found and not self.stop_requested:
            self.error(f"{found[0]}: another process publishes in this run's ROS domain")
            self.exit_status = 1
            self.stop_requested = True
        return bool(found)

    def inject_fault(self, step: int) -> None:
        """run.fault: from the given step on, crash (an uncaught exception), hang (deaf
        to SIGINT and SIGTERM, so the launcher has to escalate to SIGKILL), kill (the
        process SIGKILLs itself: no clean-up of any kind) or diskfull (every further
        write to a file fails, as on a full disk)."""
        if self._fault is None or step < self._fault[1]:
            return
        kind, self._fault = self._fault[0], None if self._fault[0] == "diskfull" else self._fault
        if kind == "crash":
            raise RuntimeError(f"{self.role}: injected crash at step {step} (run.fault)")
        if kind == "kill":
            os.kill(os.getpid(), signal.SIGKILL)
        if kind == "diskfull":  # writes beyond the files' current sizes fail with EFBIG
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
            resource.setrlimit(resource.RLIMIT_FSIZE, (0, resource.getrlimit(
                resource.RLIMIT_FSIZE)[1]))
            return
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        while True:
            time.sleep(1.0)

    # Run events -----------------------------------------------------------
    def error(self, message: str) -> None:
        """A failure, as early as it is known: an ERROR record on /rosout and, when the
        node's console logs are off (the launcher's `--disable-stdout-logs`), one
        `node: error: ...` line on stderr, so a console shows it once either way."""
        self.log.error(message)
        if "--disable-stdout-logs" in sys.argv:
            print(f"{self.role}: error: {message}", file=sys.stderr, flush=True)

    def warn(self, message: str) -> None:
        """Something the run should know at start-up (it runs on): a WARN record on
        /rosout and, with the node's console logs off, one `node: warning: ...` line on
        stderr, as error() does."""
        self.log.warning(message)
        if "--disable-stdout-logs" in sys.argv:
            print(f"{self.role}: warning: {message}", file=sys.stderr, flush=True)

    def announce(self, text: str) -> None:
        if text.partition(" ")[0] in ANNOUNCED_EVENTS:
            self.log.info(f"run event: {text}")
        self.events_out.publish(String(data=text))

    def _on_event_message(self, msg: String) -> None:
        word, _, argument = msg.data.partition(" ")
        if word == "shutdown":
            self.shut_down()
            return
        if word in HEARD_EVENTS:
            self.log.info(f"run event: {word} {argument}".rstrip())
        self.run_started = self.run_started or word == "start"
        self.on_event(word, argument)

    def shut_down(self) -> None:
        """End this node's part of the run: say so, see the log records delivered, then
        shut the context down (the spin loop ends)."""
        if self._shut_down:
            return
        self._shut_down = True
        faulthandler.dump_traceback_later(TEARDOWN_LIMIT, exit=True)
        self.log.info("run event: shutdown")
        self.log.flush()
        self.context.try_shutdown()

    def on_event(self, word: str, argument: str) -> None:
        """Run events other than 'shutdown' (which every node obeys by exiting)."""

    def on_stop(self) -> None:
        """After a signal, before exit: what this node published reaches its subscribers
        (reliable, keep-all: the recorder gets every step that left this node)."""
        for publisher, _ in self._outgoing:
            publisher.wait_for_all_acked(Duration(seconds=FLUSH_TIMEOUT))

    def close(self) -> None:
        """Release what must be released before exit (the recorder closes its bag)."""


def _housekeeping(executor: SingleThreadedExecutor) -> None:
    """Run every callback the executor has ready now, without blocking."""
    for _ in range(HOUSEKEEPING_CALLBACKS):
        try:
            handler, _, _ = executor.wait_for_ready_callbacks(timeout_sec=0.0)
        except TimeoutException:
            return
        handler()
        handler.result()  # re-raise what the callback raised


def spin_lockstep(node: AtoNode, executor: SingleThreadedExecutor) -> None:
    """Spin a node of the lockstep loop.

    rclpy's Python executor costs 100-300 us of CPU per callback (it rebuilds
    its wait set every time); on two cores shared by five processes that, not
    DDS, bounds the step rate. So a wait set holding only the node's per-step
    subscriptions is waited on directly, and every message queued on a ready
    subscription is taken and handled at once (in arrival order per topic,
    as the executor would). Run events are on the fast path as well (see
    AtoNode.__init__). The executor serves everything else (/clock for the node's
    sim time, timers, parameter services) every HOUSEKEEPING_PERIOD, then every
    RUNNING_HOUSEKEEPING_PERIOD once the run has started, so /clock, published
    every step, costs no callback. Where the fast path is unavailable
    (LockstepInputs) the executor serves everything, logged once on /rosout with
    the reason.
    """
    context = node.context
    lockstep = LockstepInputs(node)
    if lockstep.fallback:
        node.log.info(f"per-step inputs served by the standard executor: {lockstep.fallback}")
    next_housekeeping = 0.0
    while context.ok() and not node.stop_requested:
        now = time.monotonic()
        if now >= next_housekeeping:
            _housekeeping(executor)
            next_housekeeping = now + (RUNNING_HOUSEKEEPING_PERIOD if node.run_started
                                       else HOUSEKEEPING_PERIOD)
            continue
        lockstep.take(next_housekeeping - now)


class LockstepGroup(CallbackGroup):
    """The callback group of the subscriptions the lockstep wait set serves (on the fast
    path): the executor neither waits on them nor runs their callbacks. Left in its view,
    it took whatever was queued on them at each housekeeping through its own slower path,
    and waited on a bigger wait set every time."""

    def can_execute(self, entity) -> bool:
        return False

    def beginning_execution(self, entity) -> bool:
        return False

    def ending_execution(self, entity) -> None:
        """Nothing to end: no execution ever begins."""


class SubscriptionWaitSet:
    """The private rclpy API of the lockstep fast path, in one place: an rcl wait set of
    subscriptions (rclpy.impl.implementation_singleton's WaitSet), waited on directly,
    and messages taken from a ready subscription's handle (take_message). Only for the
    rclpy release FAST_PATH_RCLPY names: see `unavailable()`."""

    def __init__(self, subscriptions: list, context):
        from rclpy.impl.implementation_singleton import rclpy_implementation
        self.handles = [subscription.handle for subscription in subscriptions]
        self.wait_set = rclpy_implementation.WaitSet(len(self.handles), 0, 0, 0, 0, 0,
                                                     context.handle)

    @staticmethod
    def unavailable() -> str:
        """Why the fast path cannot be used here ("" if it can): forced off by
        $ATO_STANDARD_EXECUTOR=1, another rclpy release than FAST_PATH_RCLPY, or the
        private API missing."""
        if os.environ.get(STANDARD_EXECUTOR) == "1":
            return f"{STANDARD_EXECUTOR}=1"
        distribution, tested = FAST_PATH_RCLPY
        try:
            version = importlib.metadata.version(distribution)
        except importlib.metadata.PackageNotFoundError:
            return f"{distribution} is not installed (rclpy from elsewhere)"
        if version != tested:
            return f"{distribution} {version}, not {tested} (the release the fast path is for)"
        try:
            from rclpy.impl.implementation_singleton import rclpy_implementation
        except ImportError as exc:
            return f"rclpy's implementation singleton is missing ({exc})"
        missing = [f"{kind}.{name}" for kind, names in (
            ("WaitSet", ("clear_entities", "add_subscription", "wait", "get_ready_entities")),
            ("Subscription", ("take_message",)))
            for name in names if not hasattr(getattr(rclpy_implementation, kind, None), name)]
        return f"rclpy lacks {', '.join(missing)}" if missing else ""

    def wait(self, timeout: float, waited: list[bool]) -> list[bool]:
        """Wait up to `timeout` s for the `waited` subscriptions (flags in the given
        order); which of them are ready."""
        wait_set = self.wait_set
        wait_set.clear_entities()
        for handle, wanted in zip(self.handles, waited, strict=True):
            if wanted:
                wait_set.add_subscription(handle)
        wait_set.wait(int(timeout * 1e9))
        ready = wait_set.get_ready_entities("subscription")
        return [wanted and handle.pointer in ready
                for handle, wanted in zip(self.handles, waited, strict=True)]

    def take(self, index: int, msg_type: type, raw: bool):
        """The next queued message of subscription `index`, or None."""
        taken = self.handles[index].take_message(msg_type, raw)
        return None if taken is None else taken[0]


def take_queued(subscription) -> list:
    """The messages queued on `subscription` now, taken as rclpy's executor takes them."""
    taken = []
    while (message := subscription.handle.take_message(subscription.msg_type,
                                                        subscription.raw)) is not None:
        taken.append(message[0])
    return taken


class LockstepInputs:
    """A node's per-step subscriptions and run events: wait, then take and handle every
    queued message of each ready one (in arrival order per topic), and of each not
    waited for (its `wakes` false: see AtoNode.subscription), in the node's order of
    subscriptions.

    On the fast path (SubscriptionWaitSet) the messages are taken straight from rcl.
    Where that path is unavailable (another rclpy release, or $ATO_STANDARD_EXECUTOR=1)
    the node's standard executor waits and runs the subscriptions' own callbacks (the
    same callbacks, in arrival order per topic, so the same bag; only slower)."""

    def __init__(self, node: AtoNode):
        self.subscriptions = [sub for sub, _, _ in node.lockstep_inputs]
        self.inputs = [(sub.msg_type, sub.raw, callback) for sub, callback, _ in
                       node.lockstep_inputs]
        self.wakes = [wakes for _, _, wakes in node.lockstep_inputs]
        self.fallback = node.fast_path_unavailable
        self.wait_set = None if self.fallback else SubscriptionWaitSet(self.subscriptions,
                                                                       node.context)
        self.executor = node.executor  # run_node's (the fallback's)

    def take(self, timeout: float) -> int:
        """Wait up to `timeout` s; the number of messages handled."""
        if self.wait_set is None:
            return self._take_through_executor(timeout)
        handled = 0
        waited = [wakes is None or wakes() for wakes in self.wakes]
        for index, ready in enumerate(self.wait_set.wait(timeout, waited)):
            if waited[index] and not ready:
                continue
            msg_type, raw, callback = self.inputs[index]
            message = self.wait_set.take(index, msg_type, raw)
            while message is not None:
                callback(message)
                handled += 1
                message = self.wait_set.take(index, msg_type, raw)
        return handled

    def _take_through_executor(self, timeout: float) -> int:
        """The fallback: one ready callback of the node run by its executor (whatever it
        is: the executor serves the node's timers and services too); 1 if it handled a
        per-step input."""
        try:
            handler, entity, _ = self.executor.wait_for_ready_callbacks(timeout_sec=timeout)
        except TimeoutException:
            return 0
        handler()
        handler.result()  # re-raise what the callback raised
        return int(any(entity is subscription for subscription in self.subscriptions))

    def drain(self, quiet: float, limit: float) -> None:
        """Handle what still arrives until nothing has for `quiet` s (`limit` s at most)."""
        deadline = time.monotonic() + limit
        last = time.monotonic()
        while time.monotonic() < deadline and time.monotonic() - last < quiet:
            if self.take(quiet / 4):
                last = time.monotonic()


def _request_stop(node_holder: list, pending: list) -> Callable:
    def handler(signum, frame) -> None:
        if node_holder:
            node_holder[0].stop_requested = True
        else:  # still being built (the recorder may have opened its bag): stop once built
            pending.append(signum)
    return handler


def run_node(factory: Callable[[], AtoNode]) -> None:
    """Life cycle of a node process: init, spin until shutdown or signal, clean exit.

    SIGINT and SIGTERM do not tear the ROS context down under the node (rclpy's own
    handlers would): they end the spin loop, then the node's on_stop() runs with the
    context alive (its data is flushed to the subscribers; the recorder drains what is
    still arriving and closes its bag), then the node exits. Bad parameters end the
    process with one line on stderr and exit status 2.
    """
    _init_rclpy(getattr(factory, "role", "node"))
    holder: list[AtoNode] = []
    pending: list[int] = []
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, _request_stop(holder, pending))
    # the launcher starts nodes with both held, so that none is lost while importing
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})
    node = None
    status = 0
    try:
        node = factory()
        holder.append(node)
        install_timing(node, {  # nothing unless $ATO_NODE_TIMING is set
            "wait": (SubscriptionWaitSet, "wait"), "take": (SubscriptionWaitSet, "take"),
            "housekeeping": (sys.modules[__name__], "_housekeeping")})
        node.stop_requested = node.stop_requested or bool(pending)
        # rclpy.experimental.EventsExecutor (7.1.6) fires no timers and ignores SIGINT here.
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        spin_lockstep(node, executor)
        if node.stop_requested and rclpy.ok():
            node.on_stop()
            node.log.flush()  # stopped by a signal: its last records still reach /rosout
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (ScenarioError, rclpy.exceptions.ParameterException, ValueError) as exc:
        role = getattr(factory, "role", "node")
        print(f"{role}: error: {str(exc).splitlines()[0]}", file=sys.stderr)
        status = 2
    except Exception:
        # A signal shuts the context down under a running callback, whose next rcl call
        # then fails (publisher or context invalid): that is the shutdown, not a fault.
        if rclpy.ok():
            raise
    finally:
        status = _tear_down(node, status)
    sys.exit(status)


def _init_rclpy(role: str) -> None:
    """rclpy.init, which reads the --params-file before any node exists. A command line
    rcl refuses ends the process with exit status 2 and one line on stderr (rcl's own
    ERROR record of it, written to the same descriptor, is dropped)."""
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as said:
        os.dup2(said.fileno(), 2)
        try:
            rclpy.init(args=sys.argv, signal_handler_options=SignalHandlerOptions.NO)
        except RCLError as exc:
            refused = exc
        else:
            refused = None
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        if refused is not None:
            print(f"{role}: error: {_unreadable_arguments(refused)}", file=sys.stderr)
            sys.exit(2)
        said.seek(0)
        sys.stderr.buffer.write(said.read())  # anything else rcl said while starting
        sys.stderr.flush()


def _unreadable_arguments(exc: RCLError) -> str:
    """Why rcl refused the command line, in one line: a scenario that builds on a preset
    (`base:`, which only this project's loader reads) named as such, else rcl's own
    reason without its source locations."""
    for path in parameter_files():
        try:
            document = yamlfile.load(path, "parameter file")
        except ScenarioError as refused:
            return str(refused)
        if isinstance(document, dict) and "base" in document:
            return (f"{path} builds on the preset {document['base']!r} (base:), which a ROS "
                    "parameter file cannot: start the nodes with run_stack.py or the launch "
                    "file, or give them a bag's params.yaml")
    return str(exc).split(", at ")[0].removeprefix("failed to initialize rcl: ")


def _tear_down(node: AtoNode | None, status: int) -> int:
    """Release what the node holds (the recorder's bag first), then the middleware, within
    TEARDOWN_LIMIT each; the process's exit status."""
    faulthandler.dump_traceback_later(TEARDOWN_LIMIT, exit=True)
    if node is not None:
        node.close()
        status = status or node.exit_status
    # the node's work is done: a stall in the middleware's teardown (seen once: a Fast DDS
    # node destroyed on a loaded machine) ends the process with the status it earned
    watchdog.exit_after(TEARDOWN_LIMIT, status)
    if node is not None:
        node.destroy_node()
    rclpy.try_shutdown()
    return status


def labelled(names) -> Float64MultiArray:
    """A Float64MultiArray whose layout names its entries (`names`, comma-separated in
    dim[0].label): its values travel with their names, and a bag says what it holds."""
    message = Float64MultiArray()
    message.layout.dim = [MultiArrayDimension(label=",".join(names), size=len(names),
                                              stride=len(names))]
    return message
