"""Nothing recorded is lost: killed, frozen and disk-starved recorders, a killed
launcher, SIGTERM, and tunings that must not mix or share their logs."""

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader

from ato_nodes.bags.bagio import read_run
from ato_nodes.core.base.topics import step_topics
from ato_nodes.launcher.launch import DOMAIN_LOCK_PORT, IGNORED_ENVIRONMENT, node_environment
from test_stack import (ROOT, alive, children, message_counts, run_stack, start_stack,
                        wait_for_children, wait_for_stepping)
from commands import invocation

pytestmark = pytest.mark.integration
TUNE = [*invocation("tune")]


def parent(pid: int) -> int:
    return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])


def opens_everywhere(bag: Path) -> dict[str, int]:
    """The bag opens in rosbags and in mcap's reader with the same messages; its counts."""
    counts = message_counts(bag)
    with AnyReader([bag]) as reader:
        assert sum(1 for _ in reader.messages()) == sum(counts.values())
    (mcap_file,) = bag.glob("*.mcap")
    with mcap_file.open("rb") as handle:
        assert sum(1 for _ in make_reader(handle).iter_messages()) == sum(counts.values())
    return counts


def holds_what_its_summary_says(bag: Path) -> None:
    summary = json.loads((bag / "summary.json").read_text())
    assert summary["recorded"] == message_counts(bag)
    if not any(summary["recorded"].values()):  # stopped before its first step
        assert summary["scored_steps"] == 0
        return
    assert summary["scored_steps"] == len(read_run(bag).series["t"]) == \
        summary["indices"]["steps"]


def wait_for_chunks(bag: Path, size: int = 20000) -> None:
    """Until the recorder has chunks of steps on disk (an event, not a guess of time)."""
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and sum(
            path.stat().st_size for path in bag.glob("*.mcap")) < size:
        time.sleep(0.05)


@pytest.mark.parametrize("step", [0, 500])
def test_a_sigkilled_recorder_loses_at_most_a_second_and_its_bag_is_repaired(tmp_path, step):
    bag = tmp_path / "killed"
    result = run_stack("--duration", "60", "--out", str(bag), "--set",
                       f"run.fault=recorder:kill:{step}", timeout=120)
    assert result.returncode == 1 and "node 'recorder' exited" in result.stderr
    assert "repaired" in result.stderr and "Traceback" not in result.stderr
    counts = opens_everywhere(bag)
    # killed on taking that step of /clock; the plant never ran more than run.record_lag
    # (1 s = 20 steps) ahead of the last block on disk: at most 1 s of simulated time lost.
    # Other topics' messages of the steps the plant ran ahead may reach the recorder
    # before that /clock message does (seen in a fresh-clone CI run: 513 at step 500),
    # so the counts lie within the plant's lead on either side of the step.
    assert set(counts) == {topic.name for topic in step_topics()}
    assert max(0, step - 20) <= min(counts.values()) <= max(counts.values()) <= step + 20 + 2
    metadata = (bag / "metadata.yaml").read_text()  # as the recorder would have written it
    assert "ros_distro: jazzy" in metadata and metadata.count("reliability: reliable") == 9
    if step:
        holds_what_its_summary_says(bag)


def stepping_real_time_run(bag: Path, role: str) -> tuple[subprocess.Popen, int]:
    """A 600 s real-time run that is stepping; the launcher and the pid of one node."""
    process = start_stack("--duration", "600", "--real-time", "--out", str(bag))
    nodes = wait_for_children(process, roles=(role,))
    wait_for_stepping(process)
    return process, nodes[role]


def test_a_frozen_recorder_and_ctrl_c_leave_a_complete_bag(tmp_path):
    bag = tmp_path / "frozen"
    process, recorder = stepping_real_time_run(bag, "recorder")
    wait_for_chunks(bag)
    os.kill(recorder, signal.SIGSTOP)
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 130 and "Traceback" not in stderr
    assert "repaired" not in stderr  # woken (SIGCONT) with the SIGINT, it closed its bag
    assert min(opens_everywhere(bag).values()) > 0
    holds_what_its_summary_says(bag)


def test_a_frozen_node_is_named_and_ends_the_run(tmp_path):
    bag = tmp_path / "stalled"
    process, controller = stepping_real_time_run(bag, "controller")
    os.kill(controller, signal.SIGSTOP)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 1 and "node 'controller' is stopped" in stderr
    assert "Traceback" not in stderr
    holds_what_its_summary_says(bag)


def test_a_full_disk_is_one_line_and_keeps_what_was_written(tmp_path):
    bag = tmp_path / "full"
    result = run_stack("--duration", "60", "--out", str(bag), "--set",
                       "run.fault=recorder:diskfull:300", timeout=120)
    assert result.returncode == 1 and "Traceback" not in result.stderr
    errors = [line for line in result.stderr.splitlines() if line.startswith("recorder:")]
    assert len(errors) == 1 and "cannot write the bag" in errors[0]
    assert 280 <= min(opens_everywhere(bag).values()) <= 300


