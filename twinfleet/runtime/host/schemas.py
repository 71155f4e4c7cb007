"""JSON Schemas of twinfleet messages, from the message dataclasses' type hints.

Used by the recorder (one schema per message type in an MCAP file) and served
by every node process on ``twinfleet/<fleet>/@types/<node>``
(`runtime.host.keys.KeyKind.TYPES`), so a tool that joins a running fleet
learns the exact schemas of message classes it has not imported.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from collections.abc import Mapping
from typing import Any

from twinfleet.runtime.contract.messages import is_message, registered_types

ENVELOPE_FIELDS = {"stamp_ms": {"type": "integer", "description": "ms since the fleet's start"},
                   "seq": {"type": "integer", "description": "per-publisher sequence number"},
                   "sender": {"type": "string", "description": "publishing node"}}


def message_schema(type_name: str, sample: Any = None,
                   known: Mapping[str, dict[str, Any]] | None = None) -> dict[str, Any]:
    """JSON Schema of an envelope carrying `type_name`.

    The data schema comes from the registered class, else from `known` (schemas
    served by the fleet's node processes), else it is inferred from `sample`.
    """
    cls = registered_types().get(type_name)
    if cls is not None:
        data = dataclass_schema(cls)
    elif known and type_name in known:
        data = known[type_name]
    else:
        data = {**_value_schema(sample), "description": "inferred from the first recorded sample"}
    return {"title": type_name, "type": "object",
            "description": "twinfleet envelope, msgpack-encoded (twinfleet/runtime/contract/messages.py)",
            "properties": {"type": {"const": type_name}, **ENVELOPE_FIELDS, "data": data},
            "required": ["type", "data"]}


def dataclass_schema(cls: type) -> dict[str, Any]:
    """JSON Schema of a message dataclass's fields, from its type hints."""
    hints = typing.get_type_hints(cls)
    props, required = {}, []
    for f in dataclasses.fields(cls):
        props[f.name] = _hint_schema(hints.get(f.name, Any))
        if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            required.append(f.name)
    return {"type": "object", "properties": props, "required": required}


def _hint_schema(hint: Any) -> dict[str, Any]:
    simple = {bool: "boolean", int: "integer", float: "number", str: "string",
              type(None): "null"}
    if hint in simple:
        return {"type": simple[hint]}
    if hint is bytes:
        return {"type": "string", "contentMediaType": "application/octet-stream",
                "description": "msgpack bin"}
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return {"anyOf": [_hint_schema(a) for a in args]}
    if origin in (tuple, list):
        if origin is list or (len(args) == 2 and args[1] is Ellipsis):
            return {"type": "array", "items": _hint_schema(args[0]) if args else {}}
        return {"type": "array", "prefixItems": [_hint_schema(a) for a in args],
                "minItems": len(args), "maxItems": len(args)}
    if isinstance(hint, type) and is_message(hint):
        nested = dataclass_schema(hint)
        nested["properties"]["_type"] = {"const": hint.__message_type__}  # type: ignore[attr-defined]
        return nested
    return {}


def _value_schema(value: Any) -> dict[str, Any]:
    if isinstance(value, bool):
        return {"type": "boolean"}
    if isinstance(value, int | float | str) or value is None:
        return _hint_schema(type(value))
    if isinstance(value, bytes):
        return _hint_schema(bytes)
    if isinstance(value, list | tuple):
        return {"type": "array", "items": _value_schema(value[0]) if value else {}}
    if isinstance(value, Mapping):
        return {"type": "object", "properties": {str(k): _value_schema(v) for k, v in value.items()}}
    return {}


def registered_schemas() -> dict[str, dict[str, Any]]:
    """Data schema (`dataclass_schema`) of every message class this process has registered."""
    return {name: dataclass_schema(cls) for name, cls in sorted(registered_types().items())}
