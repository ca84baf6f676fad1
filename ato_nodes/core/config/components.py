"""The registered controllers and target profiles: add a kind here (one line) and in
its own module (its parameters, its factory, its outputs); nothing else changes. Kinds
from outside the package join them as plug-ins (core/config/plugins.py)."""

from __future__ import annotations

from ..base.registry import Registry
from ..base.spec import PROFILE_NODES
from ..control import adrc, gpc, pid
from ..targets import profiles, served

CONTROLLERS = Registry("controller", "han_adrc", ("controller",), (
    adrc.HAN_ADRC, adrc.NLADRC, adrc.DISCRETE_ADRC, adrc.LINEAR_ADRC,
    pid.PID_CONTROLLER, gpc.GPC_CONTROLLER,
))

PROFILES = Registry("profile", "seed000", PROFILE_NODES, (
    profiles.SEED000, profiles.STEP, profiles.TABLE, profiles.ATO, profiles.STRATEGY,
    served.JOURNEY,
))

# By role: a plug-in's kind joins the registry its Component's `role` names
# (core/config/plugins.py).
REGISTRIES = {registry.role: registry for registry in (CONTROLLERS, PROFILES)}
