import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ato_nodes.launcher.launch import DomainLock  # noqa: E402


@pytest.fixture
def ros_domain():
    """A ROS domain held through the project's DomainLock for the whole test: for the
    participants the test starts itself (probes, nodes started alone) and for the commands
    it hands the lock to (`--domain-id`, lock.handed_down()), so that no two suites on one
    host meet in a domain and none of the test's participants is ever in one nobody holds."""
    lock = DomainLock()
    yield lock
    lock.release()
