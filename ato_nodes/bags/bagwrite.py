"""How the project writes rosbag2 bags (the recorder, and the repair of a bag whose
recorder was killed): rosbag2 version 9 metadata, MCAP storage, the Jazzy message
types, and metadata.yaml as rosbag2 itself writes it for Jazzy: `ros_distro: jazzy`
and each topic's offered QoS profiles, so `ros2 bag play` replays a topic with the
QoS it was recorded with (RELIABLE, KEEP_ALL) instead of its defaults."""

from __future__ import annotations

from pathlib import Path

from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness, QosReliability,
                                QosTime)
from rosbags.rosbag2 import StoragePlugin, Writer

ROS_DISTRO = "jazzy"
METADATA = "metadata.yaml"
_WRITERS_DISTRO = "ros_distro: rosbags"  # what rosbags' Writer puts there


def open_writer(path: Path) -> Writer:
    writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    return writer


def qos(history: str, depth: int, reliability: str, durability: str) -> Qos:
    """A QoS profile by policy names (KEEP_ALL, RELIABLE, VOLATILE, ...); deadline,
    lifespan and lease at their defaults (0 s: unspecified), liveliness automatic."""
    unspecified = QosTime(sec=0, nsec=0)
    return Qos(history=QosHistory[history], depth=depth,
               reliability=QosReliability[reliability], durability=QosDurability[durability],
               deadline=unspecified, lifespan=unspecified,
               liveliness=QosLiveliness.AUTOMATIC, liveliness_lease_duration=unspecified,
               avoid_ros_namespace_conventions=False)


def close_writer(writer: Writer, path: Path) -> None:
    """Close the bag (metadata.yaml written), then name the distribution its types
    are from, as rosbag2 does."""
    writer.close()
    metadata = Path(path) / METADATA
    text = metadata.read_text()
    if _WRITERS_DISTRO in text:
        staged = metadata.with_suffix(".yaml.tmp")
        staged.write_text(text.replace(_WRITERS_DISTRO, f"ros_distro: {ROS_DISTRO}", 1))
        staged.replace(metadata)
