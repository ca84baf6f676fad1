"""Console entry points (setup.py console_scripts): `ros2 run ato_nodes run_stack`,
or .venv/bin/run_stack after `pip install -e .`."""

from functools import partial

from ato_nodes.cli import start

run_stack = partial(start, "run_stack")
tune = partial(start, "tune")
analyze = partial(start, "analyze")
replay_bag = partial(start, "replay_bag")
score_bag = partial(start, "score_bag")
check_node = partial(start, "check_node")
