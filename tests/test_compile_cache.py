"""The compiled loop's cache follows what changed (core/base/kernels.py): each signature's
machine code is keyed by the sources it is built from, the loop's modules and the
controller kind's, wherever the kind lives. A process finding them unchanged loads the
loop; an edited plug-in is compiled again (its new constant in the new bits), another
kind's signature stays cached, and a process without the plug-ins still reads the cache."""

import importlib
import json
import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

from ato_nodes.core.base import kernels
from ato_nodes.core.config.components import CONTROLLERS
from ato_nodes.core.run import fast_loop

PLUG_IN = '''"""A controller kind from outside the package: a gain on the error."""
from typing import NamedTuple

from ato_nodes.core.base.kernels import jitable
from ato_nodes.core.control.stepped import ControllerSteps, SteppedController

GAIN = 2.0


class GainState(NamedTuple):
    steps: int = 0


@jitable
def start(settings, state, target, measured, horizon=None):
    return state


@jitable
def step(settings, state, target, measured, horizon, last, limits):
    return GAIN * (1.0 + target - measured), (target,), GainState(state.steps + 1)


STEPS = ControllerSteps(start, step, GainState)


def factory(values, context, limiter):
    return SteppedController(STEPS, (), limiter)
'''

# Registers each plug-in module in place of a kind, runs a short seed000 run of it
# compiled and as Python, and prints what it ran and which kinds' loops were compiled.
RUNNER = '''import dataclasses, importlib, json, sys
from numba.core import event
from ato_nodes.core.base import kernels
from ato_nodes.core.config.components import CONTROLLERS
from ato_nodes.core.config.scenario import apply_overrides, load_scenario
from ato_nodes.core.config.schema import SPEC_BY_NAME
from ato_nodes.core.run import fast_loop
from ato_nodes.core.run.loop import simulate

class Compiled(event.Listener):
    kinds = []
    def on_start(self, compilation):
        if compilation.data["dispatcher"] is fast_loop._steps:
            self.kinds.append(kind)
    def on_end(self, compilation):
        pass

seed000, outcome = load_scenario("seed000"), {}
duration = max(2 * seed000["run.period"], SPEC_BY_NAME["run.duration"].low)
for kind, name in zip(sys.argv[1::2], sys.argv[2::2]):
    plug_in = importlib.import_module(name)
    CONTROLLERS.components[kind] = dataclasses.replace(
        CONTROLLERS[kind], factory=plug_in.factory, steps=plug_in.STEPS,
        outputs=CONTROLLERS[kind].outputs[:1], state_paths=())
    run = apply_overrides(seed000, {"run.duration": duration, "controller.kind": kind})
    with event.install_listener("numba:compile", Compiled()), kernels.announced():
        compiled = simulate(run)["command"]
    python = simulate(run, compiled=False)["command"]
    outcome[name] = {"command": compiled.tolist(), "as_python": bool((compiled == python).all())}
print(json.dumps({"ran": outcome, "compiled": Compiled.kinds}))
'''


# A short run of the shipped PID, compiled, in a process that has no plug-in.
SHIPPED = """from ato_nodes.core.config.scenario import apply_overrides, load_scenario
from ato_nodes.core.run.loop import simulate
simulate(apply_overrides(load_scenario("seed000"), ["controller.kind=pid", "run.duration=1"]))
"""


def run_plug_ins(directory: Path, cache: Path) -> tuple[dict, str]:
    """A new process running gain_a as the PID and gain_b as the discrete ADRC."""
    done = subprocess.run([sys.executable, str(directory / "runner.py"),
                           "pid", "gain_a", "discrete_adrc", "gain_b"],
                          capture_output=True, text=True, timeout=900, cwd=directory,
                          env={**os.environ, "NUMBA_CACHE_DIR": str(cache)})
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout), done.stderr


@pytest.mark.slow
@pytest.mark.skipif(not kernels.AVAILABLE, reason="numba is not installed")
def test_an_edited_plug_in_is_compiled_again_and_the_other_kind_stays_cached(tmp_path):
    cache = tmp_path / "cache"
    (tmp_path / "runner.py").write_text(RUNNER)
    (tmp_path / "gain_a.py").write_text(PLUG_IN)
    # (numba's dispatch tells two NamedTuple classes apart by name and fields only)
    (tmp_path / "gain_b.py").write_text(PLUG_IN.replace("GAIN = 2.0", "GAIN = 3.0")
                                        .replace("GainState", "OtherGainState"))
    cold, said = run_plug_ins(tmp_path, cache)
    assert cold["compiled"] == ["pid", "discrete_adrc"]
    assert "compiling the loop for controller pid (not in the cache) ..." in said
    warm, said = run_plug_ins(tmp_path, cache)
    assert warm == {"ran": cold["ran"], "compiled": []} and "compiling" not in said
    (tmp_path / "gain_a.py").write_text(PLUG_IN.replace("GAIN = 2.0", "GAIN = 5.0"))
    edited, said = run_plug_ins(tmp_path, cache)
    assert edited["compiled"] == ["pid"]
    assert "compiling the loop for controller pid (its sources changed) ..." in said
    assert edited["ran"]["gain_a"]["as_python"]  # the new constant, not the old machine code
    assert edited["ran"]["gain_a"]["command"] != cold["ran"]["gain_a"]["command"]
    assert edited["ran"]["gain_b"] == cold["ran"]["gain_b"]
    # gain_a's entry built from its old source was replaced: one per signature
    assert len(list(cache.rglob("fast_loop._steps_source.*.nbc"))) == 2
    # the index names the plug-ins' classes by text: a process without them reads it
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    shipped = subprocess.run([sys.executable, "-c", SHIPPED], capture_output=True, text=True,
                             timeout=900, cwd=elsewhere,
                             env={**os.environ, "NUMBA_CACHE_DIR": str(cache)})
    assert shipped.returncode == 0, shipped.stderr


