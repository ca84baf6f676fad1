"""Reading recorded runs back into time series (rosbags; no rclpy needed)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import yaml
from rosbags.highlevel import AnyReader

from ato_nodes.core.topics import topic_map

PARAMETERS_KEY = "ato_nodes.parameters"  # the run's parameters, JSON, in metadata custom_data

# series name -> (topic key, field path in the message)
FIELDS = {
    "target": ("target_speed", "data"),
    "position": ("position", "data"),
    "measured_speed": ("measured_speed", "data"),
    "command": ("command", "data"),
    "speed": ("state", "linear.x"),
    "acceleration": ("state", "linear.y"),
    "disturbance": ("state", "linear.z"),
    "force": ("state", "angular.x"),
    "resistance": ("state", "angular.y"),
    "z1": ("controller_state", "linear.x"),
    "z2": ("controller_state", "linear.y"),
    "z3": ("controller_state", "linear.z"),
    "v1": ("controller_state", "angular.x"),
    "v2": ("controller_state", "angular.y"),
}


class BagError(ValueError):
    """A bag that cannot be read or lacks what is asked of it (one-line message)."""


def _field(message, path: str) -> float:
    for part in path.split("."):
        message = getattr(message, part)
    return float(message)


def read_series(bag: str | Path) -> dict[str, np.ndarray]:
    """Per-step series of a run: one array per FIELDS name present, plus `t`
    (the target topic's timestamps, s). Messages are paired by order."""
    bag = Path(bag)
    if not bag.exists():
        raise BagError(f"{bag} does not exist")
    topics = topic_map()
    by_name = {topics[key].name: key for key, _ in FIELDS.values()}
    values: dict[str, list] = {key: [] for key in by_name.values()}
    stamps: dict[str, list] = {key: [] for key in by_name.values()}
    try:
        with AnyReader([bag]) as reader:
            connections = [c for c in reader.connections if c.topic in by_name]
            for connection, timestamp, raw in reader.messages(connections=connections):
                key = by_name[connection.topic]
                values[key].append(reader.deserialize(raw, connection.msgtype))
                stamps[key].append(timestamp)
    except BagError:
        raise
    except Exception as exc:  # rosbags raises several unrelated types for unreadable bags
        raise BagError(f"{bag}: not a readable rosbag2 bag ({exc})") from None
    if not stamps["target_speed"]:
        raise BagError(f"{bag}: no messages on {topics['target_speed'].name}")
    series = {"t": np.array(stamps["target_speed"], dtype=np.int64) * 1e-9}
    for name, (key, path) in FIELDS.items():
        if values[key]:
            series[name] = np.array([_field(m, path) for m in values[key]], dtype=float)
    return series


def read_parameters(bag: str | Path) -> dict | None:
    """The run parameters the recorder stored in the bag's metadata, if any."""
    try:
        metadata = yaml.safe_load((Path(bag) / "metadata.yaml").read_text())
        text = (metadata["rosbag2_bagfile_information"].get("custom_data") or {})[PARAMETERS_KEY]
        return json.loads(text)
    except (OSError, yaml.YAMLError, KeyError, TypeError, json.JSONDecodeError):
        return None  # someone else's bag, or one without metadata: no parameters