def test_an_interrupted_run_records_every_step_the_loop_made(tmp_path):
    """SIGINT while stepping flat out: the nodes flush, the recorder drains, so every
    topic ends within the two steps the targets run ahead, and the summary says so."""
    bag = tmp_path / "interrupted"
    process = start_stack("--duration", "2400", "--out", str(bag))
    wait_for_stepping(process)
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 130 and "Traceback" not in stderr
    counts = opens_everywhere(bag)
    assert max(counts.values()) - min(counts.values()) <= 3
    holds_what_its_summary_says(bag)


@pytest.mark.parametrize("spacing", [0.05, 0.3, 1.0])
def test_a_second_ctrl_c_keeps_the_summary_and_the_parameter_file(tmp_path, spacing):
    """The second signal lands while the first is being handled (the nodes stopping, the
    bag closing, the summary being written): it changes nothing."""
    bag = tmp_path / "twice"
    process = start_stack("--duration", "2400", "--out", str(bag))
    wait_for_stepping(process)
    process.send_signal(signal.SIGINT)
    time.sleep(spacing)  # the stimulus: two presses this far apart
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 130 and "Traceback" not in stderr, stderr
    assert (bag / "params.yaml").exists()
    holds_what_its_summary_says(bag)
    assert json.loads((bag / "summary.json").read_text())["status"] == "interrupted"


def test_a_hung_recorder_goes_with_a_killed_launcher_and_its_bag_opens(tmp_path):
    """The recorder is deaf to its death signal (run.fault hang): the fork server kills
    it after the grace period and repairs the bag it left open."""
    bag = tmp_path / "hung"
    process = start_stack("--duration", "600", "--out", str(bag), "--set",
                          "run.fault=recorder:hang:100")
    nodes = wait_for_children(process, roles=("profile", "plant", "controller", "supervisor",
                                               "recorder"))
    server = parent(nodes["recorder"])  # the fork server: it repairs the bag, then ends
    wait_for_stepping(process)
    wait_for_chunks(bag, size=1)  # the recorder has the bag open
    process.send_signal(signal.SIGKILL)
    process.wait(timeout=10)
    deadline = time.monotonic() + 60
    while any(alive(pid) for pid in [*nodes.values(), server]) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not [role for role, pid in nodes.items() if alive(pid)] and not alive(server)
    counts = opens_everywhere(bag)
    assert set(counts) == {topic.name for topic in step_topics()}
    assert 80 <= min(counts.values()) <= max(counts.values()) <= 100 + 20 + 2


def domain_free(domain: int) -> bool:
    """Whether the domain's lock port can be bound (SO_REUSEADDR: a TIME_WAIT connection on
    the port, which lies in the ephemeral range, is no lock)."""
    with socket.socket() as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind(("127.0.0.1", DOMAIN_LOCK_PORT + domain))
        except OSError:
            return False
    return True


def test_a_deaf_node_dies_with_a_killed_launcher_and_keeps_its_domain_till_then(tmp_path):
    bag = tmp_path / "orphan"
    process = start_stack("--duration", "600", "--real-time", "--out", str(bag), "--set",
                          "run.fault=controller:hang:40")
    nodes = wait_for_children(process, roles=("profile", "plant", "controller", "supervisor",
                                               "recorder"))
    banner = wait_for_stepping(process)[0]
    domain = int(banner.split("ROS_DOMAIN_ID=")[1].split(",")[0])
    process.send_signal(signal.SIGKILL)
    process.wait(timeout=10)
    deadline = time.monotonic() + 30
    while any(alive(pid) for pid in nodes.values()) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not [role for role, pid in nodes.items() if alive(pid)]
    while not domain_free(domain) and time.monotonic() < deadline:
        time.sleep(0.1)  # the last process holding the lock may exit after the nodes
    assert domain_free(domain)
    assert (bag / "metadata.yaml").exists()  # the recorder closed its bag on SIGTERM


def test_sigterm_interrupts_a_run_like_ctrl_c_and_removes_its_temporary_files(tmp_path):
    bag = tmp_path / "terminated"
    process = start_stack("--duration", "600", "--real-time", "--out", str(bag))
    wait_for_stepping(process)
    wait_for_chunks(bag)
    process.send_signal(signal.SIGTERM)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 130 and "Traceback" not in stderr
    assert not list(Path("/tmp").glob(f"ato-run-{process.pid}-*"))
    holds_what_its_summary_says(bag)


