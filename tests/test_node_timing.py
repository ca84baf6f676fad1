"""The nodes' timing of their loop ($ATO_NODE_TIMING, nodes/timing.py) without a run:
run events of different nodes arrive in no fixed order."""

import json
from types import SimpleNamespace

from ato_nodes.nodes.timing import _NodeTiming


def event(text: str) -> SimpleNamespace:
    return SimpleNamespace(data=text)


def test_a_start_heard_after_finished_leaves_the_loop_from_the_first_step(tmp_path):
    timing = _NodeTiming("recorder", str(tmp_path))
    work = timing.part("handle /plant/speed")
    events = timing.noting_the_loop(lambda msg: None)
    step = timing.noting_a_step(lambda msg: sum(range(200_000)))
    for _ in range(3):
        step(event("0.0"))
        work[2] += 1
    events(event("finished 3"))
    events(event("start"))  # delivered late
    timing.write()
    figure = json.loads((tmp_path / "recorder.json").read_text())
    assert figure["steps"] == 3 and figure["process_cpu_ns"] > 0
    assert figure["parts"]["handle /plant/speed"][2] == 3


def test_a_start_heard_first_starts_the_loop():
    timing = _NodeTiming("plant", "unused")
    events, step = timing.noting_the_loop(lambda msg: None), timing.noting_a_step(
        lambda msg: None)
    events(event("start"))
    started = timing.loop["start"]
    step(event("0.0"))
    assert timing.loop["start"] is started
