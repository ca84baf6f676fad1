"""The lockstep fast path's private rclpy calls are used only with the rclpy release they
were written for; otherwise (or forced) the standard executor serves the per-step inputs.
The through-the-stack comparison is in test_stack.py."""

from ato_nodes.nodes import base
from ato_nodes.nodes.base import STANDARD_EXECUTOR, SubscriptionWaitSet


def test_the_fast_path_is_used_with_the_release_it_was_written_for(monkeypatch):
    monkeypatch.delenv(STANDARD_EXECUTOR, raising=False)
    assert SubscriptionWaitSet.unavailable() == ""


def test_the_environment_forces_the_standard_executor(monkeypatch):
    monkeypatch.setenv(STANDARD_EXECUTOR, "1")
    assert SubscriptionWaitSet.unavailable() == f"{STANDARD_EXECUTOR}=1"


def test_another_rclpy_release_gets_the_standard_executor(monkeypatch):
    monkeypatch.delenv(STANDARD_EXECUTOR, raising=False)
    monkeypatch.setattr(base, "FAST_PATH_RCLPY", ("ros-jazzy-rclpy", "7.1.5"))
    assert "not 7.1.5" in SubscriptionWaitSet.unavailable()
    monkeypatch.setattr(base, "FAST_PATH_RCLPY", ("no-such-rclpy", "7.1.6"))
    assert "no-such-rclpy is not installed" in SubscriptionWaitSet.unavailable()


def test_a_missing_private_call_gets_the_standard_executor(monkeypatch):
    from rclpy.impl.implementation_singleton import rclpy_implementation
    monkeypatch.delenv(STANDARD_EXECUTOR, raising=False)
    monkeypatch.setattr(rclpy_implementation, "WaitSet", object)
    assert SubscriptionWaitSet.unavailable() == "rclpy lacks WaitSet.clear_entities, " \
        "WaitSet.add_subscription, WaitSet.wait, WaitSet.get_ready_entities"
