"""The in-process API the scripts use, in one import: a run prepared from a scenario
(loaded, overridden, checked once, as the stack's launchers do), simulated in this process
(the one loop, compiled when numba is installed) and scored as score_bag scores a bag (a
journey's per station under "journey"); the same values, series and indices as a run
through the nodes (tests/test_stack.py). The README shows it."""

from ato_nodes.core.config.scenario import prepare
from ato_nodes.core.run.loop import simulate
from ato_nodes.results.journeys import score_run as score

__all__ = ["prepare", "simulate", "score"]
