"""The five nodes of one run, as a standard ROS 2 launch file:

    ros2 launch ato_nodes stack.launch.py scenario:=seed004-metro out:=bags/metro

`scenario` is a shipped scenario's name or a scenario file; the nodes are given it
resolved, as `scripts/run_stack.py` gives it (its base, `base:`, which ROS 2 parameter
files do not know; the train preset; the values the scenario derives, the load weighing's
reading and where a journey's last stop begins: core/config/scenario.DERIVED_PARAMETERS),
a parameter file of the same name in a new temporary folder, so both give the same run.
`out` is the bag directory to create (default bags/<scenario>-launch). The run ends when
the supervisor ends it: every node exits on its 'shutdown' and the launch ends with the last
of them (a node still running STOP_GRACE s after the supervisor, or one that fails, shuts
the launch down, as run_stack.py does). The ROS domain is the environment's
(ROS_DOMAIN_ID). Without a ROS install, `python scripts/run_stack.py --scenario NAME` is
the same run.

`controller:=external` (or `profile:=external`) starts the other nodes and leaves that one
to a node of your own (docs/external-nodes.md), started in the same domain with
`--ros-args -r __node:=controller -p use_sim_time:=true --params-file FILE`, FILE the
resolved parameter file the launch logs; the supervisor waits supervisor.ready_timeout
for it, then ends the run naming it.
"""

import tempfile
from pathlib import Path

import yaml
from launch import LaunchDescription
from launch.actions import (DeclareLaunchArgument, EmitEvent, LogInfo, OpaqueFunction,
                            RegisterEventHandler, TimerAction)
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from ato_nodes.core.config.scenario import prepare, resolve_scenario, ros_parameter_file
from ato_nodes.core.config.schema import NODES
from ato_nodes.launcher.launch import EXTERNAL_CONTRACT, EXTERNAL_ROLES, external_arguments
from ato_nodes.launcher.nodefork import STOP_GRACE  # s the other nodes have after the supervisor


def nodes(context):
    scenario = LaunchConfiguration("scenario").perform(context)
    path = resolve_scenario(scenario).resolve()  # a name, or a file
    out = LaunchConfiguration("out").perform(context) or f"bags/{path.stem}-launch"
    report = LaunchConfiguration("report").perform(context)
    run_parameters = {"recorder.output": str(Path(out).resolve()), "supervisor.report": report}
    # the scenario resolved (its base, its derived values, which a node cannot derive
    # itself) as the parameter file run_stack.py writes: rcl knows no `base:`
    resolved = Path(tempfile.mkdtemp(prefix="ato_nodes-launch-")) / path.name
    resolved.write_text(yaml.safe_dump(ros_parameter_file(prepare(str(path))), sort_keys=False))
    external = [role for role in EXTERNAL_ROLES
                if LaunchConfiguration(role).perform(context) == "external"]
    started = [role for role in NODES if role not in external]
    launched = [Node(package="ato_nodes", executable=role, name=role, output="screen",
                     parameters=[str(resolved), {name: value for name, value in
                                                 run_parameters.items()
                                                 if name.startswith(role)}])
                for role in started]
    said = [LogInfo(msg=f"the {role} is yours: start it with "
                        f"{' '.join(external_arguments(role, resolved))} ({EXTERNAL_CONTRACT})")
            for role in external]
    # A Shutdown as soon as the supervisor exits would SIGINT nodes that are already
    # exiting on its 'shutdown' (launch then reports them as died, exit code -2): the
    # launch ends by itself once every node has exited; the grace timer is the fallback.
    running = set(started)
    grace = TimerAction(period=STOP_GRACE, actions=[EmitEvent(event=Shutdown(
        reason=f"a node still ran {STOP_GRACE:g} s after the supervisor ended the run"))])

    def exited(event, context):
        role = event.action.node_executable
        running.discard(role)
        if event.returncode != 0 and not context.is_shutdown:
            reason = f"{role} exited with status {event.returncode}"
            return [EmitEvent(event=Shutdown(reason=reason))]
        if not running:
            grace.cancel()
        elif role == "supervisor":
            return [grace]
        return None

    return [*said, *launched, RegisterEventHandler(OnProcessExit(on_exit=exited))]


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription([
        DeclareLaunchArgument("scenario", default_value="seed000",
                              description="a shipped scenario's name or a scenario file"),
        DeclareLaunchArgument("out", default_value="",
                              description="bag directory to create (default "
                                          "bags/<scenario>-launch)"),
        DeclareLaunchArgument("report", default_value="",
                              description="path of the supervisor's JSON run report"),
        *(DeclareLaunchArgument(role, default_value="ato_nodes", choices=["ato_nodes", "external"],
                                description=f"external: a node of your own is the {role}")
          for role in EXTERNAL_ROLES),
        OpaqueFunction(function=nodes),
    ])
