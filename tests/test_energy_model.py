"""The energy model: regenerative braking up to the train's regenerative force and power,
the rest pneumatic; traction and regeneration each through its efficiency. Numbers
worked by hand."""

import numpy as np
import pytest

from ato_nodes.core.base.paths import config_dir
from ato_nodes.core.config.schema import defaults
from ato_nodes.core.run.scoring import energy_terms
from ato_nodes.core.scoring.operation import Regeneration, operation_indices
from ato_nodes.core.train.ttobench import load_train

T = np.linspace(0.0, 100.0, 1001)


def braking(force: float, speed: float = 20.0) -> dict:
    zeros = np.zeros_like(T)
    return {"t": T, "position": zeros, "speed": np.full_like(T, speed),
            "acceleration": zeros, "force": np.full_like(T, force)}


def test_the_regenerative_force_and_power_cap_what_is_regenerated():
    """-5 N/kN on 400 t brakes with 5 x 400 x 9.8 / 1000 = 19.6 kN; at 20 m/s for 100 s.
    F_r = 10 kN: the drive brakes 10 kN electrically, 10 x 20 = 200 kW, 20,000 kJ, of
    which eta_r = 0.7 returns 14,000 kJ = 3.8889 kWh (the other 9.6 kN pneumatic).
    P_r = 150 kW as well: 150 kW for 100 s = 15,000 kJ, x 0.7 = 2.9167 kWh.
    No limits: 19.6 x 20 = 392 kW, 39,200 kJ x 0.7 = 7.6222 kWh."""
    series = braking(-5.0)
    force_only = operation_indices(series, mass=400.0, regeneration=Regeneration(
        10.0, float("inf"), 0.7))
    assert force_only["regenerated_energy_kwh"] == pytest.approx(14000.0 / 3600.0)
    assert force_only["net_energy_kwh"] == pytest.approx(-14000.0 / 3600.0)
    both = operation_indices(series, mass=400.0, regeneration=Regeneration(10.0, 150.0, 0.7))
    assert both["regenerated_energy_kwh"] == pytest.approx(15000.0 * 0.7 / 3600.0)
    unlimited = operation_indices(series, mass=400.0, efficiency=0.8,
                                  regeneration=Regeneration(efficiency=0.7))
    assert unlimited["regenerated_energy_kwh"] == pytest.approx(39200.0 * 0.7 / 3600.0)


def test_traction_and_regeneration_have_each_their_efficiency():
    """+10 N/kN on 400 t at 20 m/s for 100 s: 39.2 x 20 x 100 = 78,400 kJ at the wheel,
    78,400 / 0.8 = 98,000 kJ at the pantograph; no braking, nothing regenerated."""
    zeros = np.zeros_like(T)
    series = {**braking(10.0), "acceleration": zeros}
    result = operation_indices(series, mass=400.0, efficiency=0.8,
                               regeneration=Regeneration(10.0, 150.0, 0.5))
    assert result["traction_energy_kwh"] == pytest.approx(98000.0 / 3600.0)
    assert result["regenerated_energy_kwh"] == 0.0


def test_the_real_mass_sets_the_braking_force_in_kn():
    """The run's mass is the nominal times plant.mass_factor: 200 t x 1.5 = 300 t; -5 N/kN
    is then 14.7 kN, beyond F_r = 10 kN: 10 kN x 20 m/s x 100 s x 0.9 = 18,000 kJ. At the
    nominal 200 t it would be 9.8 kN, all of it regenerative (17,640 kJ)."""
    parameters = {**defaults(), "plant.mass": 200.0, "plant.mass_factor": 1.5,
                  "plant.regenerative_limits": True, "plant.regenerative_force": 10.0}
    terms = energy_terms(parameters)
    assert terms["mass"] == 300.0 and terms["regeneration"] == Regeneration(10.0, 12000.0)
    result = operation_indices(braking(-5.0), **terms)
    assert result["regenerated_energy_kwh"] == pytest.approx(18000.0 / 3600.0)


def test_the_defaults_are_the_model_without_limits():
    """The schema's defaults regenerate all braking at plant.efficiency, bit for bit as a
    run scored without the regenerative terms (a bag recorded before them)."""
    assert Regeneration.of(defaults()) == Regeneration()
    assert Regeneration.of({}) == Regeneration()
    rng = np.random.default_rng(3)
    series = {**braking(0.0), "speed": rng.uniform(0.0, 25.0, len(T)),
              "force": rng.uniform(-30.0, 30.0, len(T))}
    scored = operation_indices(series, mass=400.0, efficiency=0.85,
                               regeneration=Regeneration.of(defaults()))
    braking_kw = np.maximum(-series["force"] * 400.0 * 9.8 / 1000.0, 0.0) * series["speed"]
    assert scored["regenerated_energy_kwh"] == float(np.trapezoid(braking_kw, T)) * 0.85 / 3600.0


def test_a_ttobench_train_sets_the_regenerative_terms():
    """CH_Stadler_FLIRT_TPF: max reg braking force 200 kN, power 2600 kW, efficiency reg
    brake 90 %."""
    train = load_train(config_dir() / "ttobench" / "trains" / "CH_Stadler_FLIRT_TPF.json")
    values = train.plant_values(9.8)
    assert values["plant.regenerative_limits"] is True
    assert values["plant.regenerative_force"] == pytest.approx(200.0)
    assert values["plant.regenerative_power"] == pytest.approx(2600.0)
    assert values["plant.regenerative_efficiency"] == pytest.approx(0.9)
    assert Regeneration.of(values) == pytest.approx((200.0, 2600.0, 0.9))
