"""`twinfleet export`: a JSON-encoded copy of an MCAP recording, for Foxglove and friends.

`twinfleet record` keeps the raw msgpack envelopes, so that `twinfleet play`
puts the very bytes back on Zenoh; but viewers such as Foxglove Studio only
decode MCAP channels whose message encoding they know. This module rewrites a
recording with message encoding ``json``: each message is the envelope as a
JSON object (``{type, stamp_ms, seq, sender, data}``), ``bytes`` values become
base64 strings, and every schema says so with ``contentEncoding: base64``
(the JSON Schema keyword Foxglove reads). Channels keep their topic and
metadata; messages keep their log and publish times and sequence numbers.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import msgpack
from mcap.reader import make_reader
from mcap.writer import Writer

from twinfleet.runtime.viewstate import jsonable


def json_schema(schema: Any) -> Any:
    """A recorded JSON Schema rewritten for JSON messages: msgpack bins become base64 strings."""
    if isinstance(schema, list):
        return [json_schema(s) for s in schema]
    if not isinstance(schema, dict):
        return schema
    out = {k: json_schema(v) for k, v in schema.items()}
    if out.get("contentMediaType") == "application/octet-stream":
        out["contentEncoding"] = "base64"
        out["description"] = "bytes, base64-encoded"
    if isinstance(out.get("description"), str) and "msgpack-encoded" in out["description"]:
        out["description"] = out["description"].replace("msgpack-encoded", "exported as JSON")
    return out


def message_json(payload: bytes) -> bytes:
    """One recorded payload as JSON bytes; an undecodable one as ``{"undecodable": base64}``."""
    try:
        value = msgpack.unpackb(payload, raw=False, strict_map_key=False)
    except Exception:  # msgpack raises several unrelated types
        value = {"undecodable": payload}
    return json.dumps(jsonable(value), separators=(",", ":"), allow_nan=True).encode()


def export_json(source: str | Path, target: str | Path) -> int:
    """Write `target`, a JSON-encoded copy of the msgpack MCAP `source`.

    Returns:
        The number of messages written.

    Raises:
        ValueError: `source` and `target` are the same file, or `source` holds a
            channel that is neither msgpack nor JSON.
        OSError: a file cannot be read or written.
    """
    if Path(source).resolve() == Path(target).resolve():
        raise ValueError(f"{target}: export needs a new file, not the recording itself")
    with open(source, "rb") as src, open(target, "wb") as dst:
        reader = make_reader(src)
        writer = Writer(dst)
        writer.start(profile="", library="twinfleet export")
        for name, values in _metadata(reader):
            writer.add_metadata(name, values)
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        count = 0
        for schema, channel, message in reader.iter_messages(log_time_order=True):
            if channel.id not in channels:
                channels[channel.id] = _copy_channel(writer, schema, channel, schemas, source)
            data = message.data if channel.message_encoding == "json" else message_json(message.data)
            writer.add_message(channels[channel.id], log_time=message.log_time, data=data,
                               publish_time=message.publish_time, sequence=message.sequence)
            count += 1
        writer.finish()
    return count


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
