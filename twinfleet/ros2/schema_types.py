"""Message classes rebuilt from a recording's JSON Schemas, for types this process never
imported: what `rosbag` needs to carry a recorded fleet's own types by their fields.

A twinfleet recording keeps one JSON Schema per message type (`runtime.host.schemas`):
``integer``, ``number``, ``string``, ``boolean``, a ``string`` with
``contentMediaType: application/octet-stream`` (bytes), an ``array`` of ``items``
(``tuple[T, ...]``) or of ``prefixItems`` (a fixed tuple), and a nested message as an
``object`` whose ``_type`` is a constant. `schema_classes` turns each into a frozen
dataclass with those annotations and its type name, which `interfaces.Interfaces` reads
as it reads a registered class. A schema outside that table (a union, an inferred one
with no fields) makes no class: the type is left out, as `Interfaces` leaves out a class
it cannot carry.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

_SIMPLE: dict[str, type] = {"integer": int, "number": float, "boolean": bool, "string": str}


class SchemaError(ValueError):
    """A schema that has no message class here."""


def schema_classes(schemas: Mapping[str, Mapping[str, Any]]) -> dict[str, type]:
    """Message classes by type name, from data schemas by type name (those that have one)."""
    made: dict[str, type] = {}
    for name, schema in schemas.items():
        try:
            made[name] = _message(name, schema, made)
        except (SchemaError, KeyError, TypeError):
            continue
    return made


def _message(name: str, schema: Mapping[str, Any], made: dict[str, type]) -> type:
    if name in made:
        return made[name]
    props = schema.get("properties")
    if schema.get("type") != "object" or not isinstance(props, Mapping) or not props:
        raise SchemaError(f"{name}: not a message schema")
    fields = [(field, _hint(sub, made), dataclasses.field(default=None))
              for field, sub in props.items() if field != "_type"]
    cls = dataclasses.make_dataclass(name.replace("/", "_"), fields, frozen=True)
    cls.__message_type__ = name  # type: ignore[attr-defined]
    made[name] = cls
    return cls


def _hint(schema: Mapping[str, Any], made: dict[str, type]) -> Any:
    kind = schema.get("type")
    if kind == "string" and schema.get("contentMediaType") == "application/octet-stream":
        return bytes
    if kind in _SIMPLE:
        return _SIMPLE[kind]
    if kind == "array" and "prefixItems" in schema:
        return tuple[tuple(_hint(s, made) for s in schema["prefixItems"])]  # type: ignore[misc]
    if kind == "array" and isinstance(schema.get("items"), Mapping):
        return tuple[_hint(schema["items"], made), ...]  # type: ignore[misc]
    nested = schema.get("properties", {}).get("_type", {}).get("const") if kind == "object" \
        else None
    if isinstance(nested, str):
        return _message(nested, schema, made)
    raise SchemaError(f"no message field type for {dict(schema)!r:.60}")
