"""ament_python package: `colcon build` in a ROS 2 workspace, or `pip install -e .`."""

from pathlib import Path

from setuptools import find_packages, setup

PACKAGE = "ato_nodes"
NODES = ("profile", "plant", "controller", "supervisor", "recorder")
# The user-facing commands (ato_nodes.cli), named as their scripts in scripts/ are
# (`ros2 run ato_nodes run_stack` = scripts/run_stack.py)
COMMANDS = ("run_stack", "tune", "analyze", "replay_bag", "score_bag", "check_node")


def config_files():
    """msg_config/ installed under share/ato_nodes/msg_config, tree preserved."""
    grouped = {}
    for path in sorted(Path("msg_config").rglob("*")):
        if path.is_file():
            grouped.setdefault(str(Path("share") / PACKAGE / path.parent), []).append(str(path))
    return sorted(grouped.items())


setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(include=[PACKAGE, f"{PACKAGE}.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/launch", ["launch/stack.launch.py"]),
        *config_files(),
    ],
    install_requires=["setuptools", "numpy", "daqp", "PyYAML", "matplotlib", "rosbags",
                      "mcap", "mcap-ros2-support", "plotly"],
    extras_require={"dask": ["dask[distributed]"],  # tune.py --cluster
                    "tables": ["pandas", "pyarrow"],  # bags.bagio.read_frame, export.py --parquet
                    "fast": ["numba"],  # compiled in-process runs (core/run/fast_loop.py)
                    "pareto": ["pymoo", "moocore"]},  # tune.py --objectives
    zip_safe=True,
    maintainer="ATO stack maintainers",
    description="ROS 2 automatic train operation stack: nodes, lockstep runs, MCAP scoring",
    license="Apache-2.0",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [f"{node} = {PACKAGE}.nodes.{node}:main" for node in NODES]
        + [f"{command} = {PACKAGE}.cli.console:{command}" for command in COMMANDS]
        + [f"ato-check-node = {PACKAGE}.cli.console:check_node"],
    },
)
