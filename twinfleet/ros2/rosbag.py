"""`twinfleet export run.mcap --ros2 -o BAG/`: a recording as a rosbag2 folder ROS 2 tools read.

A twinfleet recording keeps msgpack envelopes of the fleet's own types. The
export runs every message through the fleet's ROS 2 mapping (`mapping`; the
recording's scene names it) and writes what comes out with rosbags' rosbag2
writer: a folder with ``metadata.yaml`` and one MCAP file (profile ``ros2``,
``ros2msg`` schemas, ``cdr`` message encoding), one connection per ROS topic
and type with its offered QoS (transient-local for the mapping's latched
topics) and its RIHS01 hash as rosidl computes it (`twinfleet.interfaces.typehash`: rosbags' own
hash is wrong for types with ``char`` fields, so the hash is passed in).
Messages keep the recording's log time (receive time, ns).

`bag_info` summarises such a folder for ``twinfleet bag info BAG/``.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

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

from twinfleet.ros2.cdr import RosTypes
from twinfleet.ros2.mapping import Ros2Mapping, load_mapping, mapping_of_scene

BAG_VERSION = 9


class ExportError(ValueError):
    """The recording cannot be exported; the text says why."""


@dataclass(frozen=True)
class BagWritten:
    """What `export_rosbag2` wrote: messages per (topic, type), and the mapping used."""

    counts: dict[tuple[str, str], int]
    mapping: str

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


def recording_scene(path: Path) -> str | None:
    """The scene a twinfleet recording names in its metadata."""
    with path.open("rb") as f:
        for record in make_reader(f).iter_metadata():
            if record.name == "twinfleet" and record.metadata.get("scene"):
                return str(record.metadata["scene"])
    return None


def _envelopes(path: Path) -> Iterator[tuple[str, int, dict[str, Any]]]:
    with path.open("rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages(log_time_order=True):
            if channel.message_encoding != "msgpack":
                continue
            try:
                env = msgpack.unpackb(message.data, raw=False, strict_map_key=False)
            except Exception:  # msgpack raises several unrelated types: not a fleet message
                continue
            if isinstance(env, dict) and isinstance(env.get("data"), dict):
                yield channel.topic, message.log_time, env


def export_rosbag2(source: str | Path, target: str | Path, *, mapping: str | None = None,
                   types: RosTypes | None = None) -> BagWritten:
    """Write the rosbag2 folder `target` from the twinfleet recording `source`.

    Raises:
        ExportError: `target` exists, or no mapping is given and the recording names none.
    """
    source, target = Path(source), Path(target)
    if target.exists():
        raise ExportError(f"{target} exists already: a bag export needs a new folder")
    name = mapping or mapping_of_scene(recording_scene(source))
    if name is None:
        raise ExportError(f"{source} names no scene with a ROS 2 mapping: give --mapping "
                          "module:Name")
    table: Ros2Mapping = load_mapping(name)
    types = types or RosTypes()
    counts: dict[tuple[str, str], int] = {}
    connections: dict[tuple[str, str], Connection] = {}
    writer = Writer(target, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    try:
        for topic, log_time, env in _envelopes(source):
            outputs = table.outbound(topic, str(env.get("type")), env["data"],
                                     int(env.get("stamp_ms") or 0))
            for ros_topic, ros_type, fields in outputs:
                key = (ros_topic, ros_type)
                if key not in connections:
                    connections[key] = _connection(writer, types, ros_topic, ros_type,
                                                   ros_topic in table.latched)
                writer.write(connections[key], log_time, types.encode(ros_type, fields))
                counts[key] = counts.get(key, 0) + 1
    finally:
        writer.close()
    return BagWritten(counts, name)


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
                         f"{c.digest}  serialization: {c.ext.serialization_format}")
    print("\n".join(lines), file=out, flush=True)
