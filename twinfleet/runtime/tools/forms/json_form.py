"""Recorded payloads in JSON form, for the web viewer, the Foxglove bridge and the export.

Envelopes travel as msgpack; JSON readers (browsers, Foxglove) get the same values with
``bytes`` as base64 text, and the schemas the nodes serve say so
(``contentEncoding: base64``, the JSON Schema keyword Foxglove reads).
"""

from __future__ import annotations

import base64
import json
from typing import Any

import msgpack


def jsonable(value: Any) -> Any:
    """Msgpack-decoded data → JSON values: bytes become base64 text, tuples lists."""
    if isinstance(value, bytes | bytearray):
        return base64.b64encode(value).decode("ascii")
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    return value


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