def loop_signature(kind: str) -> tuple:
    """The loop's arguments as far as fast_loop._loop_sources reads them: the LoopState's
    controller state names the kind."""
    state = SimpleNamespace(instance_class=CONTROLLERS[kind].steps.state_type)
    loop = SimpleNamespace(instance_class=fast_loop.LoopState,
                           types=[state if field == "controller" else None
                                  for field in fast_loop.LoopState._fields])
    return (None, None, loop)


def built_from(kind: str) -> set[str]:
    sources = fast_loop._loop_sources(loop_signature(kind))
    modules = kernels._closure((fast_loop.__name__, *sources.modules), sources.apart)
    return {name.removeprefix("ato_nodes.core.") for name in modules}


def test_a_kinds_loop_is_built_from_its_own_modules_and_the_shared_ones_only():
    pid, gpc, adrc = built_from("pid"), built_from("gpc"), built_from("han_adrc")
    shared = {"run.fast_loop", "train.plant", "targets.horizons", "control.limiter"}
    assert shared <= pid & gpc & adrc
    assert "control.pid" in pid and not {"control.adrc", "control.gpc", "control.qp"} & pid
    assert {"control.gpc", "control.gpc_steps", "control.qp"} <= gpc and "control.pid" not in gpc
    assert "control.adrc" in adrc and not {"control.pid", "control.gpc"} & adrc
    assert "the loop for controller han_adrc, nladrc" == fast_loop._loop_sources(
        loop_signature("han_adrc")).what


def test_no_kind_takes_code_from_another_kinds_modules():
    """What the keys rely on: a kind's modules enter its own signatures only, so no shipped
    kind may import another kind's (shared formulas live in shared modules: limiter,
    train_model). A plug-in reaches the registry through ato_nodes.plugin: the loop's keys
    keep every other kind's modules apart from its signatures (fast_loop._loop_sources)."""
    kinds = {kind: fast_loop._modules_of(component)
             for kind, component in CONTROLLERS.shipped().components.items()}
    for kind, own in kinds.items():
        others = set().union(*kinds.values()) - own
        assert not set(kernels._closure(own, frozenset())) & others, kind


@pytest.fixture
def plug_ins(tmp_path, monkeypatch):
    """Modules written to tmp_path, imported by name (forgotten after the test)."""
    monkeypatch.syspath_prepend(str(tmp_path))
    names = []

    def imported(name: str, source: str):
        (tmp_path / f"{name}.py").write_text(source)
        names.append(name)
        return importlib.import_module(name)

    yield imported
    for name in names:
        sys.modules.pop(name, None)


def test_a_digest_follows_an_outside_modules_own_imports(tmp_path, plug_ins):
    plug_ins("plug_helper", "SCALE = 1.0\n")
    plug_ins("plug_a", "import numpy\nfrom plug_helper import SCALE\n")
    plug_ins("plug_b", "from ato_nodes.core.train import plant\n")
    a, b = kernels.sources_digest(["plug_a"]), kernels.sources_digest(["plug_b"])
    assert set(kernels._closure(["plug_a"], frozenset())) == {"plug_a", "plug_helper"}
    assert "ato_nodes.core.train.plant" in kernels._closure(["plug_b"], frozenset())
    (tmp_path / "plug_helper.py").write_text("SCALE = 1.25\n")
    assert kernels.sources_digest(["plug_a"]) != a and kernels.sources_digest(["plug_b"]) == b


@pytest.mark.skipif(not kernels.AVAILABLE, reason="numba is not installed")
def test_a_signatures_entry_from_newer_sources_replaces_its_older_one(tmp_path):
    index = kernels.SignatureIndex(str(tmp_path), "module.function-1.py311")
    index.save(("(pid)", "cpu", "code", "sources 1"), "machine code 1")
    index.save(("(adrc)", "cpu", "code", "sources 1"), "machine code 2")
    index.save(("(pid)", "cpu", "code", "sources 2"), "machine code 3")
    assert index.load(("(pid)", "cpu", "code", "sources 2")) == "machine code 3"
    assert index.load(("(pid)", "cpu", "code", "sources 1")) is None
    assert index.load(("(adrc)", "cpu", "code", "sources 1")) == "machine code 2"
    assert index.holds("(pid)") and not index.holds("(gpc)")
    assert len(list(tmp_path.glob("*.nbc"))) == 2


@pytest.mark.skipif(not kernels.AVAILABLE, reason="numba is not installed")
def test_the_cache_files_are_named_without_the_functions_first_line():
    """numba names them by it: an edit above the function would leave them behind."""
    impl = kernels.SourcesCacheImpl(fast_loop._steps_source)
    assert impl.filename_base == f"fast_loop._steps_source.py{sys.version_info[0]}" \
        f"{sys.version_info[1]}{sys.abiflags}"
