"""A controller node of a user's, standing in for the project's: the PID's law through
ato_nodes.nodes.external, as a user would write it around a law of their own."""

from ato_nodes.core.config.components import CONTROLLERS
from ato_nodes.core.config.context import RunContext
from ato_nodes.core.config.schema import NodeValues
from ato_nodes.core.control.limiter import CommandLimiter
from ato_nodes.nodes.external import run_controller

PID = CONTROLLERS["pid"]


class PIDLaw:
    """The PID kind's controller, built from the run's controller values."""

    def __init__(self, parameters: dict):
        values = NodeValues("controller", parameters)
        self.controller = PID.factory(values, RunContext(values),
                                      CommandLimiter.from_values(values))

    def start(self, target, measured, horizon):
        self.controller.start(target, measured)

    def step(self, target, measured, horizon):
        return self.controller.step(target, measured, horizon)


if __name__ == "__main__":
    run_controller(PIDLaw, outputs=PID.output_names, name="tests/data/external_pid.py")