def tune(out: Path, *extra: str, duration: float = 5, wait: bool = True):
    command = [*TUNE, "--algorithm", "pso", "--scenario", "seed000", "--in-process",
               "--params", "adrc.mu1=600:60000", "--evaluations", "40", "--population", "4",
               "--set", f"run.duration={duration}", "--out", str(out), "--quiet", *extra]
    if wait:
        return subprocess.run(command, capture_output=True, text=True, timeout=120)
    return subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_a_tuning_resumed_under_other_conditions_is_refused(tmp_path):
    out = tmp_path / "tuning"
    assert tune(out).returncode == 0
    changed = tune(out, "--resume", duration=6)
    assert changed.returncode == 2 and "other settings or conditions" in changed.stderr
    log = out / "evaluations.jsonl"
    lines = log.read_text().splitlines()
    record = json.loads(lines[3])
    record["conditions"] = "0" * 16  # evaluated under something else
    lines[3] = json.dumps(record)
    log.write_text("\n".join(lines) + "\n")
    mixed = tune(out, "--resume")
    assert mixed.returncode == 2 and "line 4 was evaluated under other conditions" in \
        mixed.stderr and len(mixed.stderr.strip().splitlines()) == 1


def test_two_tunings_never_share_an_output_directory(tmp_path):
    out = tmp_path / "shared"
    first = tune(out, duration=60, wait=False)
    deadline = time.monotonic() + 60
    while not (out / "evaluations.jsonl").exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    second = tune(out, "--resume", duration=60)
    assert second.returncode == 2 and "being written by another tuning" in second.stderr
    first.send_signal(signal.SIGINT)
    first.communicate(timeout=60)


INTRUDER = """
import sys, time, rclpy
from std_msgs.msg import Float64
from ato_nodes.nodes.base import QOS
rclpy.init()
node = rclpy.create_node("intruder")
publisher = node.create_publisher(Float64, "/train/measured_speed", QOS["data"])
print("publishing", flush=True)
while True:
    publisher.publish(Float64(data=99.0))
    time.sleep(0.05)
"""


def domain_of(banner: str) -> int:
    return int(banner.split("ROS_DOMAIN_ID=")[1].split(",")[0])


def test_another_publisher_in_a_runs_domain_ends_the_run_and_is_named(tmp_path, ros_domain):
    """The intruder publishes in the test's own domain, handed to the run: it outlives
    the run (until killed) in a domain still held."""
    bag = tmp_path / "intruded"
    process = start_stack("--duration", "600", "--real-time", "--out", str(bag),
                          domain=ros_domain)
    wait_for_stepping(process)
    intruder = subprocess.Popen([sys.executable, "-c", INTRUDER],
                                env=node_environment(ros_domain.domain_id),
                                stdout=subprocess.PIPE, text=True)
    try:
        assert intruder.stdout.readline().strip() == "publishing"
        _, stderr = process.communicate(timeout=60)
    finally:
        intruder.kill()
        intruder.wait()
    assert process.returncode == 1 and "exited with status 1" in stderr  # the first to see it
    assert "/train/measured_speed has 2 publishers, not 1: another process publishes in " \
        "this run's ROS domain" in stderr
    assert "Traceback" not in stderr
    holds_what_its_summary_says(bag)


def test_replay_into_a_running_runs_domain_is_refused(tmp_path):
    process = start_stack("--duration", "600", "--real-time", "--out", str(tmp_path / "run"))
    domain = domain_of(wait_for_stepping(process)[0])
    try:
        replay = subprocess.run([*invocation("replay_bag"),
                                 str(tmp_path), "--domain-id", str(domain)],
                                capture_output=True, text=True, timeout=60)
    finally:
        process.send_signal(signal.SIGINT)
        process.communicate(timeout=60)
    assert replay.returncode == 2 and f"ROS domain {domain} is in use by a run" in replay.stderr


