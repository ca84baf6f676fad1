"""A controller node that breaks one rule of the contract (docs/external-nodes.md), named
by its first argument: ato-check-node must find that rule broken and the others kept.

    python tests/data/broken_node.py FLAW [MARK] --ros-args ...
"""

import sys

from ato_nodes.nodes.base import run_node
from ato_nodes.nodes.external import ExternalController


def proportional(parameters: dict):
    return lambda target, measured, horizon: (50.0 * (target - measured), (target - measured,))


class Broken(ExternalController):
    flaw = sys.argv[1]

    def __init__(self):
        super().__init__(proportional, ("error",), name="broken")
        if self.flaw == "unnamed-outputs":
            self.outputs_msg.layout.dim = []

    def _declare_parameters(self, use_sim_time: bool):
        return super()._declare_parameters(use_sim_time and self.flaw != "no-clock")

    def announce_parameters(self) -> None:
        if self.flaw != "no-parameters":
            super().announce_parameters()

    def ready_when_matched(self) -> None:
        if self.flaw != "never-ready":
            super().ready_when_matched()

    latest = (0.0,)  # the newest horizon, whichever step it is for

    def on_horizon(self, msg) -> None:
        if self.flaw == "latest-horizon":
            self.latest = msg.data
            return
        super().on_horizon(msg)

    def on_speed(self, msg) -> None:
        if self.flaw == "latest-horizon":
            self.horizons.append(self.latest)
        super().on_speed(msg)

    def shut_down(self) -> None:
        if self.flaw != "deaf":
            super().shut_down()


if __name__ == "__main__":
    if Broken.flaw == "no-clock":  # not even rclpy's time source subscribes /clock
        at = sys.argv.index("use_sim_time:=true")
        del sys.argv[at - 1:at + 1]
    run_node(Broken)
