"""One outcome per run, said the same everywhere: a stop (Ctrl-C or SIGTERM) while a
command still validates its input is one line and exit 130; a stop once the run has
ended (the supervisor reported it, or a frozen node was named) changes nothing: the
console, the exit status and summary.json say how the run ended."""

import json
import os
import signal
import subprocess
import tempfile
import time
from pathlib import Path

import pytest

from ato_nodes.cli.run_stack import summarized
from ato_nodes.launcher.launch import WORKDIR_PREFIX, RunOutcome
from commands import ROOT, invocation
from test_bag_integrity import write
from test_faults import holds_what_its_summary_says, opens_everywhere
from test_stack import children, start_stack, wait_for_children, wait_for_stepping

EXIT_STATUS = {"completed": 0, "failed": 1, "interrupted": 130}
FROZEN = "node 'recorder' was stopped (SIGSTOP or a debugger)"


def until(condition, what: str, timeout: float = 120.0) -> None:
    """Wait for an event of the run (a file, a process state), not for a guess of time."""
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"never happened: {what}"
        time.sleep(0.01)


def core_loaded(pid: int) -> bool:
    """The process has the simulation core's compiler mapped: the command is importing
    or validating (building the plan), long before anything starts."""
    try:
        return "llvmlite" in Path(f"/proc/{pid}/maps").read_text()
    except OSError:
        return False


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
@pytest.mark.parametrize("command", ["run_stack", "tune"])
def test_a_stop_while_a_command_validates_is_one_line_and_exit_130(tmp_path, command,
                                                                   signum):
    """seed002-journey's validation builds its curves (many seconds): a SIGTERM there
    once killed the command silently (status 143) where Ctrl-C said `interrupted`."""
    out = tmp_path / "out"
    extra = ["--in-process", "--evaluations", "10"] if command == "tune" else []
    process = subprocess.Popen([*invocation(command), "--scenario", "seed002-journey",
                                "--out", str(out), *extra], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, cwd=ROOT)
    until(lambda: core_loaded(process.pid), "the simulation core loaded", timeout=60)
    process.send_signal(signum)
    stdout, stderr = process.communicate(timeout=60)
    assert (process.returncode, stderr, stdout) == (130, "interrupted\n", "")
    assert not out.exists()  # nothing had started, nothing is left


def rclpy_loaded(pid: int) -> bool:
    try:
        return "_rclpy_pybind11" in Path(f"/proc/{pid}/maps").read_text()
    except OSError:
        return False


