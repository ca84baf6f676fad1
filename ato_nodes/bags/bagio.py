"""Reading recorded runs back into time series (rosbags and mcap; no rclpy needed).

Reads any rosbag2 bag directory (MCAP or SQLite storage) and a lone .mcap
file without metadata.yaml. Topics are found by role (target speed, true
state, measured speed, command, controller state, position) under the names
of the topic map, or under other names given as a role -> topic mapping.
Every series is sampled at the time stamps of the speed source (the true
state, else the measured speed). Where a topic shares those stamps (the
stack's own bags: one stamp per step on every topic) only the steps every
topic has are read, and the run says how many it left out: a gap is never
filled. A topic of someone else's bag with stamps of its own is sampled at
the latest message at or before each stamp.

A run's bag says whether it is whole: its parameters give the steps the run
planned (core.schema.steps), its summary.json (when the launcher or the
supervisor wrote one) the run's status; Run.partial compares them with the steps
recorded (a journey ended at its last stop, run.last_stop_hold, planned to end there:
core/run/last_stop.planned_steps counts its end again from the recorded states). The
parameters kept in a bag are checked against the schema when read: a bag is anyone's
file.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import numpy as np
import yaml
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.schema import SPEC_BY_NAME, load_plugins, steps, upgraded
from ato_nodes.core.run.last_stop import planned_steps
from ato_nodes.core.run.scoring import KEPT_FILES, LINE_BASE64, files_kept, run_line
from ato_nodes.core.base.topics import topic_map

PARAMETERS_KEY = "ato_nodes.parameters"  # the run's parameters, JSON, in metadata custom_data
SUMMARY = "summary.json"  # the run's outcome, beside the bag's files: {"status": ..., ...}
# A run's status (summary.json) as the reason it ended before its planned steps.
ENDED = {"timeout": "timed out", "completed": "interrupted"}

LABELLED = "labelled"  # a Float64MultiArray whose layout.dim[0].label names its entries
MATRIX = "matrix"      # a Float64MultiArray kept whole: one row per step

# role -> (message type, [(series name, field path)] or LABELLED or (MATRIX, series name))
ROLES: dict[str, tuple[str, object]] = {
    "target_speed": ("std_msgs/msg/Float64", [("target", "data")]),
    "state": ("geometry_msgs/msg/Twist", [
        ("speed", "linear.x"), ("acceleration", "linear.y"), ("disturbance", "linear.z"),
        ("force", "angular.x"), ("resistance", "angular.y"), ("line_resistance", "angular.z")]),
    "speed_limit": ("std_msgs/msg/Float64", [("speed_limit", "data")]),
    "measured_speed": ("std_msgs/msg/Float64", [("measured_speed", "data")]),
    "command": ("std_msgs/msg/Float64", [("command", "data")]),
    "controller_state": ("std_msgs/msg/Float64MultiArray", LABELLED),
    "target_preview": ("std_msgs/msg/Float64MultiArray", (MATRIX, "preview")),
    "position": ("std_msgs/msg/Float64", [("position", "data")]),
    "odometry": ("std_msgs/msg/Float64MultiArray", LABELLED),
}
OPTIONAL_ROLES = ("odometry",)  # a run has them with an option on: none missing without
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


class BagError(ValueError):
    """A bag that cannot be read or lacks what is asked of it (one-line message)."""


# The parameter a controller node of the user's announces (ato_nodes.nodes.external,
# docs/external-nodes.md): its law is not in the bag, so no in-process run repeats it.
EXTERNAL_LAW = "controller.external"


class ExternalLaw(BagError):
    """A bag whose controller was an external node's law: it can be scored, not
    simulated again."""


@dataclass
class Run:
    """What a bag holds, as per-step series."""

    path: Path
    series: dict[str, np.ndarray]
    parameters: dict | None
    roles: dict[str, str]                       # role -> topic found
    missing: list[str] = field(default_factory=list)  # roles not in the bag
    notes: list[str] = field(default_factory=list)
    # live controller parameters changed during the run: {step: {name: value}}, as
    # core.loop.simulate(changes=...) takes them
    parameter_changes: dict[int, dict[str, float]] = field(default_factory=dict)
    # a journey's late departures and the curves they drove (the profile's /ato/profile/replans:
    # served.Replan's fields and the step), in step order
    replans: list[dict] = field(default_factory=list)
    status: str | None = None  # the run's status from its summary.json, if it has one

    @property
    def planned_steps(self) -> int | None:
        """The steps the run was to make (None: a bag without the stack's parameters):
        run.duration's, or those up to the step at which a journey's train had stood
        run.last_stop_hold at its last stop (the run ends there, complete)."""
        if not self.parameters:
            return None
        try:
            if "position" not in self.series:
                return steps(self.parameters)
            return planned_steps(self.parameters, self.series["position"],
                                 self.series["speed"])
        except (KeyError, TypeError):  # someone else's parameters
            return None

    @property
    def recorded_steps(self) -> int:
        """Steps up to the last one every topic has: its stamp is t_k = k run.period."""
        t = self.series["t"]
        period = (self.parameters or {}).get("run.period")
        if not len(t) or not period:
            return len(t)
        return round(t[-1] / period) + 1

    @property
    def ended_at_last_stop(self) -> bool:
        """The run ended, complete, once its journey's train had stood run.last_stop_hold
        at its last stop (before run.duration)."""
        planned = self.planned_steps
        return planned is not None and planned < steps(self.parameters) \
            and self.recorded_steps >= planned

    @property
    def partial(self) -> str | None:
        """How the run ended before its planned steps, e.g. "interrupted at step 99 of
        2000"; None for a whole run (or a bag that does not say what was planned)."""
        planned = self.planned_steps
        if planned is None or self.recorded_steps >= planned:
            return None
        ended = ENDED.get(self.status or "completed", self.status)
        return f"{ended} at step {self.recorded_steps} of {planned}"


def parse_mapping(items: list[str]) -> dict[str, str]:
    """`role=topic` items, e.g. target_speed=/my/target."""
    mapping = {}
    for item in items:
        role, sep, topic = item.partition("=")
        if not sep or role not in ROLES or not topic.startswith("/"):
            raise BagError(f"--map expects role=/topic with role one of {', '.join(ROLES)}; "
                           f"got {item!r}")
        mapping[role] = topic
    return mapping


def _messages(path: Path, wanted: dict[str, str] | None
              ) -> tuple[dict[str, str], Iterator[tuple[str, int, bytes]]]:
    """(topic -> type of every topic in the bag, iterator of (topic, stamp ns, CDR))."""
    if path.is_dir():
        if not (path / "metadata.yaml").exists():
            lone = sorted(path.glob("*.mcap"))
            if len(lone) == 1:
                return _mcap_messages(lone[0], wanted)
            raise BagError(f"{path}: no rosbag2 metadata.yaml and no single .mcap file in it")
        reader = AnyReader([path])
        reader.open()
        types = {c.topic: c.msgtype for c in reader.connections}

        def generate():
            try:
                selected = [c for c in reader.connections if wanted is None or c.topic in wanted]
                for connection, stamp, raw in reader.messages(connections=selected):
                    yield connection.topic, stamp, bytes(raw)
            finally:
                reader.close()
        return types, generate()
    if path.suffix == ".mcap" or path.is_file():
        return _mcap_messages(path, wanted)
    raise BagError(f"{path} does not exist")


def _mcap_messages(path: Path, wanted: dict[str, str] | None):
    from mcap.reader import make_reader

    handle = path.open("rb")
    try:
        reader = make_reader(handle)
        summary = reader.get_summary()
    except Exception:
        handle.close()
        raise
    if summary is None:  # no summary section (e.g. cut short): read the channels as we go
        types = None
    else:
        schemas = summary.schemas
        types = {channel.topic: schemas[channel.schema_id].name
                 for channel in summary.channels.values()}

    def generate():
        try:
            topics = None if wanted is None else list(wanted)
            for _schema, channel, message in reader.iter_messages(topics=topics,
                                                                  log_time_order=False):
                yield channel.topic, message.log_time, message.data
        finally:
            handle.close()
    if types is None:
        raise BagError(f"{path}: MCAP file without a summary (truncated or still being written)")
    return types, generate()


def _unreadable(path: Path, exc: Exception) -> BagError:
    problem = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    return BagError(f"{path}: not a readable rosbag2 bag or MCAP file ({problem})")


def _field(message, path: str) -> float:
    for part in path.split("."):
        message = getattr(message, part)
    return float(message)


def read_run(bag: str | Path, mapping: dict[str, str] | None = None) -> Run:
    """Every series a bag can give, sampled on the speed source's stamps."""
    path = Path(bag)
    if not path.exists():
        raise BagError(f"{path} does not exist")
    names = {key: topic.name for key, topic in topic_map().items()}
    topics_by_role = {role: (mapping or {}).get(role, names[role]) for role in ROLES}
    try:
        types, messages = _messages(path, None)
        found = {role: topic for role, topic in topics_by_role.items() if topic in types}
        for role, topic in found.items():
            expected = ROLES[role][0]
            if types[topic] != expected:
                raise BagError(f"{path}: {topic} is {types[topic]}, but {role} needs {expected}")
        role_of = {topic: role for role, topic in found.items()}
        stamps: dict[str, list[int]] = {role: [] for role in found}
        raws: dict[str, list[bytes]] = {role: [] for role in found}
        changes_topic = names["parameter_changes"]
        changes: dict[int, dict[str, float]] = {}
        replans_topic, replans = names["replans"], []
        count = 0
        for topic, stamp, raw in messages:
            count += 1
            role = role_of.get(topic)
            if role is not None:
                stamps[role].append(stamp)
                raws[role].append(raw)
            elif topic == changes_topic:
                change = json.loads(TYPESTORE.deserialize_cdr(raw, "std_msgs/msg/String").data)
                changes.setdefault(change["step"], {}).update(change["parameters"])
            elif topic == replans_topic:
                replan = TYPESTORE.deserialize_cdr(raw, "std_msgs/msg/String").data
                replans.append(json.loads(replan))
    except BagError:
        raise
    except Exception as exc:  # rosbags and mcap raise many unrelated types for bad files
        raise _unreadable(path, exc) from None
    status = run_status(path)
    if count == 0:
        ended = f" ({status} before its first step)" if status else ""
        raise BagError(f"{path}: 0 messages recorded{ended}; nothing to score")
    run = _assemble(path, found, stamps, raws, types)
    run.parameter_changes = changes
    run.replans = replans
    run.status = status
    return run


def run_status(path: Path) -> str | None:
    """The status in the run's summary.json ("completed", "interrupted", ...), None
    without one (a bag of someone else's, or one its writer left no summary in)."""
    try:
        status = json.loads((path / SUMMARY).read_text()).get("status")
    except (OSError, ValueError, AttributeError):
        return None
    return status if isinstance(status, str) and status else None


def _assemble(path, found, stamps, raws, types) -> Run:
    missing = [role for role in ROLES if (role not in found or not raws[role])
               and role not in OPTIONAL_ROLES]
    usable = _usable_roles(path, found, raws, types)
    notes = []
    clock_role = "state" if "state" in usable else "measured_speed"
    if clock_role == "measured_speed":
        notes.append("no true state: the speed is the measured speed")
    base = np.array(stamps[clock_role], dtype=np.int64)
    clock_order = np.argsort(base, kind="stable")
    base = base[clock_order]
    keep = np.ones(len(base), dtype=bool)
    picks = {clock_role: clock_order}
    short = []
    for role in usable - {clock_role}:
        role_stamps = np.array(stamps[role], dtype=np.int64)
        role_order = np.argsort(role_stamps, kind="stable")
        ordered = role_stamps[role_order]
        at = np.minimum(np.searchsorted(ordered, base), len(ordered) - 1)
        exact = ordered[at] == base
        if exact.any():  # one stamp per step: a step without this topic is not scored
            if not exact.all():
                short.append(found[role])
            keep &= exact
            picks[role] = role_order[at]
        else:  # someone else's bag, stamps not shared: the latest message at or before
            latest = np.searchsorted(ordered, base, side="right") - 1
            keep &= latest >= 0
            picks[role] = role_order[np.maximum(latest, 0)]
            notes.append(f"{found[role]} has no message at the speed source's stamps: "
                         "sampled at the latest one before each")
    if not keep.all():
        notes.append(f"{np.count_nonzero(~keep)} of {len(base)} steps lack a message on "
                     f"{', '.join(sorted(short)) or 'a topic'}: only the {np.count_nonzero(keep)} "
                     "steps every topic has are read (no gap is filled)")
    series = _decoded_series(base[keep] * 1e-9, clock_role, usable, picks, keep, raws)
    return Run(path, series, _checked_parameters(path), {r: found[r] for r in usable}, missing,
               notes)


def _usable_roles(path, found, raws, types) -> set[str]:
    """The roles found with messages; a BagError unless they give a target speed and a
    speed, and, when their topics are there, a first complete step."""
    usable = {role for role in found if raws[role]}
    silent = sorted(found[role] for role in ("target_speed", "state", "measured_speed")
                    if role in found and role not in usable)
    if silent and "target_speed" in found and found.keys() & {"state", "measured_speed"}:
        raise BagError(f"{path}: no complete step: {', '.join(silent)} recorded no message "
                       "(the run ended before its first step)")
    if "target_speed" not in usable or not usable & {"state", "measured_speed"}:
        names = ", ".join(sorted(types)) or "none"
        raise BagError(f"{path}: needs a target speed and a speed topic; topics in the bag: "
                       f"{names} (map others with --map role=/topic)")
    return usable


def _decoded_series(t, clock_role, usable, picks, keep, raws) -> dict[str, np.ndarray]:
    """The series of the kept steps: each role's picked messages decoded into columns,
    the stamps' source first."""
    series: dict[str, np.ndarray] = {"t": t}
    for role in sorted(usable, key=lambda r: r != clock_role):
        msgtype, fields = ROLES[role]
        chosen = picks[role][keep]
        decoded = {i: TYPESTORE.deserialize_cdr(raws[role][i], msgtype) for i in set(chosen)}
        series.update(_columns(fields, [decoded[i] for i in chosen]))
    if "speed" not in series:
        series["speed"] = series["measured_speed"]
    return series


def _checked_parameters(path: Path) -> dict | None:
    """The run's parameters, with the line the bag carries readable (else one line)."""
    values = read_parameters(path)
    if values:
        try:
            run_line(values)
        except (ScenarioError, ValueError) as exc:  # bad base64 is a ValueError too
            raise BagError(f"{path}: the run's line kept in the bag is unreadable "
                           f"({str(exc).splitlines()[0]})") from None
    return values


def _columns(fields, messages) -> dict[str, np.ndarray]:
    """The series one role's messages give, by its ROLES entry."""
    if fields == LABELLED:
        if not messages or not messages[0].layout.dim:
            return {}
        names = messages[0].layout.dim[0].label.split(",")
        table = np.array([message.data for message in messages], dtype=float)
        return {name: table[:, i] for i, name in enumerate(names) if name}
    if isinstance(fields, tuple):
        rows = [np.asarray(message.data, dtype=float) for message in messages]
        width = min((len(row) for row in rows), default=0)
        return {fields[1]: np.array([row[:width] for row in rows]).reshape(len(rows), width)}
    return {name: np.array([_field(message, path) for message in messages], dtype=float)
            for name, path in fields}


def read_messages(bag: str | Path, topics: list[str] | None = None
                  ) -> tuple[dict[str, str], list[tuple[str, int, bytes]]]:
    """(topic -> type, [(topic, stamp ns, CDR bytes)] in recorded order) of a bag,
    restricted to `topics` if given."""
    path = Path(bag)
    if not path.exists():
        raise BagError(f"{path} does not exist")
    try:
        types, messages = _messages(path, None)
        if topics is not None:
            unknown = sorted(set(topics) - set(types))
            if unknown:
                raise BagError(f"{path}: no topic {', '.join(unknown)}; the bag has "
                               f"{', '.join(sorted(types))}")
            types = {topic: types[topic] for topic in topics}
        selected = [(topic, stamp, raw) for topic, stamp, raw in messages if topic in types]
    except BagError:
        raise
    except Exception as exc:
        raise _unreadable(path, exc) from None
    selected.sort(key=lambda message: message[1])  # stable: ties keep the recorded order
    return types, selected


def message_counts(bag: str | Path) -> dict[str, int]:
    """Messages per topic, as the bag's metadata.yaml states them."""
    try:
        metadata = yaml.safe_load((Path(bag) / "metadata.yaml").read_text())
        return {entry["topic_metadata"]["name"]: int(entry["message_count"]) for entry in
                metadata["rosbag2_bagfile_information"]["topics_with_message_count"]}
    except (OSError, yaml.YAMLError, KeyError, TypeError, ValueError) as exc:
        raise BagError(f"{bag}: no readable metadata.yaml ({exc})") from None


def read_series(bag: str | Path, mapping: dict[str, str] | None = None) -> dict[str, np.ndarray]:
    return read_run(bag, mapping).series


def read_parameters(bag: str | Path) -> dict | None:
    """The run parameters the recorder stored in the bag's metadata, if any (None:
    someone else's bag, or one without metadata). Kept ones that are not a JSON object
    of valid values are a BagError: each parameter the schema knows is checked by it,
    and the files the bag keeps are text."""
    try:
        metadata = yaml.safe_load((Path(bag) / "metadata.yaml").read_text())
        text = (metadata["rosbag2_bagfile_information"].get("custom_data") or {})[PARAMETERS_KEY]
    except (OSError, yaml.YAMLError, KeyError, TypeError, AttributeError):
        return None
    where = f"{bag}: the run's parameters kept in metadata.yaml"
    try:
        values = json.loads(text)
    except (TypeError, ValueError) as exc:
        raise BagError(f"{where} are not JSON ({exc})") from None
    if not isinstance(values, dict):
        raise BagError(f"{where} are a JSON {type(values).__name__}, not an object")
    try:  # the run's plug-ins first: their kinds' parameters are checked as the others
        load_plugins(_checked_value("run.plugins", values.get("run.plugins", ""), where))
    except ScenarioError as exc:
        raise BagError(f"{bag}: the run's plug-ins: {exc}") from None
    try:  # a bag recorded before the linear ADRC's modes holds their switches
        return {name: _checked_value(name, value, where)
                for name, value in upgraded(values).items()}
    except ScenarioError as exc:
        raise BagError(str(exc)) from None


KEPT_TEXT = {LINE_BASE64, *(f"{name}.{part}" for name in KEPT_FILES
                            for part in ("base64", "sha256"))}


def _checked_value(name: str, value, where: str):
    spec = SPEC_BY_NAME.get(name)
    if spec is not None and not (spec.choices and isinstance(value, str)):
        return spec.check(value, where)  # a kind another version knows is said so later
    if (spec is not None or name in KEPT_TEXT) and not isinstance(value, str):
        raise ScenarioError(f"{where}: {name} must be a string, not {value!r}")
    return value


def run_columns(run: Run) -> dict[str, np.ndarray]:
    """The run's series as flat columns, one value per step, in simulate()'s order, then
    the controller's outputs; the horizon becomes preview_0 .. preview_N (r_k .. r_k+N).
    Units as in the topic map (SI: s, m, m/s, m/s^2, N/kN); t is the step's simulated
    time, s from the run's start. speed_limit is NaN where no limit applies, and left
    out for a run without any (the open track)."""
    from ato_nodes.core.run.loop import SERIES
    first = [name for name in SERIES if name in run.series]  # the simulation's order
    columns = {}
    others = [name for name in run.series if name not in first]  # outputs in their order
    for name in first + sorted(others, key=lambda name: name == "preview"):  # horizon last
        values = run.series[name]
        if name == "speed_limit":  # no limit (inf, the open track's) is a missing value
            if not np.isfinite(values).any():
                continue
            values = np.where(np.isfinite(values), values, np.nan)
        if values.ndim == 2:
            columns.update({f"{name}_{i}": values[:, i] for i in range(values.shape[1])})
        else:
            columns[name] = values
    return columns


def read_frame(bag: str | Path, mapping: dict[str, str] | None = None):
    """A recorded run as a pandas.DataFrame, one row per step (run_columns), indexed
    by t (simulated seconds from the run's start)."""
    try:
        import pandas
    except ImportError:
        raise BagError("read_frame needs pandas: pip install pandas") from None
    return pandas.DataFrame(run_columns(read_run(bag, mapping))).set_index("t")


def resimulate(run: Run) -> tuple[dict[str, np.ndarray], list[str]]:
    """The run simulated in-process from its bag alone: its parameters, the files it
    keeps (line, tables, model) and its live parameter changes. Returns the series and
    the names of the recorded series that differ from it over the steps the bag holds
    (empty: bit for bit; an interrupted run's bag is compared over what it holds)."""
    from ato_nodes.core.run.loop import simulate
    if not run.parameters:
        raise BagError(f"{run.path}: the bag keeps no run parameters to simulate from")
    if run.parameters.get(EXTERNAL_LAW):
        raise ExternalLaw(f"not re-simulated: the controller was an external node's law "
                          f"({run.parameters[EXTERNAL_LAW]}), which only that node runs; the "
                          "bag is scored as recorded")
    with files_kept(run.parameters) as values:
        try:
            series = simulate(values, changes=run.parameter_changes)
        except ScenarioError as exc:
            raise BagError(f"{run.path}: cannot simulate the run again: {exc}") from None
    steps = len(run.series["t"])
    differ = [name for name, recorded in run.series.items()
              if name != "t" and name in series and not (
                  len(series[name]) >= steps
                  and np.array_equal(series[name][:steps], recorded, equal_nan=True))]
    return series, differ
