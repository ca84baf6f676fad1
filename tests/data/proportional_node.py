"""A controller node of a user's with a gain of its own: u = gain (r_k - y_k) plus the
basic resistance at r_k, the gain declared with its range (tune.py --external tunes it)."""

from ato_nodes.core.train.plant import basic_resistance
from ato_nodes.nodes.external import run_controller


class Proportional:
    def __init__(self, parameters: dict):
        self.gain = parameters["gain"]
        self.davis = [parameters[f"plant.davis_{c}"] for c in "abc"]

    def step(self, target, measured, horizon):
        error = target - measured
        return self.gain * error + basic_resistance(target, *self.davis), (error,)

    def retune(self, changes: dict) -> None:
        self.gain = changes.get("gain", self.gain)


if __name__ == "__main__":
    run_controller(Proportional, outputs=("error",),
                   own=[("gain", 50.0, "N/kN per m/s", 1.0, 200.0)], name="proportional")
