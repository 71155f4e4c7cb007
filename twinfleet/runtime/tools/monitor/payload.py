"""Messages typed on the command line: type names, YAML fields, checks, envelopes.

`topic pub` and `service call` take a type name and the fields as YAML. The
type name may be twinfleet's (``std_msgs/String``) or ROS 2's
(``std_msgs/msg/String``; for a service ``example_interfaces/srv/AddTwoInts``
means its request type ``example_interfaces/AddTwoInts_Request``). A message is
checked before it is sent, against the class registered in this process
(`--module`) or else against the JSON Schema the fleet's nodes serve
(``@types``), so an unknown type, an unknown field, a missing field or a value
of the wrong kind is refused with one line, instead of being sent and dropped
by every receiver as undecodable.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import msgpack
import yaml

from twinfleet.runtime.contract.messages import DecodeError, from_plain, registered_types, to_plain
from twinfleet.runtime.contract.names import OPERATOR_SENDER


class PayloadError(ValueError):
    """A typed-in message cannot be sent; the text says what is wrong with it."""


def parse_data(text: str | None) -> dict[str, Any]:
    """YAML text of message fields (``"{a: 1, b: 2}"``) → a mapping; empty → {}."""
    if not text or not text.strip():
        return {}
    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        where = getattr(exc, "problem_mark", None)
        at = f" at column {where.column + 1}" if where is not None else ""
        raise PayloadError(f"message fields {text!r} are not YAML{at} "
                           f"({getattr(exc, 'problem', None) or 'syntax error'})") from None
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise PayloadError(f"message fields must be a YAML mapping like \"{{data: hello}}\", "
                           f"got {text!r}")
    return value


def normalise_type(name: str, *, service: bool = False) -> str:
    """``pkg/msg/Name`` → ``pkg/Name``; ``pkg/srv/Name`` → ``pkg/Name_Request`` (services)."""
    parts = name.split("/")
    if len(parts) == 3 and parts[1] == "msg":
        return f"{parts[0]}/{parts[2]}"
    if len(parts) == 3 and parts[1] == "srv":
        return f"{parts[0]}/{parts[2]}" + ("_Request" if service else "")
    if len(parts) != 2 or not all(parts):
        raise PayloadError(f"message type {name!r}: expected PACKAGE/NAME (e.g. std_msgs/String "
                           "or std_msgs/msg/String)")
    return name


_JSON_TYPES: dict[str, type | tuple[type, ...]] = {"string": str, "integer": int, "number": (int, float), "boolean": bool,
               "null": type(None), "array": (list, tuple), "object": dict}


def check_fields(type_name: str, data: Mapping[str, Any], schema: Mapping[str, Any],
                 where: str = "") -> None:
    """Check `data` against a data schema (`runtime.host.schemas.dataclass_schema`)."""
    props = schema.get("properties") or {}
    for key in data:
        if key not in props:
            raise PayloadError(f"{type_name}: unknown field {where}{key!r}; fields: "
                               + (", ".join(props) or "none"))
    for key in schema.get("required") or []:
        if key not in data:
            raise PayloadError(f"{type_name}: missing field {where}{key!r}")
    for key, value in data.items():
        _check_value(type_name, f"{where}{key}", value, props[key])


def _check_value(type_name: str, where: str, value: Any, schema: Mapping[str, Any]) -> None:
    if "anyOf" in schema:
        for option in schema["anyOf"]:
            try:
                _check_value(type_name, where, value, option)
                return
            except PayloadError:
                continue
        raise PayloadError(f"{type_name}: field {where!r}: {value!r} matches none of its types")
    kind = schema.get("type")
    if kind == "string" and schema.get("contentMediaType"):
        if not isinstance(value, str | bytes):
            raise PayloadError(f"{type_name}: field {where!r} holds bytes, got {value!r}")
        return
    expected = _JSON_TYPES.get(kind) if isinstance(kind, str) else None
    if expected is None:
        return
    matches = isinstance(value, expected)  # kept apart: `value` stays Any below
    if not matches or (kind in ("integer", "number") and isinstance(value, bool)):
        raise PayloadError(f"{type_name}: field {where!r} must be {kind}, got {value!r}")
    if kind == "array":
        items = schema.get("prefixItems")
        if items is not None and len(items) != len(value):
            raise PayloadError(f"{type_name}: field {where!r} needs {len(items)} values, "
                               f"got {value!r}")
        for i, item in enumerate(value):
            sub = items[i] if items is not None else schema.get("items") or {}
            _check_value(type_name, f"{where}[{i}]", item, sub)
    if kind == "object" and "properties" in schema:
        nested = {k: v for k, v in value.items() if k != "_type"}
        check_fields(type_name, nested, {**schema, "properties": {
            k: v for k, v in schema["properties"].items() if k != "_type"}}, f"{where}.")


def build_fields(type_name: str, data: Mapping[str, Any],
                 known: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    """The envelope `data` for `type_name`, checked (module docstring).

    Args:
        known: data schemas the fleet serves (type name → schema).

    Raises:
        PayloadError: unknown type, or fields that do not fit it.
    """
    cls = registered_types().get(type_name)
    if cls is not None:
        from twinfleet.runtime.host.schemas import dataclass_schema

        check_fields(type_name, data, dataclass_schema(cls))
        try:
            msg = from_plain({**data, "_type": type_name})
        except DecodeError as exc:
            raise PayloadError(_class_error(type_name, str(exc))) from None
        plain = to_plain(msg)
        plain.pop("_type")
        return plain
    if type_name in known:
        check_fields(type_name, data, known[type_name])
        return {k: _tuple_free(v) for k, v in data.items()}
    names = sorted({*registered_types(), *known})
    hint = ", ".join(n for n in names if n.rsplit("/", 1)[-1].lower()
                     in type_name.lower()) or ", ".join(names[:12])
    raise PayloadError(f"unknown message type {type_name!r}: no node of the fleet knows it "
                       f"(known: {hint}{', ...' if len(names) > 12 and hint else ''}); "
                       "see `twinfleet interface list`")


def _class_error(type_name: str, text: str) -> str:
    text = text.removeprefix(f"{type_name}: ")
    if "unexpected keyword argument" in text:
        field = text.rsplit("'", 2)[-2] if text.count("'") >= 2 else text
        return f"{type_name}: unknown field {field!r}"
    if "missing" in text and "required" in text:
        return f"{type_name}: {text.split('() ', 1)[-1]}"
    return f"{type_name}: {text}"


def _tuple_free(value: Any) -> Any:
    if isinstance(value, tuple):
        return [_tuple_free(v) for v in value]
    return value


def envelope(type_name: str, fields: Mapping[str, Any], *, seq: int = 0,
             stamp_ms: int = 0) -> bytes:
    """A msgpack envelope of already checked fields."""
    return msgpack.packb({"type": type_name, "stamp_ms": stamp_ms, "seq": seq,
                          "sender": OPERATOR_SENDER, "data": dict(fields)}, use_bin_type=True)