@pytest.mark.integration
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_stop_of_a_replay_is_one_line_and_exit_130(tmp_path, ros_domain, signum):
    """A SIGTERM once ended a replay with rclpy's traceback (its context shut down under
    a publish), exit 1, where Ctrl-C said `interrupted`."""
    bag = tmp_path / "small"
    write(bag, 40)
    replay = subprocess.Popen([*invocation("replay_bag"), str(bag), "--wait-subscribers", "1",
                               "--domain-id", str(ros_domain.domain_id)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              cwd=ROOT, **ros_domain.handed_down())
    until(lambda: rclpy_loaded(replay.pid), "rclpy loaded: the replay is starting or "
          "waiting for a subscriber (it has none)", timeout=60)
    replay.send_signal(signum)
    stdout, stderr = replay.communicate(timeout=60)
    assert (replay.returncode, stderr, stdout) == (130, "interrupted\n", "")


def said_once(process: subprocess.Popen, bag: Path) -> tuple[dict, str, str]:
    """The run's summary, stdout and stderr, once it has ended; its exit status is the
    one its summary's status calls for, and a run that did not complete says the
    summary's message on the console."""
    stdout, stderr = process.communicate(timeout=120)
    assert "Traceback" not in stderr, stderr
    summary = json.loads((bag / "summary.json").read_text())
    assert process.returncode == EXIT_STATUS[summary["status"]], (summary, stderr)
    if summary["status"] != "completed":
        said = stderr.strip().splitlines()[-1]
        assert all(part in said for part in summary["message"].split("; ")[1:]), said
    holds_what_its_summary_says(bag)
    return summary, stdout, stderr


def reported(process: subprocess.Popen) -> bool:
    """The supervisor has reported the run's end (the launcher's report.json)."""
    return any(Path(tempfile.gettempdir()).glob(f"{WORKDIR_PREFIX}{process.pid}-*/report.json"))


def nodes_gone(process: subprocess.Popen) -> bool:
    """Every node has exited: the launcher is scoring the bag and writing its summary."""
    return not children(process.pid)


@pytest.mark.integration
@pytest.mark.parametrize("args, moment", [
    (["--scenario", "seed004-metro-line"], reported),  # its last-stop hold over
    (["--duration", "30"], nodes_gone),
])
def test_a_stop_after_the_run_ended_leaves_it_completed(tmp_path, ros_domain, args, moment):
    """Once the supervisor has reported the run's end the recorder holds every step: a
    Ctrl-C then (the nodes exiting, the bag being scored) once gave exit 130 with a
    summary saying `completed`, or `interrupted` with a complete bag."""
    bag = tmp_path / "late"
    process = start_stack(*args, "--out", str(bag), domain=ros_domain)
    wait_for_children(process, roles=("supervisor",))
    until(lambda: moment(process), moment.__doc__)
    process.send_signal(signal.SIGINT)
    summary, stdout, _ = said_once(process, bag)
    assert summary["status"] == "completed" and summary["scored_steps"] == summary["steps"]
    assert "ITAE" in stdout and f"bag: {bag}" in stdout
    assert (summary["ended"] == "at the last stop") == ("ended at the last stop" in stdout)


def frozen_recorder_run(bag: Path, domain) -> subprocess.Popen:
    """A real-time run, stepping, its recorder then stopped by SIGSTOP."""
    process = start_stack("--duration", "600", "--real-time", "--out", str(bag),
                          domain=domain)
    nodes = wait_for_children(process, roles=("recorder",))
    wait_for_stepping(process)
    os.kill(nodes["recorder"], signal.SIGSTOP)
    return process


@pytest.mark.integration
def test_ctrl_c_with_a_frozen_recorder_is_an_interrupt_that_names_it(tmp_path, ros_domain):
    bag = tmp_path / "frozen"
    process = frozen_recorder_run(bag, ros_domain)
    process.send_signal(signal.SIGINT)  # before the launcher names the frozen node
    summary, _, stderr = said_once(process, bag)
    assert summary["status"] == "interrupted" and FROZEN in summary["message"]
    assert stderr.strip().splitlines()[-1] == \
        f"interrupted; {summary['scored_steps']} steps recorded in {bag}; {FROZEN}"
    assert min(opens_everywhere(bag).values()) > 0  # woken with the SIGINT, it closed its bag


@pytest.mark.integration
def test_ctrl_c_after_a_frozen_recorder_was_named_leaves_the_run_failed(tmp_path, ros_domain):
    """The run had failed (the frozen recorder named, every node stopped) when the Ctrl-C
    came: it once turned the exit status into 130 and the console's line into
    `interrupted`, the node never named, while summary.json said `failed`."""
    bag = tmp_path / "named"
    process = frozen_recorder_run(bag, ros_domain)
    until(lambda: nodes_gone(process), "every node stopped")
    process.send_signal(signal.SIGINT)
    summary, _, stderr = said_once(process, bag)
    assert summary["status"] == "failed" and "node 'recorder' is stopped" in summary["message"]
    assert stderr.strip().splitlines()[-1].startswith(f"error: {summary['message']}; ")


def test_sigterm_stops_a_tuning_as_ctrl_c_does(tmp_path):
    """It once ended the tuner by the signal (status 143), its workers left running."""
    out = tmp_path / "tuning"
    log = out / "evaluations.jsonl"
    tuning = subprocess.Popen([*invocation("tune"), "--algorithm", "pso", "--in-process",
                               "--params", "adrc.mu1=600:60000", "--evaluations", "400",
                               "--population", "4", "--workers", "2", "--set",
                               "run.duration=60", "--out", str(out), "--quiet"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    until(lambda: log.exists() and log.read_text().count("\n") >= 2, "two evaluations logged")
    workers = [int(pid) for pid in Path(f"/proc/{tuning.pid}/task/{tuning.pid}/children")
               .read_text().split()]
    tuning.send_signal(signal.SIGTERM)
    try:
        _, stderr = tuning.communicate(timeout=120)  # the workers hold its pipes open too
    finally:
        left = [pid for pid in workers if Path(f"/proc/{pid}").exists()]
        for pid in left:  # not left running on the machine when the test fails
            os.kill(pid, signal.SIGKILL)
    assert tuning.returncode == 130 and stderr.endswith("continue with --resume\n"), stderr
    assert log.read_text().endswith("\n")  # every logged evaluation whole
    assert workers and not left


def test_a_completed_run_whose_bag_cannot_be_scored_is_a_failure_in_its_summary(tmp_path):
    """run_stack.py exits 1 for it (`error: ... bag not scored`): summary.json says the
    same, not `completed`."""
    bag = tmp_path / "unreadable"
    bag.mkdir()
    (bag / "unreadable_0.mcap").write_bytes(b"not a bag")
    summary = summarized("seed000", bag, RunOutcome("completed", report={"steps": 10}), "")
    written = json.loads((bag / "summary.json").read_text())
    assert summary["status"] == written["status"] == "failed"
    assert written["message"].startswith("bag not scored: ")
