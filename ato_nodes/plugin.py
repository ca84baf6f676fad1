"""What a plug-in needs to add a controller or target-profile kind from outside the
package, in one import (docs/plugins.md; examples/ato-smc/ is a worked example).

A plug-in module declares `PLUGIN_API` (the version of this interface it is written
for; another is refused) and `COMPONENTS`, its kinds, each a Component with its `role`:

    from ato_nodes.plugin import Component, Output, param
    PLUGIN_API = 1
    COMPONENTS = (Component("smc", "sliding-mode speed control", PARAMETERS, factory,
                            OUTPUTS, steps=SMC_STEPS, role="controller"),)

A controller kind's parameters are `KIND.*`, declared by CONTROLLER_NODES; a profile
kind's `profile.KIND.*`, declared by PROFILE_NODES. Its factory(values, context, limiter)
returns a Controller; to run compiled, its start and step are `jitable` functions of
NamedTuples (ControllerSteps) that SteppedController runs in Python:

    start(settings, state, target, measured, horizon) -> state
    step(settings, state, target, measured, horizon, last, limits) -> (u, outputs, state)

`target` is r_k, `horizon` r_k .. r_k+N (controller.preview = N), `last` and `limits`
what limit_command() takes, `outputs` the kind's declared outputs in order. The
`context` holds the run's period (context.period) and the nominal train
(context.train.constants(): TrainConstants, with basic_resistance for its Davis
resistance). A run names its plug-ins (a scenario's `plugins: [my_pkg.smc]`, the
commands' `--plugin my_pkg.smc`) or an installed package declares them as entry points
(groups `ato_nodes.controllers`, `ato_nodes.profiles`); load() imports them here (a
script that imports its plug-in before anything of ato_nodes calls it before it reads the
registries; a run's check does it anyway).
"""

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.base.kernels import jitable
from ato_nodes.core.base.registry import (PLUGIN_API, Component, Controller, ControllerOutput,
                                          Output, Plan)
from ato_nodes.core.base.spec import PROFILE_NODES, ParamSpec, param, settings
from ato_nodes.core.config.components import CONTROLLERS
from ato_nodes.core.config.plugins import ENTRY_POINT_GROUPS
from ato_nodes.core.config.schema import load_plugins as load
from ato_nodes.core.control.limiter import CommandLimiter, LimiterSettings, limit_command
from ato_nodes.core.control.stepped import STATE_PATHS, ControllerSteps, SteppedController
from ato_nodes.core.train.plant import TrainConstants, basic_resistance

CONTROLLER_NODES = CONTROLLERS.nodes  # the nodes that declare a controller kind's parameters

__all__ = ["CONTROLLER_NODES", "ENTRY_POINT_GROUPS", "PLUGIN_API", "PROFILE_NODES",
           "CommandLimiter", "Component", "Controller", "ControllerOutput", "ControllerSteps",
           "LimiterSettings", "Output", "ParamSpec", "Plan", "STATE_PATHS", "ScenarioError",
           "SteppedController", "TrainConstants", "basic_resistance", "jitable",
           "limit_command", "load", "param", "settings"]
