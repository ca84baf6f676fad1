"""profile.berth: a train standing still within it of the stop mark has arrived."""

import numpy as np
import pytest

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import prepare
from ato_nodes.core.config.schema import NodeValues
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.run.scoring import score_series
from ato_nodes.core.run.stages import ProfileStage
from ato_nodes.core.targets.horizons import has_arrived

# A metro train with a slow actuator (lag 1.22) and the on-board estimator: it stops 7.3 cm
# short of the mark at 164.4 s, on time, and creeps on for 3.2 s (to 1.7 cm) without a berth.
CREEPING = ("plant.mass_factor=1.023364659182611", "plant.resistance_factor=1.167200766910856",
            "plant.lag_factor=1.2216867448341637", "plant.noise_seed=354096443",
            "train.load_weighing_seed=340331917", "estimator.enabled=true",
            "profile.departure_jerk=0",  # the departure this train was found creeping with
            # on the true position, as it was found (not the ato-on-board preset's)
            "odometry.enabled=false", "profile.replan.enabled=false", "estimator.lag_sigma=0",
            "estimator.gate=0")


@pytest.mark.parametrize("k, travel, position, expected", [
    (5, 0.0, 99.95, True), (5, 0.0, 100.05, True),   # standing short of the mark or past it
    (5, 0.0, 99.85, False), (5, 1e-6, 99.95, False),  # too far, or still moving
    (0, 0.0, 99.95, False)])                           # the first step is no standstill
def test_a_train_has_arrived_standing_within_the_berth(k, travel, position, expected):
    assert has_arrived(k, travel, position, 100.0, 0.1) == expected
    assert not has_arrived(k, travel, position, float("nan"), 0.1)  # no berth


def test_the_profile_publishes_a_zero_target_once_the_train_stands_in_its_berth():
    # the stage's first steps, near the mark: no departure ramp holding them at 0
    values = prepare("seed004-metro-ato", ["profile.berth=0.1", "profile.departure_jerk=0"])
    stage = ProfileStage(NodeValues("profile", values))
    mark = stage.settings.berth_mark
    stage.on_position(mark - 0.07)
    moving = stage.on_position(mark - 0.06)  # still moving into the berth: the plan's
    assert moving[0][0] > 0.0
    zero = [[0.0] * (values["controller.preview"] + 1)]
    assert stage.on_position(mark - 0.06) == zero
    assert stage.on_position(mark - 0.0599) == zero  # arrived for good: a hair's creep after
    far = ProfileStage(NodeValues("profile", values))
    far.on_position(mark - 0.5)
    assert far.on_position(mark - 0.5)[0][0] > 0.0  # standing short of the berth: the plan's


@pytest.mark.slow
def test_a_train_stopped_short_in_its_berth_stays_there_and_arrives_then():
    creeping = simulate(prepare("seed004-metro-ato", [*CREEPING, "profile.berth=0"]))
    values = prepare("seed004-metro-ato", [*CREEPING, "profile.berth=0.1"])
    berthed = simulate(values)
    late, on_time = (score_series(run, values) for run in (creeping, berthed))
    first_stop = np.flatnonzero(berthed["speed"] == 0.0)
    first_stop = first_stop[first_stop > 100][0]
    assert np.ptp(berthed["position"][first_stop:]) < 1e-3  # the commands still in the
    assert np.all(berthed["target"][first_stop + 3:] == 0.0)  # pipeline move it a hair
    assert on_time["arrival_time"] < late["arrival_time"] - 2.0
    assert abs(on_time["stopping_error"]) < 0.1


@pytest.mark.parametrize("scenario", ["seed004-metro-line", "seed000"])
def test_a_berth_without_a_stop_to_berth_at_is_refused(scenario):
    with pytest.raises(ScenarioError, match="profile.berth"):
        prepare(scenario, ["profile.berth=0.1"])
