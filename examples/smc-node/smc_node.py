"""A controller node of your own in the ATO stack: the sliding-mode law of the plug-in
package examples/ato-smc (ato_smc.law), run by plain rclpy through
ato_nodes.nodes.external in place of the project's controller node.

    python scripts/run_stack.py --scenario seed000 \\
        --external controller -- python examples/smc-node/smc_node.py

The law's gains are the node's own ROS parameters (smc.*, with the ranges of the law's
PARAMETERS; `--ros-args -p smc.gain:=30.0` after the command, or `ros2 param set
/controller smc.gain 30.0` during the run); the period, the nominal train and the command
limits are the run's, from the parameter file the launcher hands the node. A run whose
controller.kind is smc (the plug-in installed) gives the node its smc.* values instead.
"""

from ato_smc.law import PARAMETERS, SMC_STEPS, SMCState, smc_settings

from ato_nodes.nodes.external import command_limiter, nominal_train, run_controller
from ato_nodes.plugin import SteppedController

OUTPUTS = ("sliding_surface", "feedforward", "equivalent", "switching")  # the law's, in order
GAINS = [(spec.name, spec.default, spec.description, spec.low, spec.high)
         for spec in PARAMETERS]


class SlidingMode:
    """The law's steps with the run's period, nominal train and limiter; its gains from
    the node's parameters, changed between two steps by retune()."""

    def __init__(self, parameters: dict):
        self.parameters = parameters
        self.train = nominal_train(parameters)
        self.controller = SteppedController(SMC_STEPS, self.settings(),
                                            command_limiter(parameters), SMCState(0.0))

    def settings(self):
        return smc_settings(self.parameters, self.parameters["run.period"], self.train)

    def start(self, target, measured, horizon):
        self.controller.start(target, measured, horizon)

    def step(self, target, measured, horizon):
        return self.controller.step(target, measured, horizon)

    def retune(self, changes: dict) -> None:
        self.parameters = {**self.parameters, **changes}
        self.controller.settings = self.settings()


if __name__ == "__main__":
    run_controller(SlidingMode, outputs=OUTPUTS, own=GAINS, name="examples/smc-node")
