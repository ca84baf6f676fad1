"""The real multi-process graph: recorded bags, faults, bad input, isolation, echo.

Each test launches scripts/run_stack.py as a user would.
"""

import json
import os
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Message
from mcap.stream_reader import StreamReader
from rosbags.highlevel import AnyReader

from ato_nodes.results import jsontext
from ato_nodes.bags.bagio import read_run, read_series, resimulate
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.config.scenario import apply_overrides, load_scenario
from ato_nodes.core.config.schema import NODES
from ato_nodes.core.run.scoring import score_series
from ato_nodes.core.base.topics import step_topics
from ato_nodes.launcher.launch import node_environment, node_processes
from ato_nodes.launcher.nodefork import NODE_START
from ato_nodes.nodes.base import STANDARD_EXECUTOR
from ato_nodes.nodes.timing import VARIABLE as TIMING
from commands import invocation

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[1]
RUN_STACK = [*invocation("run_stack")]
SCORE_BAG = [*invocation("score_bag")]
STEP_TOPICS = {topic.name for topic in step_topics()}


def run_stack(*args, timeout=180):
    return subprocess.run([*RUN_STACK, *args], capture_output=True, text=True, timeout=timeout,
                          cwd=ROOT)


def start_stack(*args, domain=None):
    """run_stack.py started; given `domain` (a DomainLock: the ros_domain fixture), in that
    domain, the lock handed to the launcher, so that the domain stays held by the test
    for its probes before the run starts and after it ends."""
    if domain is None:
        return subprocess.Popen([*RUN_STACK, *args], stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True, cwd=ROOT)
    return subprocess.Popen([*RUN_STACK, *args, "--domain-id", str(domain.domain_id)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
                            **domain.handed_down())


def children(pid):
    """Node processes started by a run_stack.py process: {role: pid}."""
    return node_processes(pid)


def alive(pid):
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def wait_for_children(process, roles=("plant", "controller", "recorder"), timeout=30.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        found = children(process.pid)
        if all(role in found for role in roles):
            return found
        time.sleep(0.05)
    raise AssertionError(f"node processes did not start: {children(process.pid)}")


def wait_for_stepping(process):
    """Read the run's stderr until the supervisor's first progress line: stepping began.
    Returns the lines read (the first is the banner with the domain id)."""
    lines = []
    for line in process.stderr:
        lines.append(line)
        if "steps/s" in line:
            return lines
    raise AssertionError("the run never started stepping: " + "".join(lines))


def message_counts(bag):
    with AnyReader([Path(bag)]) as reader:
        counts = {c.topic: 0 for c in reader.connections}
        for connection, _, _ in reader.messages():
            counts[connection.topic] += 1
    return counts


def mcap_message_count(bag):
    (mcap_file,) = Path(bag).glob("*.mcap")
    with mcap_file.open("rb") as handle:
        return sum(1 for _ in make_reader(handle).iter_messages())


def recorded_steps(bag):
    """Steps the recorder has on disk so far (its complete chunks; the file is still being
    written): the fewest messages of any per-step topic."""
    channels, counts = {}, dict.fromkeys(STEP_TOPICS, 0)
    for path in Path(bag).glob("*.mcap"):
        with path.open("rb") as handle:
            try:
                for record in StreamReader(handle).records:
                    if isinstance(record, Channel):
                        channels[record.id] = record.topic
                    elif isinstance(record, Message) and channels.get(record.channel_id) \
                            in counts:
                        counts[channels[record.channel_id]] += 1
            except (McapError, EOFError, ValueError, struct.error):
                pass  # the end the recorder is writing
    return min(counts.values())


def wait_for_recorded_steps(bag, steps, timeout=60.0):
    """Until `steps` steps of every per-step topic are on disk (an event, not a guess of
    time)."""
    deadline = time.monotonic() + timeout
    while recorded_steps(bag) < steps:
        assert time.monotonic() < deadline, f"{bag}: {steps} steps never recorded"
        time.sleep(0.05)


def in_process(duration, *overrides):
    values = apply_overrides(load_scenario("seed000"), [f"run.duration={duration}", *overrides])
    return simulate(values)


def test_short_run_records_every_step_and_scores_like_the_in_process_simulation(tmp_path):
    bag = tmp_path / "run"
    result = run_stack("--duration", "5", "--out", str(bag), "--quiet")
    assert result.returncode == 0, result.stderr
    counts = message_counts(bag)
    assert set(counts) == STEP_TOPICS
    assert set(counts.values()) == {100}
    assert mcap_message_count(bag) == 100 * len(STEP_TOPICS)

    scored = subprocess.run([*SCORE_BAG, str(bag), "--json"], capture_output=True, text=True)
    assert scored.returncode == 0, scored.stderr
    from_bag = json.loads(scored.stdout)
    expected = score_series(in_process(5))
    assert from_bag["steps"] == expected["steps"] == 100
    for index in ("itae", "iae", "ise", "max_abs_error", "j_seed004"):
        assert from_bag[index] == pytest.approx(expected[index], rel=1e-9), index
    summary = json.loads((bag / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["steps"] == 100
    assert summary["indices"]["itae"] == pytest.approx(expected["itae"], rel=1e-9)

    # metadata.yaml as rosbag2 writes it for Jazzy: ros2 bag play replays with these QoS
    metadata = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert metadata["version"] == 9 and metadata["ros_distro"] == "jazzy"
    for entry in metadata["topics_with_message_count"]:
        (offered,) = entry["topic_metadata"]["offered_qos_profiles"]
        assert (offered["reliability"], offered["history"], offered["durability"]) == \
            ("reliable", "keep_all", "volatile"), entry["topic_metadata"]["name"]


END_OF_RUN_LINES = {"plant": ("finished",), "recorder": ("recorded",), "supervisor": (),
                    "profile": (), "controller": ()}


def test_rosout_carries_every_nodes_end_of_run_lines(tmp_path, ros_domain):
    """What `ros2 topic echo /rosout` sees through a run: each node's last lines reach it
    before the node exits, and the launcher's console shows none of them."""
    process = start_stack("--scenario", "seed004-metro", "--duration", "8", "--real-time",
                          "--out", str(tmp_path / "watched"), domain=ros_domain)
    probe = subprocess.run([sys.executable, str(ROOT / "tests" / "rosout_probe.py"), "60",
                            *END_OF_RUN_LINES], capture_output=True, text=True, timeout=90,
                           env=node_environment(ros_domain.domain_id))
    stdout, stderr = process.communicate(timeout=60)
    assert process.returncode == 0 and probe.returncode == 0, (stderr, probe.stderr)
    lines = json.loads(probe.stdout)
    for node, words in END_OF_RUN_LINES.items():
        for word in (*words, "shutdown"):
            assert any(line.startswith(f"run event: {word}") for line in lines[node]), \
                (node, word, lines[node])
    assert "[INFO]" not in stdout + stderr


def test_two_simultaneous_runs_are_isolated_and_identical(tmp_path):
    bags = [tmp_path / "a", tmp_path / "b"]
    processes = [start_stack("--duration", "10", "--out", str(bag), "--quiet") for bag in bags]
    for process in processes:
        _, stderr = process.communicate(timeout=180)
        assert process.returncode == 0, stderr
    domains = {json.loads((bag / "summary.json").read_text())["domain_id"] for bag in bags}
    assert len(domains) == 2
    expected = in_process(10)
    series = [read_series(bag) for bag in bags]
    for run in series:
        assert len(run["target"]) == 200  # cross-talk would double or scramble the counts
        for name in ("target", "speed", "command", "z3"):
            np.testing.assert_array_equal(run[name], expected[name])
    # Same data: every topic's (timestamp, CDR bytes) sequence. Messages of one step
    # on different topics interleave in arrival order, which varies.
    with AnyReader([bags[0]]) as first, AnyReader([bags[1]]) as second:
        assert sorted((c.topic, t, bytes(d)) for c, t, d in first.messages()) == \
               sorted((c.topic, t, bytes(d)) for c, t, d in second.messages())


def test_ctrl_c_leaves_a_readable_bag_with_every_step_so_far(tmp_path):
    bag = tmp_path / "interrupted"
    process = start_stack("--duration", "60", "--real-time", "--out", str(bag))
    wait_for_stepping(process)
    wait_for_recorded_steps(bag, 40)
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 130, stderr
    assert "Traceback" not in stderr
    counts = message_counts(bag)
    assert set(counts) == STEP_TOPICS
    recorded = min(counts.values())
    assert recorded >= 40  # what was on disk before the Ctrl-C is all still there
    # a step cut between the plant's publish and the command: targets k+2, commands k-1
    assert max(counts.values()) - recorded <= 3
    assert mcap_message_count(bag) == sum(counts.values())
    series = read_series(bag)
    expected = in_process(60)
    np.testing.assert_array_equal(series["speed"][:recorded], expected["speed"][:recorded])


def test_a_crashing_node_stops_the_stack_and_is_named(tmp_path):
    bag = tmp_path / "crash"
    process = start_stack("--duration", "60", "--real-time", "--out", str(bag))
    nodes = wait_for_children(process, roles=("profile", "plant", "controller", "supervisor",
                                               "recorder"))
    wait_for_stepping(process)
    wait_for_recorded_steps(bag, 1)
    os.kill(nodes["controller"], signal.SIGKILL)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 1
    assert "node 'controller' exited" in stderr
    assert "Traceback" not in stderr
    assert not [role for role, pid in nodes.items() if alive(pid)]
    assert min(message_counts(bag).values()) > 0  # what was recorded is still readable


@pytest.mark.parametrize("args, problem", [
    (["--scenario", "no-such-scenario"], "unknown scenario 'no-such-scenario'"),
    (["--set", "adrc.r0=-1"], "adrc.r0 = -1.0 is out of range"),
    (["--set", "adrc.mu11=5"], "unknown parameter 'adrc.mu11'"),
    (["--set", "controller.kind=mpc"], "must be one of"),
    (["--duration", "-3"], "out of range"),
])
def test_bad_input_is_one_line_and_exit_2(args, problem):
    result = run_stack(*args, timeout=60)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and problem in lines[0]


def test_malformed_scenario_file_is_one_line_and_exit_2(tmp_path):
    broken = tmp_path / "broken.yaml"
    broken.write_text("plant:\n  ros__parameters: {plant.mass: 3\n")
    result = run_stack("--scenario", str(broken), timeout=60)
    assert result.returncode == 2
    assert result.stderr.strip().count("\n") == 0 and "malformed YAML" in result.stderr


def test_a_node_rejects_a_bad_parameter_alone(tmp_path, ros_domain):
    """`ros2 run ato_nodes controller --ros-args -p adrc.r0:=-1` fails cleanly too."""
    result = subprocess.run([sys.executable, "-m", "ato_nodes.nodes.controller", "--ros-args",
                             "-p", "adrc.r0:=-1.0"], capture_output=True, text=True, timeout=60,
                            cwd=ROOT, env=node_environment(ros_domain.domain_id))
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    assert "controller: error:" in result.stderr and "adrc.r0" in result.stderr


def test_a_node_given_an_old_switch_in_its_parameter_file_names_the_mode(tmp_path, ros_domain):
    """A raw ROS parameter file of an older version: the node's one line is a scenario's."""
    old = tmp_path / "old.yaml"
    old.write_text("/**:\n  ros__parameters:\n    ladrc.delay_aware: true\n")
    result = subprocess.run([sys.executable, "-m", "ato_nodes.nodes.controller", "--ros-args",
                             "--params-file", str(old)], capture_output=True, text=True,
                            timeout=60, cwd=ROOT, env=node_environment(ros_domain.domain_id))
    assert result.returncode == 2
    assert result.stderr.strip() == (
        f"controller: error: {old}: ladrc.delay_aware: true is an old switch of the linear "
        "ADRC: give ladrc.prediction: speed")


@pytest.mark.parametrize("content, line", [
    (None, "builds on the preset 'ato-on-board' (base:), which a ROS parameter file cannot"),
    ("a: [\n", "malformed YAML"),
    ("", "cannot read parameter file")], ids=["based-scenario", "malformed", "missing"])
def test_a_parameter_file_rcl_refuses_is_one_line_and_exit_2(content, line, tmp_path,
                                                               ros_domain):
    """rcl reads --params-file before any node exists: its refusal is the node's one line,
    without rcl's own record of it or a traceback."""
    given = ROOT / "msg_config" / "scenarios" / "seed004-metro-ato.yaml"
    if content is not None:
        given = tmp_path / "given.yaml"
        if content:
            given.write_text(content)
    result = subprocess.run([sys.executable, "-m", "ato_nodes.nodes.plant", "--ros-args",
                             "--params-file", str(given)], capture_output=True, text=True,
                            timeout=60, cwd=ROOT, env=node_environment(ros_domain.domain_id))
    assert result.returncode == 2
    assert result.stderr.startswith("plant: error: ") and result.stderr.count("\n") == 1
    assert line in result.stderr and str(given) in result.stderr


def test_a_separate_process_echoes_every_topic_at_the_configured_rate(tmp_path, ros_domain):
    bag = tmp_path / "watched"
    process = start_stack("--duration", "30", "--real-time", "--out", str(bag), domain=ros_domain)
    wait_for_stepping(process)
    probe = subprocess.run([sys.executable, str(ROOT / "tests" / "echo_probe.py"), "6"],
                           capture_output=True, text=True, timeout=60,
                           env=node_environment(ros_domain.domain_id))
    process.send_signal(signal.SIGINT)
    process.communicate(timeout=60)
    assert probe.returncode == 0, probe.stderr
    received = json.loads(probe.stdout)
    for name in STEP_TOPICS:
        count, span = received[name]["count"], received[name]["span"]
        assert count >= 40, (name, count)
        rate = (count - 1) / span
        assert 0.5 * 20 < rate < 1.5 * 20, (name, rate)  # configured: run.period 0.05 s


def test_a_diverging_run_ends_early_the_same_way_in_both_runners(tmp_path):
    bag = tmp_path / "diverged"
    result = run_stack("--duration", "20", "--set", "adrc.b0=0.001", "--out", str(bag), "--quiet")
    assert result.returncode == 1
    assert "diverged at step" in result.stderr
    summary = json.loads((bag / "summary.json").read_text())
    assert summary["status"] == "diverged"
    expected = in_process(20, "adrc.b0=0.001")
    assert summary["steps"] == len(expected["t"]) < 400
    np.testing.assert_array_equal(read_series(bag)["speed"], expected["speed"])


@pytest.mark.parametrize("scenario", ["seed004-metro", "seed003-maglev"])
def test_line_scenarios_run_through_the_stack_exactly_as_in_process(tmp_path, scenario):
    """Train preset, line, ATO curve, dead time, seeded sensor noise, the seed's controller:
    the bag's series equal the in-process ones and its indices include the line's."""
    bag = tmp_path / scenario
    result = run_stack("--scenario", scenario, "--duration", "60", "--out", str(bag), "--quiet")
    assert result.returncode == 0, result.stderr
    values = apply_overrides(load_scenario(scenario), ["run.duration=60"])
    expected = simulate(values)
    recorded = read_series(bag)
    for name in ("target", "position", "measured_speed", "speed", "force", "command",
                 "speed_limit", "line_resistance", "z3"):
        np.testing.assert_array_equal(recorded[name], expected[name], err_msg=name)
    scored = subprocess.run([*SCORE_BAG, str(bag), "--json"], capture_output=True, text=True)
    from_bag = json.loads(scored.stdout)
    strict = json.loads(jsontext.dumps(score_series(expected, values)))  # NaN as null
    assert from_bag == pytest.approx(strict)
    assert from_bag["traction_energy_kwh"] > 0 and "overspeed_time" in from_bag


def test_ros2_param_set_refuses_fixed_parameters_and_applies_live_gains_reproducibly(
        tmp_path, ros_domain):
    """A gain set on the live controller takes effect at a step boundary, is recorded with
    its step, and the bag alone re-simulates the run bit for bit; parameters fixed at
    start-up are refused with rclpy's standard read-only answer."""
    bag = tmp_path / "bag"
    process = start_stack("--duration", "60", "--real-time", "--out", str(bag), domain=ros_domain)
    try:
        wait_for_stepping(process)
        env = node_environment(ros_domain.domain_id)
        answers = {}
        for node, name, value in (("/controller", "adrc.mu1", "7000.0"),
                                  ("/plant", "run.period", "0.1"),
                                  ("/controller", "controller.preview", "3")):
            probe = subprocess.run([sys.executable, str(ROOT / "tests" / "param_probe.py"),
                                    node, name, value], capture_output=True, text=True,
                                   timeout=60, env=env)
            assert probe.returncode == 0, probe.stderr
            answers[name] = json.loads(probe.stdout)
    finally:
        process.send_signal(signal.SIGINT)
        process.communicate(timeout=60)
    assert answers["adrc.mu1"]["successful"] is True, answers
    for name in ("run.period", "controller.preview"):
        assert answers[name]["successful"] is False and "read-only" in answers[name]["reason"]
    run = read_run(bag)
    ((step, changes),) = run.parameter_changes.items()
    assert changes == {"adrc.mu1": 7000.0} and 0 < step < len(run.series["t"])
    resimulated, differ = resimulate(run)
    assert differ == [] and len(resimulated["command"]) > step
    unchanged = simulate(apply_overrides(load_scenario("seed000"), ["run.duration=60"]))
    recorded = run.series["command"]
    assert np.array_equal(recorded[:step], unchanged["command"][:step])
    assert not np.array_equal(recorded[step:], unchanged["command"][step:len(recorded)])
    score = subprocess.run([*SCORE_BAG, str(bag), "--resimulate"], capture_output=True,
                           text=True, timeout=120)
    assert score.returncode == 0 and "(1 live parameter change(s)): every recorded series " \
        "identical" in score.stdout, score.stdout + score.stderr

def test_a_compiled_in_process_run_equals_the_nodes_run_bit_for_bit(tmp_path):
    """seed000-realistic (lag, envelope, noisy quantised sensor) runs compiled in-process
    (core/run/fast_loop.py) and as Python in the nodes: every series is the same."""
    from ato_nodes.core.run import fast_loop
    from ato_nodes.launcher.launch import run_checked
    if not fast_loop.AVAILABLE:
        pytest.skip("numba is not installed: in-process runs are Python too")
    values = apply_overrides(load_scenario("seed000-realistic"), ["run.duration=60"])
    _, identical = run_checked(values, tmp_path / "realistic")
    assert identical


def sorted_messages(bag):
    """Every topic's (timestamp, CDR bytes) sequence: messages of one step on different
    topics interleave in arrival order, which varies from run to run."""
    with AnyReader([Path(bag)]) as reader:
        return sorted((c.topic, t, bytes(d)) for c, t, d in reader.messages())


def test_the_standard_executor_fallback_records_the_fast_paths_bag(tmp_path, ros_domain):
    """ATO_STANDARD_EXECUTOR=1 (what another rclpy release gets without it): every node says
    on /rosout that rclpy's executor serves its per-step inputs, and the bag holds the
    fast path's messages, bit for bit, and the in-process series."""
    fast, fallback = tmp_path / "fast", tmp_path / "fallback"
    assert run_stack("--duration", "5", "--out", str(fast), "--quiet").returncode == 0
    env = node_environment(ros_domain.domain_id)
    probe = subprocess.Popen([sys.executable, str(ROOT / "tests" / "rosout_probe.py"), "90",
                              *NODES], stdout=subprocess.PIPE, text=True, env=env)
    try:
        handed = ros_domain.handed_down({**os.environ, STANDARD_EXECUTOR: "1"})
        result = subprocess.run([*RUN_STACK, "--duration", "5", "--real-time", "--quiet",
                                 "--out", str(fallback), "--domain-id",
                                 str(ros_domain.domain_id)], capture_output=True, text=True,
                                timeout=120, cwd=ROOT, **handed)
        lines = json.loads(probe.communicate(timeout=120)[0])
    finally:
        if probe.poll() is None:
            probe.kill()
            probe.wait()
    assert result.returncode == 0, result.stderr
    for node in NODES:
        assert f"per-step inputs served by the standard executor: {STANDARD_EXECUTOR}=1" in \
            lines[node], (node, lines[node])
    assert sorted_messages(fallback) == sorted_messages(fast)
    expected = in_process(5)
    recorded = read_series(fallback)
    for name in ("target", "speed", "command", "z3"):
        np.testing.assert_array_equal(recorded[name], expected[name], err_msg=name)


def test_nodes_timing_their_parts_write_the_loops_figures(tmp_path):
    """$ATO_NODE_TIMING (benchmark.py --profile): each node writes, as it exits, its parts'
    time over the loop (from 'start' to 'finished'), and the run records every step."""
    timing, bag = tmp_path / "timing", tmp_path / "bag"
    timing.mkdir()
    result = subprocess.run([*RUN_STACK, "--duration", "5", "--quiet", "--out", str(bag)],
                            capture_output=True, text=True, timeout=120, cwd=ROOT,
                            env={**os.environ, TIMING: str(timing)})
    assert result.returncode == 0, result.stderr
    assert set(message_counts(bag).values()) == {100}
    figures = {role: json.loads((timing / f"{role}.json").read_text()) for role in NODES}
    for role, figure in figures.items():
        assert figure["steps"] == 100 and figure["process_cpu_ns"] > 0, role
        assert {"wait", "take", "housekeeping"} <= set(figure["parts"]), role
    # [wall ns, CPU ns, calls]: the plant steps from 'start' to 'finished'; another node's
    # loop begins when it hears 'start', maybe some steps late, and the recorder writes the
    # last steps after 'finished'
    assert figures["plant"]["parts"]["publish /clock"][2] == 100
    assert 0 < figures["controller"]["parts"]["publish /ato/traction_command"][2] <= 100
    assert 0 < figures["recorder"]["parts"]["bag write"][2] <= 9 * 100


def shares_a_socket(child, parent):
    """`child` has, beyond its console, a socket `parent` has under the same descriptor
    number (inherited: pass_fds keeps the number)."""
    for fd in Path(f"/proc/{child}/fd").iterdir():
        try:
            target = os.readlink(fd)
            if int(fd.name) > 2 and target.startswith("socket:") and \
                    os.readlink(f"/proc/{parent}/fd/{fd.name}") == target:
                return True
        except OSError:
            continue
    return False


def test_nodes_started_as_plain_processes_record_the_fork_servers_bag(tmp_path):
    """ATO_NODE_START=subprocess: each node is the launcher's own `python -m
    ato_nodes.nodes.ROLE` child, in its own session, with the run's environment; the run
    completes with the fork server's messages, bit for bit."""
    forked, plain = tmp_path / "forked", tmp_path / "plain"
    assert run_stack("--duration", "5", "--out", str(forked), "--quiet").returncode == 0
    process = subprocess.Popen([*RUN_STACK, "--duration", "5", "--real-time", "--quiet", "--out",
                                str(plain)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True, cwd=ROOT, env={**os.environ, NODE_START: "subprocess"})
    try:
        nodes = wait_for_children(process, roles=NODES)
        for role, pid in nodes.items():
            stat = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
            argv = Path(f"/proc/{pid}/cmdline").read_bytes().decode().split("\0")
            environ = Path(f"/proc/{pid}/environ").read_bytes().decode().split("\0")
            assert int(stat[1]) == process.pid and int(stat[3]) == pid, role  # parent, session
            assert argv[1:4] == ["-m", f"ato_nodes.nodes.{role}", "--ros-args"], argv
            assert "ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST" in environ
            assert shares_a_socket(pid, process.pid), role  # the domain lock, inherited
    finally:
        _, stderr = process.communicate(timeout=120)
    assert process.returncode == 0, stderr
    assert "plain processes" not in stderr  # asked for, not a fallback
    assert sorted_messages(plain) == sorted_messages(forked)


def test_a_fork_server_that_dies_before_forking_gives_a_plain_start(tmp_path, monkeypatch,
                                                                     capfd):
    """The run's fork server is killed before it forks a node: one line says so, and the
    run completes with nodes started as plain processes, the in-process series."""
    from ato_nodes.launcher import launch
    started = launch.fork_server

    def dead_fork_server(env, cwd):
        server = started(env, cwd)
        server.process.kill()
        server.process.wait()
        return server

    monkeypatch.setattr(launch, "fork_server", dead_fork_server)
    values = apply_overrides(load_scenario("seed000"), ["run.duration=5"])
    outcome = launch.Stack(values, tmp_path / "bag", quiet=True, timeout=120).run()
    assert outcome.ok, outcome.message
    said = [line for line in capfd.readouterr().err.splitlines() if "plain processes" in line]
    assert len(said) == 1 and "fork server" in said[0] and "before forking a node" in said[0]
    recorded, expected = read_series(tmp_path / "bag"), simulate(values)
    for name in ("target", "speed", "command", "z3"):
        np.testing.assert_array_equal(recorded[name], expected[name], err_msg=name)
