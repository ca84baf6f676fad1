"""Bags written in-process, as the recorder lays them out, from a run simulated here
(core.loop.simulate): every role bagio reads back, stamped t_k = k run.period, the
run's parameters in metadata.yaml, live changes on their topic, and optionally the
summary.json a launcher leaves. No ROS graph is started, so tests stay fast."""

import json
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from ato_nodes.bags.bagio import LABELLED, PARAMETERS_KEY, ROLES
from ato_nodes.core.run.loop import SERIES
from ato_nodes.core.run.scoring import LINE_BASE64, encode_line
from ato_nodes.core.base.topics import topic_map

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
TYPES = TYPESTORE.types


def _needs(fields, outputs: list[str]) -> list[str]:
    """The series a role's messages carry (its ROLES entry)."""
    if fields == LABELLED:
        return outputs
    return [fields[1]] if isinstance(fields, tuple) else [name for name, _ in fields]


def _message(role: str, series: dict, k: int, outputs: list[str]):
    """Step k's message of a role, from the series bagio would read back from it."""
    msgtype, fields = ROLES[role]
    if fields == LABELLED:
        layout = TYPES["std_msgs/msg/MultiArrayLayout"](dim=[TYPES[
            "std_msgs/msg/MultiArrayDimension"](label=",".join(outputs), size=len(outputs),
                                                stride=len(outputs))], data_offset=0)
        return TYPES[msgtype](layout=layout, data=np.array([series[n][k] for n in outputs]))
    if isinstance(fields, tuple):  # a matrix: the horizon
        layout = TYPES["std_msgs/msg/MultiArrayLayout"](dim=[], data_offset=0)
        return TYPES[msgtype](layout=layout, data=np.asarray(series[fields[1]][k], dtype=float))
    if msgtype == "std_msgs/msg/Float64":
        ((name, _),) = fields
        return TYPES[msgtype](data=float(series[name][k]))
    vectors = {"linear": [0.0] * 3, "angular": [0.0] * 3}
    for name, path in fields:
        part, axis = path.split(".")
        vectors[part]["xyz".index(axis)] = float(series[name][k])
    vector = TYPES["geometry_msgs/msg/Vector3"]
    return TYPES[msgtype](**{part: vector(*xyz) for part, xyz in vectors.items()})


def write_run_bag(bag: Path, series: dict, parameters: dict | None, steps: int | None = None,
                  changes: dict[int, dict[str, float]] | None = None,
                  status: str | None = None, silent: tuple[str, ...] = ()) -> Path:
    """The first `steps` steps (all by default) of a simulated run as its bag, the
    controller's outputs on its state topic; with `status`, a summary.json saying it;
    the `silent` roles' topics are in the bag without a message (a run stopped before
    they published their first step).
    Parameters naming a line file keep its text, as the recorder's do."""
    names = {key: topic.name for key, topic in topic_map().items()}
    steps = len(series["t"]) if steps is None else steps
    period_ns = (parameters or {}).get("run.period", 0.05) * 1e9
    kept = [name for name in series if name not in SERIES and name != "preview"]  # outputs
    writer = Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    if parameters is not None:
        values = dict(parameters)
        if values.get("line.file"):
            values[LINE_BASE64] = encode_line(Path(values["line.file"]).read_text())
        writer.set_custom_data(PARAMETERS_KEY, json.dumps(values))
    roles = [role for role, (_, fields) in ROLES.items()
             if _needs(fields, kept) and all(name in series for name in _needs(fields, kept))]
    connections = {role: writer.add_connection(names[role], ROLES[role][0], typestore=TYPESTORE)
                   for role in roles}
    for k in range(steps):
        for role in (role for role in roles if role not in silent):
            message = _message(role, series, k, kept)
            writer.write(connections[role], round(k * period_ns),
                         TYPESTORE.serialize_cdr(message, ROLES[role][0]))
    if changes:
        topic = topic_map()["parameter_changes"]
        connection = writer.add_connection(topic.name, topic.type, typestore=TYPESTORE)
        for step, parameters_changed in sorted(changes.items()):
            text = json.dumps({"step": step, "parameters": parameters_changed})
            writer.write(connection, round(step * period_ns), TYPESTORE.serialize_cdr(
                TYPES["std_msgs/msg/String"](data=text), "std_msgs/msg/String"))
    writer.close()
    if status is not None:
        (bag / "summary.json").write_text(json.dumps({"status": status}))
    return bag
