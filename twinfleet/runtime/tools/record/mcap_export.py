"""`twinfleet export`: a copy of an MCAP recording that Foxglove opens and draws as it is.

`twinfleet record` keeps the raw msgpack envelopes, so that `twinfleet play`
puts the very bytes back on Zenoh; but viewers such as Foxglove Studio only
decode MCAP channels whose message encoding they know. This module rewrites a
recording with message encoding ``json``: each message is the envelope as a
JSON object (``{type, stamp_ms, seq, sender, data}``), ``bytes`` values become
base64 strings, and every schema says so with ``contentEncoding: base64``
(the JSON Schema keyword Foxglove reads). Channels keep their topic and
metadata; messages keep their log and publish times and sequence numbers.

Beside those JSON copies the export writes Foxglove's well-known messages
(`runtime.tools.forms.foxglove_scene`, protobuf-encoded, schema names ``foxglove.Grid``,
``foxglove.SceneUpdate``, ``foxglove.PointCloud``) on ``/foxglove/...``
channels, logged at the time of the sample they come from: the same channels
the live bridge (`twinfleet foxglove`) serves, so Foxglove's 3D panel draws a
recording as it draws a live fleet. What is drawn comes from the scene the
recording names (metadata ``twinfleet``, key ``scene``: `runtime.contract.scene`);
a recording without one gets the JSON copies only. ``twinfleet record`` keeps
only the raw envelopes (what `play` needs); the Foxglove view is derived, and
so exported.
"""

from __future__ import annotations

import base64
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgpack
from mcap.reader import make_reader
from mcap.writer import Writer

from twinfleet.runtime.scenario.scenes import SceneError, load_scene
from twinfleet.runtime.tools.forms.json_form import json_schema, message_json

FOXGLOVE_CHANNELS_KEY = "foxglove"  # metadata of a derived channel: what it was made from


@dataclass(frozen=True)
class Exported:
    """What `export_json` wrote: the copied messages, and the scene that drew the Foxglove
    channels (None: the recording names none, or Foxglove channels were not asked for)."""

    messages: int
    scene: str | None






def export_json(source: str | Path, target: str | Path, *, foxglove: bool = True) -> Exported:
    """Write `target`: a JSON-encoded copy of the msgpack MCAP `source` and (with `foxglove`)
    its Foxglove channels, drawn by the scene it names (module docstring).

    Returns:
        The number of copied messages (the Foxglove ones are not counted) and the scene.

    Raises:
        ValueError: `source` and `target` are the same file, `source` holds a channel
            that is neither msgpack nor JSON, or its scene cannot be loaded.
        OSError: a file cannot be read or written.
    """
    if Path(source).resolve() == Path(target).resolve():
        raise ValueError(f"{target}: export needs a new file, not the recording itself")
    with open(source, "rb") as src, open(target, "wb") as dst:
        reader = make_reader(src)
        writer = Writer(dst)
        writer.start(profile="", library="twinfleet export")
        metadata = _metadata(reader)
        for name, values in metadata:
            writer.add_metadata(name, values)
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        scene = next((v["scene"] for n, v in metadata if n == "twinfleet" and v.get("scene")),
                     None) if foxglove else None
        derived = _FoxgloveChannels(writer, _load(scene)) if scene else None
        count = 0
        for schema, channel, message in reader.iter_messages(log_time_order=True):
            if channel.id not in channels:
                channels[channel.id] = _copy_channel(writer, schema, channel, schemas, source)
            data = message.data if channel.message_encoding == "json" else message_json(message.data)
            writer.add_message(channels[channel.id], log_time=message.log_time, data=data,
                               publish_time=message.publish_time, sequence=message.sequence)
            count += 1
            if derived is not None:
                derived.add(channel.topic, _envelope(schema, channel.message_encoding,
                                                     message.data), message.log_time)
        writer.finish()
    return Exported(count, scene)


def _load(scene: str) -> Any:
    """The scene a recording names; a `ValueError` (the command's one-line error) if it
    cannot be loaded here."""
    try:
        return load_scene(scene)
    except SceneError as exc:
        raise ValueError(f"the recording names scene {scene}, which cannot be loaded here: "
                         f"{exc}") from None


def _envelope(schema: Any, encoding: str, data: bytes) -> Any:
    """A recorded message as the decoded envelope: a JSON copy's bytes fields (base64 text,
    as its schema says) decoded again, as msgpack gives them."""
    try:
        if encoding == "msgpack":
            return msgpack.unpackb(data, raw=False, strict_map_key=False)
        env = json.loads(data)
        doc = json.loads(schema.data) if schema is not None else {}
    except Exception:  # msgpack and json raise several unrelated types
        return None
    return _bytes_again(env, doc)


def _bytes_again(value: Any, schema: Any) -> Any:
    """`value` with the strings its JSON Schema marks ``contentEncoding: base64`` decoded."""
    if not isinstance(schema, dict):
        return value
    if schema.get("contentEncoding") == "base64" and isinstance(value, str):
        try:
            return base64.b64decode(value, validate=True)
        except ValueError:
            return value
    fields = schema.get("properties")
    if isinstance(value, dict) and isinstance(fields, dict):
        return {k: _bytes_again(v, fields.get(k)) for k, v in value.items()}
    return value


class _FoxgloveChannels:
    """The ``/foxglove/...`` channels of an export, written with the recording's writer."""

    def __init__(self, writer: Writer, scene: Any) -> None:
        from twinfleet.runtime.tools.forms.foxglove_scene import FoxgloveScene

        self.writer, self.scene = writer, FoxgloveScene(scene)
        self.schemas: dict[str, int] = {}
        self.channels: dict[str, int] = {}
        self.written = 0

    def add(self, topic: str, env: Any, log_time: int) -> None:
        if not isinstance(env, dict):
            return
        for fox_topic, msg in self.scene.feed(topic, env, log_time):
            self.writer.add_message(self._channel(fox_topic, msg, topic), log_time=log_time,
                                    publish_time=log_time, data=msg.encode(),
                                    sequence=self.written)
            self.written += 1

    def _channel(self, topic: str, msg: Any, source: str) -> int:
        channel = self.channels.get(topic)
        if channel is None:
            schema = type(msg).get_schema()
            if schema.name not in self.schemas:
                self.schemas[schema.name] = self.writer.register_schema(
                    schema.name, schema.encoding, schema.data)
            channel = self.writer.register_channel(topic, "protobuf", self.schemas[schema.name],
                                                   {FOXGLOVE_CHANNELS_KEY: source})
            self.channels[topic] = channel
        return channel


def _metadata(reader: Any) -> list[tuple[str, dict[str, str]]]:
    return [(m.name, dict(m.metadata)) for m in reader.iter_metadata()]


def _copy_channel(writer: Writer, schema: Any, channel: Any, schemas: dict[int, int],
                  source: str | Path) -> int:
    if channel.message_encoding not in ("msgpack", "json"):
        raise ValueError(f"{source}: channel {channel.topic} is {channel.message_encoding!r}, "
                         "not a twinfleet recording (msgpack)")
    schema_id = 0
    if schema is not None:
        if schema.id not in schemas:
            text = json.dumps(json_schema(json.loads(schema.data)), indent=1).encode()
            schemas[schema.id] = writer.register_schema(schema.name, "jsonschema", text)
        schema_id = schemas[schema.id]
    return writer.register_channel(channel.topic, "json", schema_id, dict(channel.metadata))
