"""A controller node of a user's, standing in for the project's: the PID's law through
ato_nodes.nodes.external, as a user would write it around a law of their own."""

from ato_nodes.core.config.components import CONTROLLERS
from ato_nodes.core.config.context import RunContext
from ato_nodes.core.config.schema import NodeValues
from ato_nodes.core.control.limiter import CommandLimiter
from ato_nodes.nodes.external import run_controller

PID = CONTROLLERS["pid"]


def pid_law(parameters: dict):
    """The PID kind's controller (start and step of r_k, y_k and the horizon), built from
    the run's controller values."""
    values = NodeValues("controller", parameters)
    return PID.factory(values, RunContext(values), CommandLimiter.from_values(values))


if __name__ == "__main__":
    run_controller(pid_law, outputs=PID.output_names, name="tests/data/external_pid.py")
