"""What the rail gives: the wheel-rail adhesion's limit on the train's force, and the
wheel-slide (and anti-slip) protection's answer when a force asks for more, ROS-free.

The adhesion coefficient mu(v) of a rail condition is Curtius and Kniffler's curve
scaled (docs/localisation.md has the sources):

    mu(v) = factor * (0.161 + 7.5 / (3.6 v + 44)),   v in m/s

factor 1 on dry rail (0.33 at standstill, 0.22 at 80 km/h), ADHESION_FACTORS' on wet and
contaminated rail, times plant.adhesion_scale (a run's own draw of the condition). The
force it allows, in N/kN of the train's weight (the plant's specific force):

    traction  <= mu(v) * motored_share * 1000   (the weight on the motored axles)
    braking   <= mu(v) * braked_share * 1000    (the brake blended over every braked axle)

A demanded force past its limit makes the wheels slip (traction) or slide (braking): the
protection releases and reapplies, and the force the rail gives is then its limit
times the protection's efficiency (the release-reapply cycles lose a share of the
adhesion), the wheels turning at the protection's creep (slower than the train under a
slide, faster under a slip) until the demand falls back under the limit.
"""

from __future__ import annotations

from typing import NamedTuple

from ..base.kernels import jitable
from ..base.spec import PLANT_NODES, param

# The conditions a run's rail may have: Curtius-Kniffler's dry-rail curve times this.
ADHESION_FACTORS = {"dry": 1.0, "wet": 0.5, "contaminated": 0.2}
CONDITIONS = ("unlimited", *ADHESION_FACTORS)  # plant.adhesion's choices

PARAMETERS = (
    param("plant.adhesion", "unlimited", "the rail's condition: dry, wet or contaminated "
          "(leaves, grease) limit the force the wheels can pass to it (unlimited: any force, "
          "the papers' setting)", "plant", choices=CONDITIONS),
    param("plant.adhesion_scale", 1.0, "the run's adhesion over its condition's curve (a "
          "study's draw of how wet or dirty)", "plant", 0.05, 3.0),
    param("plant.motored_share", 1.0, "the share of the train's weight on motored axles: "
          "traction's adhesive weight (a train preset's, e.g. 4 of 6 cars motored)",
          PLANT_NODES, 0.01, 1.0),
    param("plant.braked_share", 1.0, "the share of the train's weight on braked axles: "
          "braking's adhesive weight", PLANT_NODES, 0.01, 1.0),
    param("plant.wsp_efficiency", 0.8, "the force the rail gives while the wheels slide or "
          "slip, over its limit: what the protection's release and reapply cycles keep", "plant",
          0.1, 1.0),
    param("plant.wsp_creep", 0.15, "the wheels' speed off the train's while the protection "
          "controls a slide or a slip, relative", "plant", 0.0, 0.9),
)


class Adhesion(NamedTuple):
    """What the rail gives a train (the plant's; TrainConstants.adhesion)."""

    limited: bool             # false: any force (plant.adhesion "unlimited")
    factor: float             # the condition's factor times plant.adhesion_scale
    motored_share: float      # of the weight on the motored axles (traction)
    braked_share: float       # of the weight on the braked axles (braking)
    efficiency: float         # the force given while slipping or sliding, over the limit
    creep: float              # the wheels' speed over the train's, less 1, while slipping


UNLIMITED = Adhesion(False, 0.0, 1.0, 1.0, 1.0, 0.0)


def adhesion_of(values) -> Adhesion:
    """The run's Adhesion from its plant.adhesion* values."""
    condition = values["plant.adhesion"]
    if condition == "unlimited":
        return UNLIMITED
    return Adhesion(True, ADHESION_FACTORS[condition] * values["plant.adhesion_scale"],
                    values["plant.motored_share"], values["plant.braked_share"],
                    values["plant.wsp_efficiency"], values["plant.wsp_creep"])


@jitable
def adhesion_coefficient(v: float, factor: float) -> float:
    """mu at speed v (m/s): Curtius-Kniffler's curve times `factor`."""
    speed = v if v >= 0.0 else -v
    return factor * (0.161 + 7.5 / (3.6 * speed + 44.0))


@jitable
def adhesion_limits(v: float, adhesion: Adhesion) -> tuple[float, float]:
    """(most negative, most positive) force the rail gives at v without a slide or a
    slip, N/kN."""
    mu = adhesion_coefficient(v, adhesion.factor) * 1000.0
    return -mu * adhesion.braked_share, mu * adhesion.motored_share


@jitable
def adhered(force: float, v: float, adhesion: Adhesion) -> float:
    """The force the rail gives for a demanded `force` at v (N/kN): the demand within
    the limits, else the limit times the protection's efficiency."""
    if not adhesion.limited:
        return force
    low, high = adhesion_limits(v, adhesion)
    if force < low:
        return low * adhesion.efficiency
    if force > high:
        return high * adhesion.efficiency
    return force


@jitable
def wheel_creep(force: float, v: float, adhesion: Adhesion) -> float:
    """The wheels' speed over the train's, less 1, under a demanded `force` at v: the
    protection's creep while they slip (+) or slide (-), 0 when they roll."""
    if not adhesion.limited:
        return 0.0
    low, high = adhesion_limits(v, adhesion)
    if force < low:
        return -adhesion.creep
    if force > high:
        return adhesion.creep
    return 0.0
