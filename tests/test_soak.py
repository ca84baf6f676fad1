"""scripts/soak.py's landing logic, without the stack: the progress it reads from a bag
being written, the steps it aims at for each phase and the phase it reads a landing in."""

import random
import signal
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def soak():
    """scripts/soak.py as a module; the signal handlers its scripts' prelude installs
    (a Ctrl-C while a script starts exits at once) are pytest's again after the import."""
    handlers = {number: signal.getsignal(number) for number in (signal.SIGINT, signal.SIGPIPE)}
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        import soak
    finally:
        sys.path.remove(str(ROOT / "scripts"))
        for number, handler in handlers.items():
            signal.signal(number, handler)
    return soak


def written_bag(bag: Path, steps: int, block: int, period_ns: int) -> bytes:
    """A bag written as the recorder writes one (ato_nodes.bags.bagwrite, a chunk closed and
    flushed every `block` steps); its MCAP file's bytes."""
    from rosbags.typesys import Stores, get_typestore
    from rosbags.typesys.stores.ros2_jazzy import std_msgs__msg__Float64 as Float64

    from ato_nodes.bags.bagwrite import close_writer, open_writer
    typestore = get_typestore(Stores.ROS2_JAZZY)
    writer = open_writer(bag)
    connections = [writer.add_connection(name, Float64.__msgtype__, typestore=typestore)
                   for name in ("/a", "/b")]
    writer.storage.close_chunk()  # the topics on disk before any step, as the recorder does
    for k in range(steps):
        for connection in connections:
            writer.write(connection, k * period_ns,
                         typestore.serialize_cdr(Float64(data=float(k)), Float64.__msgtype__))
        if (k + 1) % block == 0:
            writer.storage.close_chunk()
            writer.storage.bio.flush()
    close_writer(writer, bag)
    (mcap_file,) = bag.glob("*.mcap")
    return mcap_file.read_bytes()


def test_progress_is_what_whole_chunks_on_disk_hold(soak, tmp_path):
    """Read as the file grows, the progress is the steps up to the latest message of the
    chunks wholly on disk (as mcap's own index says), never a chunk still being written."""
    from mcap.reader import make_reader
    period_ns, steps = 100_000_000, 47
    data = written_bag(tmp_path / "done", steps, block=5, period_ns=period_ns)
    with next((tmp_path / "done").glob("*.mcap")).open("rb") as handle:
        chunks = make_reader(handle).get_summary().chunk_indexes
    growing = tmp_path / "growing"
    growing.mkdir()
    progress = soak.BagProgress(growing, period_ns * 1e-9)
    assert progress.steps() == 0  # no file yet
    seen, written = [], 0
    with (growing / "growing.mcap").open("wb") as handle:
        for cut in [*range(0, len(data), 97), len(data)]:
            handle.write(data[written:cut])
            handle.flush()
            written = cut
            whole = [chunk.message_end_time for chunk in chunks
                     if chunk.chunk_start_offset + chunk.chunk_length <= cut
                     and chunk.message_start_time <= chunk.message_end_time]
            expected = round(max(whole) / period_ns) + 1 if whole else 0
            seen.append(progress.steps())
            assert seen[-1] == expected, cut
    assert seen == sorted(seen) and seen[-1] == steps
    progress.close()


def journey_like(soak):
    """A run of 1000 steps: the train stands at a stop from step 300 to 499 and re-plans
    as it leaves at 500."""
    standing = np.zeros(1000, dtype=bool)
    standing[300:500] = True
    return soak.Reference(period=0.1, total=1000, standing=standing,
                          replans=[{"step": 500}], window=20, first=10, margin=50, lag=10)


def test_each_phase_aims_inside_itself(soak):
    """Every step a phase may aim at reads as that phase, and a dwell's aims are a
    window deep inside it: a landing a little early or late is still in the dwell."""
    ref = journey_like(soak)
    for aim in ("stepping", "dwell", "re-plan"):
        steps = ref.candidates(aim)
        assert steps and all(ref.phase(k) == aim for k in steps), aim
    assert all(ref.standing[k - 20:k + 21].all() for k in ref.candidates("dwell"))
    stepping = ref.candidates("stepping")
    assert min(stepping) >= ref.first and max(stepping) < ref.total - ref.margin
    assert ref.phase(ref.total) == "after end" and ref.phase(521) == "stepping"


def test_draws_cover_the_kinds_and_phases_and_repeat_for_a_seed(soak):
    ref = journey_like(soak)
    counts = {"sigint": 30, "double": 5, "sigkill": 5}
    made = soak.draws(counts, 3, ref, random.Random(7))
    assert made == soak.draws(counts, 3, ref, random.Random(7))
    assert [draw.kind for draw in made].count("sigint") == 33
    for kind, count in counts.items():  # as many of a kind aim at each phase
        aims = [draw.aim for draw in made if draw.kind == kind and draw.target is not None]
        assert len(aims) == count
        assert {aim: aims.count(aim) for aim in ("stepping", "dwell", "re-plan")} == \
            {aim: (count + 2 - turn) // 3 for turn, aim in enumerate(("stepping", "dwell",
                                                                      "re-plan"))}, kind
    assert all((draw.target is None) == (draw.aim == "after end") for draw in made)
    assert {draw.victim for draw in made if draw.kind == "sigkill"} <= set(soak.NODES)
    cruise = soak.Reference(period=0.05, total=400, standing=np.zeros(400, dtype=bool),
                            replans=[], window=40, first=20, margin=80, lag=20)
    assert {draw.aim for draw in soak.draws(counts, 0, cruise, random.Random(7))} == \
        {"stepping"}


class Bag:
    def __init__(self, steps: int, closed: bool):
        self._steps, self._closed = steps, closed

    def steps(self) -> int:
        return self._steps

    def closed(self) -> bool:
        return self._closed


def test_a_signal_is_due_at_its_step_or_once_the_run_is_over(soak):
    launcher = 1  # has no node processes of a run
    assert not soak.due(Bag(89, False), 90, launcher)
    assert soak.due(Bag(90, False), 90, launcher)
    assert soak.due(Bag(40, True), 90, launcher)  # over before its step: sent, after the end
    assert not soak.due(Bag(400, False), None, launcher)  # after the end: not before it
    assert soak.due(Bag(400, True), None, launcher)


def test_no_signal_goes_before_the_bag_holds_a_step(soak):
    assert soak.trigger_step(500, 30) == 470
    assert soak.trigger_step(24, 30) == 1 and soak.trigger_step(0, 0) == 1


def test_leads_start_at_the_record_lag_then_follow_the_landings(soak):
    leads = soak.Leads(10)
    assert leads.steps("sigint") == 10
    for overshoot in (4, 30, 6, -3):
        leads.add("sigint", overshoot)
    assert leads.steps("sigint") == 5 and leads.steps("sigkill") == 10
