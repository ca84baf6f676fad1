"""The sliding-mode speed controller kind `smc` for ato_nodes, as a plug-in: its
parameters smc.*, named outputs and compiled steps (law.py), registered through the
entry point `smc` of the group ato_nodes.controllers (pyproject.toml), or named in a run
(`plugins: [ato_smc]`, `--plugin ato_smc`)."""

from ato_nodes.plugin import STATE_PATHS, Component, Output, SteppedController

from .law import PARAMETERS, SMC_STEPS, SMCState, smc_settings

PLUGIN_API = 1

OUTPUTS = (
    Output("sliding_surface", "m/s", "s = e + lambda * integral(e)"),
    Output("feedforward", "N/kN", "nominal-model feedforward"),
    Output("equivalent", "N/kN", "equivalent term lambda * e / xi"),
    Output("switching", "N/kN", "switching term k * sat(s / phi)"),
)


def _smc(values, context, limiter) -> SteppedController:
    return SteppedController(SMC_STEPS, smc_settings(values, context.period,
                                                     context.train.constants()),
                             limiter, SMCState(0.0))


SMC = Component(
    "smc", "sliding-mode control: s = e + lambda * integral(e), boundary-layer saturation, "
    "nominal-model feedforward (a plug-in: ato_smc)", PARAMETERS, _smc, OUTPUTS,
    search_space=(("smc.integral_weight", 0.0, 2.0), ("smc.gain", 0.0, 500.0),
                  ("smc.boundary", 0.01, 2.0), ("smc.feedforward", 0.0, 1.5)),
    state_paths=STATE_PATHS, steps=SMC_STEPS, role="controller")

COMPONENTS = (SMC,)
