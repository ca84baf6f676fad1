"""ROS domains taken through the project's lock: handed to a command without a moment
unheld, and never a probe in a domain nobody holds."""

import subprocess
import sys
import time
from pathlib import Path

import pytest

from ato_nodes.launcher.launch import DomainLock, node_environment

ROOT = Path(__file__).resolve().parents[1]
# Beyond DOMAIN_IDS, so that no launcher takes them by itself (a domain let go in 1-101
# is at once the next run's on a busy host)
UNCLAIMED_DOMAINS = (231, 232)
TAKES_ITS_DOMAIN = ("import sys; from ato_nodes.launcher.launch import DomainLock; "
                    "DomainLock(int(sys.argv[1]))")


def takes(domain_id: int, **popen) -> subprocess.CompletedProcess:
    """A child process's DomainLock(domain_id), as run_stack.py --domain-id takes it."""
    return subprocess.run([sys.executable, "-c", TAKES_ITS_DOMAIN, str(domain_id)],
                          capture_output=True, text=True, timeout=60, cwd=ROOT, **popen)


def test_a_held_domain_is_refused_unless_its_lock_is_handed_down(ros_domain):
    refused = takes(ros_domain.domain_id)
    assert refused.returncode == 1 and "is in use by another run" in refused.stderr
    assert takes(ros_domain.domain_id, **ros_domain.handed_down()).returncode == 0
    other = DomainLock()  # the lock handed down is one domain's, not any the child names
    try:
        assert takes(other.domain_id, **ros_domain.handed_down()).returncode == 1
    finally:
        other.release()
    with pytest.raises(RuntimeError):  # the child's end leaves the test's lock in place
        DomainLock(ros_domain.domain_id)


def test_a_probe_refuses_a_domain_nobody_holds():
    env = node_environment(UNCLAIMED_DOMAINS[1])
    probe = subprocess.run([sys.executable, str(ROOT / "tests" / "topic_probe.py"), "/rosout",
                            "5"], capture_output=True, text=True, timeout=60, env=env)
    assert probe.returncode == 2 and "ROS domain 232 is held by no DomainLock" in probe.stderr


@pytest.mark.integration
def test_a_probe_whose_domain_is_let_go_takes_its_lock():
    lock = DomainLock(UNCLAIMED_DOMAINS[0])
    probe = subprocess.Popen([sys.executable, str(ROOT / "tests" / "topic_probe.py"), "/rosout",
                              "60"], stdout=subprocess.PIPE, text=True,
                             env=node_environment(lock.domain_id))
    try:
        assert probe.stdout.readline().strip() == "ready"
        lock.release()
        deadline = time.monotonic() + 30
        refused = takes(lock.domain_id)
        while refused.returncode == 0 and time.monotonic() < deadline:  # till the probe has it
            refused = takes(lock.domain_id)
        assert refused.returncode == 1 and "is in use by another run" in refused.stderr
    finally:
        probe.kill()
        probe.wait()
