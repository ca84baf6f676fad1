"""Making a bag whose writer died (SIGKILL, power loss, a full disk) complete again.

A recorder killed hard leaves an MCAP file without its summary and footer and no
metadata.yaml: no rosbag2 reader opens it. The recorder closes a chunk every
second of simulated time, so the file holds every message up to at most that
before the kill. `repair()` reads the file record by record up to the first
incomplete one, writes a complete bag from what it holds (same topics, types,
stamps and bytes; the run's parameters from parameters.json), checks that the
new bag reads back with every message, and only then replaces the old file.
The like of `ros2 bag reindex`, for the MCAP layout this project records. A
directory that holds no .mcap file is not taken for a complete bag: repair() says
what it holds instead.
"""

from __future__ import annotations

import shutil
import struct
from dataclasses import dataclass, field
from pathlib import Path

import yaml
from mcap.exceptions import McapError
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from rosbags.rosbag2.metadata import parse_qos
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from ato_nodes.bags.bagwrite import close_writer, open_writer

PARAMETERS_KEY = "ato_nodes.parameters"
SIDECAR = "parameters.json"
FOOTER_MAGIC = b"\x89MCAP0\r\n"


class RepairError(ValueError):
    """A bag that cannot be repaired (one-line message)."""


@dataclass
class RepairReport:
    bag: Path
    repaired: bool
    messages: dict[str, int] = field(default_factory=dict)  # topic -> messages kept

    def describe(self) -> str:
        if not self.repaired:
            return f"{self.bag}: complete (metadata.yaml and a finished MCAP file), nothing " \
                   "to repair"
        counts = ", ".join(f"{topic} {count}" for topic, count in sorted(self.messages.items()))
        return f"{self.bag}: repaired, {sum(self.messages.values())} messages kept ({counts})"


def _mcap_file(bag: Path) -> Path:
    try:
        files = sorted(path for path in bag.glob("*.mcap") if path.is_file())
    except OSError as exc:
        raise RepairError(f"{bag}: cannot list it: {exc.strerror or exc}") from None
    if not files:
        raise RepairError(f"{bag}: not a bag: {_holdings(bag)}")
    if len(files) > 1:
        raise RepairError(f"{bag}: expected one .mcap file, found {len(files)}")
    return files[0]


def _holdings(bag: Path) -> str:
    """What a directory without a .mcap file holds, in a few words."""
    metadata = bag / "metadata.yaml"
    if metadata.is_file():
        try:
            information = yaml.safe_load(metadata.read_text())["rosbag2_bagfile_information"]
            storage = information["storage_identifier"]
        except (OSError, UnicodeDecodeError, yaml.YAMLError, KeyError, TypeError):
            return "no .mcap file, and its metadata.yaml is not rosbag2 metadata"
        return (f"no .mcap file; its metadata.yaml is of a rosbag2 bag in {storage} "
                "storage, and only MCAP bags are repaired here")
    try:
        entries = sum(1 for _ in bag.iterdir())
    except OSError as exc:
        return f"no .mcap file ({exc.strerror or exc})"
    return f"no .mcap file and no metadata.yaml ({entries} other entries)" if entries else \
        "an empty directory"


def needs_repair(bag: str | Path) -> bool:
    """A bag directory without metadata.yaml, or whose MCAP file was never finished."""
    bag = Path(bag)
    if not bag.is_dir() or not list(bag.glob("*.mcap")):
        return False
    if not (bag / "metadata.yaml").exists():
        return True
    with _mcap_file(bag).open("rb") as handle:
        handle.seek(0, 2)
        if handle.tell() < len(FOOTER_MAGIC):
            return True
        handle.seek(-len(FOOTER_MAGIC), 2)
        return handle.read() != FOOTER_MAGIC


def _readable_records(path: Path):
    """Schemas, channels and messages of an MCAP file, up to its first broken record."""
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    messages: list[Message] = []
    with path.open("rb") as handle:
        try:
            for record in StreamReader(handle, skip_magic=False).records:
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, Message):
                    messages.append(record)
        except (McapError, EOFError, ValueError, OSError, KeyError, IndexError, struct.error):
            pass  # the incomplete end: everything before it is kept
    return schemas, channels, messages


def repair(bag: str | Path) -> RepairReport:
    """The bag made complete, or said complete; RepairError for a directory that is not
    a bag or a file that cannot be repaired."""
    bag = Path(bag)
    if not bag.is_dir():
        raise RepairError(f"{bag} is not a bag directory")
    broken = _mcap_file(bag)
    if not needs_repair(bag):
        return RepairReport(bag, False)
    schemas, channels, messages = _readable_records(broken)
    if not channels:
        raise RepairError(f"{bag}: {broken.name} holds no readable channel; nothing to keep")
    staging = bag.parent / f".{bag.name}.repairing"
    shutil.rmtree(staging, ignore_errors=True)
    staging.mkdir()
    try:
        written = staging / bag.name
        kept = _write_bag(written, bag / SIDECAR, schemas, channels, messages)
        _schemas, _channels, read_back = _readable_records(_mcap_file(written))
        if len(read_back) != sum(kept.values()):
            raise RepairError(f"{bag}: the repaired bag reads back {len(read_back)} messages, not "
                              f"{sum(kept.values())}; the original is left as it was")
        _replace(bag, broken, written)
    except OSError as exc:
        raise RepairError(f"{bag}: cannot write the repaired bag: {exc.strerror or exc}") \
            from None
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return RepairReport(bag, True, kept)


def _write_bag(written: Path, sidecar: Path, schemas: dict[int, Schema],
               channels: dict[int, Channel], messages: list[Message]) -> dict[str, int]:
    """A complete bag at `written` of the channels that have a schema, their messages
    and the sidecar's parameters; returns the messages kept per topic."""
    writer = open_writer(written)
    if sidecar.exists():
        writer.set_custom_data(PARAMETERS_KEY, sidecar.read_text())
    connections = _connections(writer, schemas, channels)
    kept: dict[str, int] = {connection.topic: 0 for connection in connections.values()}
    for message in messages:
        connection = connections.get(message.channel_id)
        if connection is not None:
            writer.write(connection, message.log_time, message.data)
            kept[connection.topic] += 1
    close_writer(writer, written)
    return kept


def _connections(writer, schemas: dict[int, Schema], channels: dict[int, Channel]) -> dict:
    """channel id -> the writer's connection for it, with its type and offered QoS."""
    typestore = get_typestore(Stores.ROS2_JAZZY)
    connections = {}
    for channel_id, channel in sorted(channels.items()):
        schema = schemas.get(channel.schema_id)
        if schema is None:
            continue
        if schema.name not in typestore.fielddefs:  # a type of someone else's: its text
            typestore.register(get_types_from_msg(schema.data.decode(), schema.name))
        offered = channel.metadata.get("offered_qos_profiles")
        connections[channel_id] = writer.add_connection(
            channel.topic, schema.name, typestore=typestore,
            offered_qos_profiles=parse_qos(offered) if offered else ())
    return connections


def _replace(bag: Path, broken: Path, written: Path) -> None:
    """The bag's files replaced by the repaired bag's: the data first, then the metadata
    naming it."""
    new_mcap = _mcap_file(written)
    new_mcap.replace(bag / new_mcap.name)
    (written / "metadata.yaml").replace(bag / "metadata.yaml")
    if broken.name != new_mcap.name:
        broken.unlink()
