#!/usr/bin/env python3
"""The sha256 of every series of every shipped scenario (or those named), for a slice of
each run: the check that a change which should leave behaviour alone did.

    python scripts/fingerprint.py --duration 300 --out before.json
    python scripts/fingerprint.py --duration 300 --compare before.json
    python scripts/fingerprint.py --stack --duration 300 --compare before.json
    python scripts/fingerprint.py --whole --python --compare before-whole.json

In-process by default (simulate(), compiled where the compiled loop covers the run);
--stack runs each scenario through the nodes and hashes the series its bag holds
(all but t: the bag's times are its nanosecond stamps, in-process t is k * period);
--python runs in-process uncompiled (simulate(compiled=False)). --whole runs each
scenario over its own run.duration (a journey to its last stop) instead of --duration.
--out FILE is checked before the first run and rewritten as each scenario is done, so a
failed or interrupted fingerprint keeps what it computed. --compare FILE (what --out
writes: scenario -> series -> sha256) prints each scenario's series that differ from
FILE's, or that FILE has and the run no longer does, and exits 1 if any does.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import sys
import tempfile
from pathlib import Path

import _cli
import numpy as np

from ato_nodes.core.base import yamlfile
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.config.scenario import apply_overrides, load_scenario, scenario_names

SHA256 = re.compile(r"[0-9a-f]{64}")
SAVED_SET_BYTES = 16 << 20  # every shipped scenario's digests take some 40 kB


def digests(series: dict[str, np.ndarray]) -> dict[str, str]:
    return {name: hashlib.sha256(np.ascontiguousarray(values, dtype=float).tobytes()).hexdigest()
            for name, values in sorted(series.items())}


def stack_series(values: dict, bag: Path) -> dict[str, np.ndarray]:
    from ato_nodes.bags.bagio import read_run
    from ato_nodes.launcher.launch import Stack
    outcome = Stack(values, bag, quiet=True).run()
    if not outcome.ok:
        _cli.fail(f"{bag}: {outcome.message}", 1)
    return {name: values for name, values in read_run(bag).series.items() if name != "t"}


def saved_set(path: Path) -> dict[str, dict[str, str]]:
    """--compare's file: a non-empty mapping of scenario -> non-empty mapping of series ->
    sha256 (hex), as --out writes it; ScenarioError (one line) for anything else."""
    text = yamlfile.read_text(path, "--compare", SAVED_SET_BYTES)  # bounded: not /dev/zero
    try:
        document = json.loads(text)
    except ValueError as exc:
        raise ScenarioError(f"--compare {path}: not JSON: {exc}") from None
    expected = "a saved set is a mapping of scenario -> series -> sha256, as --out writes it"
    if not isinstance(document, dict) or not document:
        raise ScenarioError(f"--compare {path}: {expected}, not {_kind(document)}")
    for scenario, entry in document.items():
        if not isinstance(entry, dict) or not entry:
            raise ScenarioError(f"--compare {path}: scenario {scenario[:80]!r} is "
                                f"{_kind(entry)}; {expected}")
        for series, digest in entry.items():
            if not (isinstance(digest, str) and SHA256.fullmatch(digest)):
                raise ScenarioError(f"--compare {path}: {scenario[:80]!r}: series "
                                    f"{series[:80]!r} is not a sha256 (64 hex digits); {expected}")
    return document


def _kind(value) -> str:
    """What a JSON value is, in words."""
    if isinstance(value, dict | list | str) and not value:
        return f"an empty {'mapping' if isinstance(value, dict) else type(value).__name__}"
    kinds = {dict: "a mapping", list: "a list", str: "a string", bool: "true or false",
             type(None): "null"}
    return kinds.get(type(value), "a number")


def check_writable(path: Path) -> None:
    """--out before any run: a regular file (left as it is) or none yet, in a directory
    that lets us create a file (made and removed again); else one line, exit 2."""
    if path.is_dir():
        _cli.fail(f"--out {path} is a directory; give the file to write")
    if path.exists() and not path.is_file():
        _cli.fail(f"--out {path} is not a regular file; give the file to write")
    if not path.parent.is_dir():
        _cli.fail(f"--out {path}: {path.parent} is not a directory")
    try:  # as write_digests() writes: a new file beside it, replacing it
        descriptor, probe = tempfile.mkstemp(dir=path.resolve().parent,
                                             prefix=f".{path.name}.")
        os.close(descriptor)
        os.unlink(probe)
    except OSError as exc:
        _cli.fail(f"--out {path}: cannot be written: {exc.strerror or exc}")


def write_digests(path: Path, result: dict) -> None:
    """All digests so far to `path`, replaced whole (never half written); when that fails,
    one line and the digests on stdout, exit 1: computed results are not lost."""
    text = json.dumps(result, indent=1, sort_keys=True) + "\n"
    target = path.resolve()  # through a symbolic link, not replacing it
    temporary = None
    try:
        descriptor, temporary = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.")
        umask = os.umask(0)
        os.umask(umask)
        os.fchmod(descriptor, 0o666 & ~umask)  # as a file written in place would be
        with os.fdopen(descriptor, "w") as file:
            file.write(text)
        os.replace(temporary, target)
    except OSError as exc:
        if temporary is not None:
            Path(temporary).unlink(missing_ok=True)
        print(text, end="", flush=True)
        _cli.fail(f"--out {path}: cannot be written ({exc.strerror or exc}); the digests "
                  f"computed are on stdout above", 1)


def compared(name: str, digests_now: dict[str, str], saved: dict[str, str]) -> bool:
    """Print how scenario `name`'s digests compare with its saved ones; True when they
    match: at least one series in common, none changed, none of the saved ones gone."""
    changed = [s for s, digest in digests_now.items() if s in saved and saved[s] != digest]
    gone = [s for s in saved if s not in digests_now]
    common = len([s for s in digests_now if s in saved])
    verdict = ", ".join(filter(None, ["differ: " + ", ".join(changed) if changed else "",
                                      "no longer computed: " + ", ".join(gone) if gone else ""]))
    print(f"{name}: {common} series compared, {verdict or 'identical'}", flush=True)
    return bool(common) and not changed and not gone


def main() -> None:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("scenarios", nargs="*", metavar="SCENARIO",
                        help="scenario names (default: every shipped one)")
    parser.add_argument("--duration", type=float, default=300.0,
                        help="simulated seconds of each run, at most its own duration (300)")
    parser.add_argument("--whole", action="store_true",
                        help="each run over its own run.duration (instead of --duration)")
    parser.add_argument("--stack", action="store_true", help="through the nodes, from the bags")
    parser.add_argument("--python", action="store_true",
                        help="in-process, uncompiled: simulate(compiled=False)")
    parser.add_argument("--out", type=Path, help="write the digests to this JSON file")
    parser.add_argument("--compare", type=Path, help="JSON file of digests to compare with")
    args = parser.parse_args()
    try:
        names = args.scenarios or scenario_names()
        runs = {name: load_scenario(name) for name in names}
        if not args.whole:
            runs = {name: apply_overrides(values, {"run.duration": min(
                args.duration, values["run.duration"])}) for name, values in runs.items()}
        reference = saved_set(args.compare) if args.compare else None
    except (ScenarioError, OSError) as exc:
        _cli.fail(str(exc))
    if reference is not None and not any(name in reference for name in runs):
        _cli.fail(f"--compare {args.compare}: none of the scenarios run is in the saved set")
    if args.stack and args.python:
        _cli.fail("--stack and --python exclude each other: the stack runs the nodes")
    if args.out:
        check_writable(args.out)
    result, differing = {}, 0
    with tempfile.TemporaryDirectory() as scratch:
        for name, values in runs.items():
            series = (stack_series(values, Path(scratch) / name) if args.stack
                      else simulate(values, compiled=not args.python))
            result[name] = digests(series)
            if args.out:
                write_digests(args.out, result)
            if reference is None:
                print(f"{name}: {len(result[name])} series", flush=True)
            elif name not in reference:
                print(f"{name}: not in the saved set", flush=True)
            else:
                saved = reference[name]
                if args.stack:  # a bag's times are its stamps: t is not hashed (see above)
                    saved = {series: digest for series, digest in saved.items() if series != "t"}
                differing += not compared(name, result[name], saved)
    if reference is not None:
        saved = sum(name in reference for name in result)
        print(f"{saved - differing} of the {saved} saved scenarios identical")
        sys.exit(1 if differing else 0)


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