def test_a_fast_dds_environment_file_of_the_users_changes_nothing(tmp_path):
    """A discovery server named in FASTDDS_ENVIRONMENT_FILE (none runs) would keep the
    nodes from ever matching; the launcher removes it, so the run completes."""
    environment_file = tmp_path / "fastdds.json"
    environment_file.write_text(json.dumps({"ROS_DISCOVERY_SERVER": "127.0.0.1:11888"}))
    result = subprocess.run([*invocation("run_stack"),
                             "--scenario", "seed000-step", "--duration", "2", "--out",
                             str(tmp_path / "run"), "--timeout", "60"],
                            env={**os.environ, "FASTDDS_ENVIRONMENT_FILE": str(environment_file)},
                            capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert result.returncode == 0, result.stderr


def test_runs_stay_on_this_host_whatever_the_environment(tmp_path):
    env = {**os.environ, **{name: "127.0.0.2" for name in IGNORED_ENVIRONMENT},
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET", "ROS_LOCALHOST_ONLY": "0"}
    process = subprocess.Popen([*invocation("run_stack"),
                                "--duration", "600", "--real-time", "--out",
                                str(tmp_path / "run")], env=env, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        nodes = wait_for_children(process, roles=("plant", "controller"))
        for pid in nodes.values():
            environ = dict(entry.split("=", 1) for entry in Path(f"/proc/{pid}/environ")
                           .read_bytes().decode().split("\0") if "=" in entry)
            assert environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
            assert environ["SKIP_DEFAULT_XML_FILE"] == "1"
            assert not set(IGNORED_ENVIRONMENT) & set(environ)
    finally:
        process.send_signal(signal.SIGINT)
        process.communicate(timeout=60)


def test_an_in_process_candidate_past_its_timeout_is_a_timeout():
    from ato_nodes.core.config.scenario import load_scenario
    from ato_nodes.studies.tuning import PENALTY, evaluate_in_process
    record = evaluate_in_process(load_scenario("seed000"), {"adrc.mu1": 7000.0}, "itae", 0,
                                 timeout=1e-9)
    assert record.status == "timeout" and record.fitness == PENALTY


def test_ctrl_c_of_a_stack_tuning_stops_its_candidates_at_once(tmp_path):
    out = tmp_path / "stack-tuning"
    command = [*TUNE, "--algorithm", "pso", "--scenario", "seed000", "--params",
               "adrc.mu1=600:60000", "--evaluations", "4", "--population", "2",
               "--workers", "2", "--set", "run.duration=2400", "--set", "run.real_time=true",
               "--out", str(out), "--quiet"]
    tuning = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True, cwd=ROOT)
    deadline = time.monotonic() + 60
    while len(list(out.glob("runs/*/*.mcap"))) < 2 and time.monotonic() < deadline:
        time.sleep(0.05)  # both candidates are recording (real time: 40 minutes each)
    tuning.send_signal(signal.SIGINT)
    _, stderr = tuning.communicate(timeout=60)  # not the candidates' 40 minutes
    assert tuning.returncode == 130 and "continue with --resume" in stderr
    assert "Traceback" not in stderr
    log = out / "evaluations.jsonl"
    assert not log.exists() or log.read_text() == ""  # nothing half-evaluated logged
    assert not [pid for pid in children(tuning.pid).values() if alive(pid)]


def test_a_run_that_times_out_names_what_the_loop_waited_for(tmp_path):
    result = run_stack("--duration", "60", "--timeout", "8", "--out", str(tmp_path / "hung"),
                       "--set", "run.fault=controller:hang:100", timeout=120)
    assert result.returncode == 1 and "did not finish within 8 s" in result.stderr
    # the plant published step 99, the controller (hung) never answered it
    assert "the loop stalled at step 99, waiting for controller (" in result.stderr


STALLED_NODE = """
import ctypes
import time
from ato_nodes.nodes import base

class StalledSupervisor(base.AtoNode):
    role = "supervisor"

    def __init__(self):
        super().__init__()
        # the run's end, as the 'shutdown' event brings it, once the node spins
        self.create_timer(0.01, self.shut_down, clock=self._wall_clock)

    def {stalled}(self):
        {stall}

base.TEARDOWN_LIMIT = 1.0
base.run_node(StalledSupervisor)
"""
# While the node holds its work (the bag): a call that never returns
STALLED_TEARDOWN = STALLED_NODE.format(stalled="close", stall="while True: time.sleep(0.1)")
# After its work: a middleware call that never returns and holds the interpreter lock, as
# a stalled DDS teardown does (libc's sleep called through ctypes.PyDLL keeps the lock)
STALLED_MIDDLEWARE = STALLED_NODE.format(stalled="destroy_node",
                                         stall="ctypes.PyDLL(None).sleep(100)")


def test_a_node_whose_teardown_stalls_exits_with_its_stack_on_stderr(ros_domain):
    process = subprocess.run([sys.executable, "-c", STALLED_TEARDOWN], cwd=ROOT,
                             env=node_environment(ros_domain.domain_id),
                             capture_output=True, text=True, timeout=60)
    assert process.returncode == 1
    stack = process.stderr.split("Timeout (0:00:01)!")[1]
    assert "in close\n" in stack and "in run_node\n" in stack
    assert "Exception" not in process.stderr


def test_a_node_whose_middleware_stalls_after_its_work_exits_with_its_own_status(ros_domain):
    process = subprocess.run([sys.executable, "-c", STALLED_MIDDLEWARE], cwd=ROOT,
                             env=node_environment(ros_domain.domain_id),
                             capture_output=True, text=True, timeout=60)
    assert process.returncode == 0, process.stderr
    stack = process.stderr.split("Timeout (0:00:01)!")[1]
    assert "in destroy_node\n" in stack and "in _tear_down\n" in stack
