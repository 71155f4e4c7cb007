"""`twinfleet export run.mcap --ros2 -o BAG/`: a recording as a rosbag2 folder ROS 2 tools read.

A twinfleet recording keeps msgpack envelopes of the fleet's own types. The
export makes of every message what the live bridge makes of it
(`interfaces.ros_messages`): what the fleet's ROS 2 mapping makes of it (named with
``--mapping``, else the one the recording's scene names; a fleet with neither needs
none), and every type the mapping does not map by its fields, on its own topic, so
that each topic of the recording is in the bag under its name with its count. The
by-fields types are the recording's own: the classes this process has imported, else
rebuilt from the JSON Schemas the recording keeps (`schema_types`), so a fleet's own
types need no import. The mapping is primed with the first message of each topic and
sender, the latched ones first (the map, then each robot's first pose), as a late joiner
of the live fleet is: messages recorded before those are mapped too.

It writes with rosbags' rosbag2 writer: a folder with ``metadata.yaml`` and one MCAP
file (profile ``ros2``, ``ros2msg`` schemas with each type's full message definition,
``cdr`` message encoding), one connection per ROS topic and type with its offered QoS
(transient-local for latched topics) and its RIHS01 hash as rosidl computes it
(`twinfleet.interfaces.typehash`: rosbags' own hash is wrong for types with ``char`` fields, so the hash is
passed in). A message's time in the bag is its **fleet time** (the envelope's stamp,
ns since the fleet's epoch, as the mapped headers are), not the wall clock of the
recording: a bag of a run at ``--time-scale 5`` has its messages as far apart as the
fleet had them. A message of a standard ROS 2 type (``std_msgs/String``) is written as
that type. What has no ROS 2 form (a type with neither class nor schema) is left out
and counted by topic (`BagWritten.left_out`).

`bag_info` summarises such a folder for ``twinfleet bag info BAG/``.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, TextIO

import msgpack
import yaml
from mcap.reader import make_reader
from rosbags.interfaces import (
    Connection,
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import Reader, StoragePlugin, Writer

from twinfleet.ros2.cdr import MessageError, RosTypes
from twinfleet.ros2.interfaces import Interfaces, fleet_interfaces, ros_messages, ros_name
from twinfleet.ros2.mapping import (
    NO_MAPPING,
    NoMapping,
    Output,
    Ros2Mapping,
    load_mapping,
    mapping_of_scene,
)
from twinfleet.ros2.schema_types import schema_classes

BAG_VERSION: Literal[8, 9] = 9


class ExportError(ValueError):
    """The recording cannot be exported; the text says why."""


NS_PER_MS = 1_000_000


@dataclass(frozen=True)
class BagWritten:
    """What `export_rosbag2` wrote: messages per (topic, type), the mapping used, and the
    messages left out per recorded topic (no ROS 2 form)."""

    counts: dict[tuple[str, str], int]
    mapping: str
    left_out: dict[str, int] = field(default_factory=dict)

    @property
    def messages(self) -> int:
        """Every message written."""
        return sum(self.counts.values())


def offered_qos(latched: bool) -> Qos:
    """The QoS a bag says its publisher offered: reliable, volatile or transient-local."""
    zero = QosTime(0, 0)
    return Qos(QosHistory.KEEP_LAST, 1 if latched else 10, QosReliability.RELIABLE,
               QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE,
               zero, zero, QosLiveliness.AUTOMATIC, zero, False)


@dataclass(frozen=True)
class Recording:
    """What an export needs to know of a recording besides its messages."""

    scene: str | None
    latched: frozenset[str]  # topics recorded as transient-local
    schemas: dict[str, dict[str, Any]]  # data schema by type name


def read_recording(path: Path) -> Recording:
    """The scene, latched topics and data schemas a twinfleet recording keeps."""
    with path.open("rb") as f:
        reader = make_reader(f)
        scene = next((str(m.metadata["scene"]) for m in reader.iter_metadata()
                      if m.name == "twinfleet" and m.metadata.get("scene")), None)
        summary = reader.get_summary()
    if summary is None:
        raise ExportError(f"{path} has no summary: run twinfleet bag repair on it first")
    latched = frozenset(c.topic for c in summary.channels.values()
                        if c.metadata.get("durability") == "transient_local")
    schemas = {}
    for schema in summary.schemas.values():
        try:
            schemas[schema.name] = json.loads(schema.data)["properties"]["data"]
        except (ValueError, KeyError, TypeError):
            continue
    return Recording(scene, latched, schemas)


def recording_scene(path: Path) -> str | None:
    """The scene a twinfleet recording names in its metadata."""
    return read_recording(path).scene


def _envelopes(path: Path) -> Iterator[tuple[str, dict[str, Any]]]:
    with path.open("rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages(log_time_order=True):
            if channel.message_encoding != "msgpack":
                continue
            try:
                env = msgpack.unpackb(message.data, raw=False, strict_map_key=False)
            except Exception:  # msgpack raises several unrelated types: not a fleet message
                continue
            if isinstance(env, dict) and isinstance(env.get("data"), dict):
                yield channel.topic, env


def export_rosbag2(source: str | Path, target: str | Path, *, mapping: str | None = None,
                   near: Iterable[Path] = (), types: RosTypes | None = None) -> BagWritten:
    """Write the rosbag2 folder `target` from the twinfleet recording `source` (module
    docstring); a named `mapping`'s module is searched in the folders `near` too.

    Raises:
        ExportError: `target` exists, or `source` is not a complete recording.
        MappingError: the mapping does not load.
    """
    source, target = Path(source), Path(target)
    if target.exists():
        raise ExportError(f"{target} exists already: a bag export needs a new folder")
    recording = read_recording(source)
    name = mapping or mapping_of_scene(recording.scene)
    table: Ros2Mapping = load_mapping(name, near) if name else NoMapping(recording.latched)
    types = types or RosTypes()
    interfaces = fleet_interfaces(types, schema_classes(recording.schemas))
    _prime(table, source, recording.latched)
    bag = _Bag(Writer(target, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP),
               types, table.latched | recording.latched)
    bag.writer.open()
    try:
        for topic, env in _envelopes(source):
            stamp = int(env.get("stamp_ms") or 0)
            outputs = _outputs(table, interfaces, topic, env, stamp)
            if not outputs:
                bag.left_out[topic] = bag.left_out.get(topic, 0) + 1
            for output in outputs:
                bag.write(output, stamp * NS_PER_MS)
    finally:
        bag.writer.close()
    return BagWritten(bag.counts, name or NO_MAPPING, bag.left_out)


def _prime(table: Ros2Mapping, source: Path, latched: frozenset[str]) -> None:
    """Give the mapping the first message of each topic and sender before the export, the
    latched topics' first (the map, then each robot's first pose): what a late joiner of
    the live fleet has heard, so that no message is recorded too early to be mapped."""
    first: dict[tuple[str, str], dict[str, Any]] = {}
    for topic, env in _envelopes(source):
        first.setdefault((topic, str(env.get("sender"))), env)
    for (topic, _), env in sorted(first.items(), key=lambda item: item[0][0] not in latched):
        table.outbound(topic, str(env.get("type")), env["data"], int(env.get("stamp_ms") or 0))


def _outputs(table: Ros2Mapping, interfaces: Interfaces, topic: str, env: dict[str, Any],
             stamp: int) -> list[Output]:
    """What one recorded message is in the bag: `ros_messages`, else, for a standard ROS 2
    type, the message as it is."""
    type_name = str(env.get("type"))
    outputs = ros_messages(table, interfaces, topic, type_name, env["data"], stamp)
    if not outputs and interfaces.ros_type(type_name) is None and \
            interfaces.types.known(ros_name(type_name)):
        outputs = [(topic, ros_name(type_name), dict(env["data"]))]
    return outputs


class _Bag:
    """The writer, its connections and counts."""

    def __init__(self, writer: Writer, types: RosTypes, latched: frozenset[str]) -> None:
        self.writer, self.types, self.latched = writer, types, latched
        self.counts: dict[tuple[str, str], int] = {}
        self.left_out: dict[str, int] = {}
        self._connections: dict[tuple[str, str], Connection] = {}

    def write(self, output: Output, time_ns: int) -> None:
        topic, ros_type, fields = output
        try:
            data = self.types.encode(ros_type, fields)
        except (MessageError, KeyError, TypeError, ValueError):  # fields not of the type
            self.left_out[topic] = self.left_out.get(topic, 0) + 1
            return
        key = (topic, ros_type)
        if key not in self._connections:
            self._connections[key] = _connection(self.writer, self.types, topic, ros_type,
                                                 topic in self.latched)
        self.writer.write(self._connections[key], time_ns, data)
        self.counts[key] = self.counts.get(key, 0) + 1


def _connection(writer: Writer, types: RosTypes, topic: str, ros_type: str,
                latched: bool) -> Connection:
    msgdef, _ = types.store.generate_msgdef(ros_type, ros_version=2)
    return writer.add_connection(topic, ros_type, msgdef=msgdef, rihs01=types.type_hash(ros_type),
                                 offered_qos_profiles=[offered_qos(latched)])


def is_rosbag2(path: str | Path) -> bool:
    """True if `path` is a rosbag2 folder (it holds ``metadata.yaml``)."""
    return (Path(path) / "metadata.yaml").is_file()


def print_bag_info(path: str | Path, out: TextIO) -> None:
    """``ros2 bag info``-style text of a rosbag2 folder, read with rosbags' reader."""
    info = yaml.safe_load((Path(path) / "metadata.yaml").read_text())
    info = info.get("rosbag2_bagfile_information", {}) if isinstance(info, dict) else {}
    with Reader(Path(path)) as reader:
        duration = max(0, reader.end_time - reader.start_time) / 1e9 if reader.message_count else 0
        lines = [f"Files:             {', '.join(info.get('relative_file_paths') or [])}",
                 f"Storage id:        {info.get('storage_identifier', '?')}",
                 f"Duration:          {duration:.3f} s",
                 f"Messages:          {reader.message_count}",
                 f"Topic information: {len(reader.connections)} topics"]
        width = max((len(c.topic) for c in reader.connections), default=0)
        for c in sorted(reader.connections, key=lambda c: c.topic):
            lines.append(f"  {c.topic:<{width}}  {c.msgtype}  {c.msgcount} msgs  "
                         f"{c.digest}  serialization: {getattr(c.ext, 'serialization_format', 'cdr')}")
    print("\n".join(lines), file=out, flush=True)
