"""Message types and the msgpack wire codec.

A message is a frozen dataclass registered with `@message("pkg/Name")`. Its
fields hold plain values: bool, int, float, str, bytes, None, tuples of those,
and nested messages. On the wire every sample is a msgpack map, the
*envelope*::

    {"type": "geometry_msgs/Pose2D", "stamp_ms": 1200, "seq": 7,
     "sender": "/r1", "data": {"x": 1.0, "y": 2.0, "theta": 0.0}}

`data` maps field names to values; a nested message is a map with an extra
`"_type"` key; tuples travel as arrays. A plain zenoh-python + msgpack script
can read it without importing twinfleet.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum, unique
from typing import Any, TypeVar, dataclass_transform

import msgpack

T = TypeVar("T")

_REGISTRY: dict[str, type] = {}
_CHECKS: list[Callable[[str, type], None]] = []


class DecodeError(ValueError):
    """A payload is not a valid twinfleet envelope or message."""


# dataclass_transform tells type checkers that `@message(...)` makes a frozen dataclass, so the
# generated __init__ (and frozenness) are checked at every construction.
@dataclass_transform(frozen_default=True)
def message(type_name: str) -> Callable[[type[T]], type[T]]:
    """Class decorator: make a frozen dataclass and register it under `type_name`."""

    def register(cls: type[T]) -> type[T]:
        if not dataclasses.is_dataclass(cls):
            cls = dataclass(frozen=True, slots=True)(cls)
        for check in _CHECKS:  # first: a check's reason says more than "registered twice"
            check(type_name, cls)
        existing = _REGISTRY.get(type_name)
        if existing is not None and existing.__qualname__ != cls.__qualname__:
            raise TypeError(f"message type {type_name!r} registered twice")
        cls.__message_type__ = type_name  # type: ignore[attr-defined]
        _REGISTRY[type_name] = cls
        return cls

    return register


def add_type_check(check: Callable[[str, type], None]) -> None:
    """Run `check(type_name, cls)` on every registered type now and on each one registered
    later; a check refuses a type by raising TypeError (one line: the user's error).

    Layers above the contract add what the contract cannot know: a standard ROS 2 type's
    name borrowed with other fields (`twinfleet.interfaces.guard`).
    """
    if check in _CHECKS:
        return
    for type_name, cls in list(_REGISTRY.items()):
        check(type_name, cls)
    _CHECKS.append(check)


def is_message(obj: object) -> bool:
    """True for instances of a registered message class."""
    return hasattr(type(obj), "__message_type__")


def type_name_of(msg: object) -> str:
    """The registered type name of a message instance or class."""
    cls = msg if isinstance(msg, type) else type(msg)
    try:
        return cls.__message_type__  # type: ignore[attr-defined]
    except AttributeError:
        raise TypeError(f"{cls.__name__} is not a registered message type") from None


def message_class(type_name: str) -> type:
    """The class registered under `type_name`."""
    try:
        return _REGISTRY[type_name]
    except (KeyError, TypeError):  # TypeError: an unhashable `_type` in a decoded payload
        raise DecodeError(f"unknown message type {type_name!r}") from None


def registered_types() -> dict[str, type]:
    """A copy of the registry: type name → class."""
    return dict(_REGISTRY)


_SCALARS = frozenset({bool, int, float, str, bytes, type(None)})
_FIELD_NAMES: dict[type, tuple[str, ...]] = {}


def _field_names(cls: type) -> tuple[str, ...]:
    """Field names of a message class, in declaration order (cached: encoding is a hot path)."""
    names = _FIELD_NAMES.get(cls)
    if names is None:
        names = _FIELD_NAMES[cls] = tuple(f.name for f in dataclasses.fields(cls))
    return names


def to_plain(value: Any) -> Any:
    """Convert a message (recursively) into msgpack-ready maps and arrays."""
    cls = type(value)
    if cls in _SCALARS:
        return value
    type_name = getattr(cls, "__message_type__", None)
    if type_name is not None:
        out = {}
        for name in _field_names(cls):
            field_value = getattr(value, name)
            out[name] = field_value if type(field_value) in _SCALARS else to_plain(field_value)
        out["_type"] = type_name
        return out
    if isinstance(value, tuple | list):
        return [to_plain(v) for v in value]
    return value


def from_plain(value: Any) -> Any:
    """Inverse of `to_plain`: maps with `_type` become messages, arrays become tuples."""
    if type(value) in _SCALARS:
        return value
    if isinstance(value, dict):
        if "_type" not in value:
            return {k: from_plain(v) for k, v in value.items()}
        return _build(value["_type"], value)
    if isinstance(value, list | tuple):
        return tuple(from_plain(v) for v in value)
    return value


def _build(type_name: Any, data: dict[Any, Any]) -> Any:
    """The message `type_name` from the field map `data` (its `_type` key ignored)."""
    if "_type" not in data and _SCALARS.issuperset(map(type, data.values())):
        fields = data  # the common case, checked in C: flat fields, nothing to convert
    else:
        fields = {k: v if type(v) in _SCALARS else from_plain(v)
                  for k, v in data.items() if k != "_type"}
    cls = _REGISTRY.get(type_name) if type(type_name) is str else None
    if cls is None:
        cls = message_class(type_name)  # raises the DecodeError
    try:
        return cls(**fields)
    except Exception as exc:  # wrong fields, or a message class that validates its values
        raise DecodeError(f"{type_name}: {exc}") from None


@dataclass(frozen=True, slots=True)
class Envelope:
    """One sample as it travels: the message plus its stamp, sequence number and sender."""

    msg: Any
    stamp_ms: int
    seq: int
    sender: str


_PACKER = msgpack.Packer(use_bin_type=True)  # packs plain data in C, under the GIL: reentrant-safe
_unpackb = msgpack.unpackb
_FIELD_MAPS: dict[type, tuple[str, Callable[[Any], dict[str, Any]]]] = {}


def _field_map_codec(cls: type) -> tuple[str, Callable[[Any], dict[str, Any]]]:
    """(type name, function: message -> {field: value}) of a message class (cached).

    The function is generated once per class, as `dataclasses` generates `__init__`:
    one dict display, no loop. Field names are identifiers, so the source is safe.
    """
    codec = _FIELD_MAPS.get(cls)
    if codec is None:
        items = ", ".join(f"{name!r}: m.{name}" for name in _field_names(cls))
        field_map = eval(f"lambda m: {{{items}}}", {})  # noqa: S307
        codec = _FIELD_MAPS[cls] = (type_name_of(cls), field_map)
    return codec


def encode(msg: Any, *, stamp_ms: int = 0, seq: int = 0, sender: str = "") -> bytes:
    """Encode a message into an envelope."""
    return _PACKER.pack(_envelope(msg, stamp_ms, seq, sender))


def encode_request(msg: Any, *, stamp_ms: int, sender: str, reply_to: str) -> bytes:
    """`encode` a service request, whose envelope also names the caller's reply handler
    (a deferred reply's token names it: `decode_request`)."""
    envelope = _envelope(msg, stamp_ms, 0, sender)
    envelope["reply_to"] = reply_to
    return _PACKER.pack(envelope)


def _envelope(msg: Any, stamp_ms: int, seq: int, sender: str) -> dict[str, Any]:
    type_name, field_map = _FIELD_MAPS.get(type(msg)) or _field_map_codec(type(msg))
    plain = field_map(msg)
    if not _SCALARS.issuperset(map(type, plain.values())):  # nested messages or sequences
        plain = to_plain(msg)
        del plain["_type"]
    return {"type": type_name, "stamp_ms": stamp_ms, "seq": seq, "sender": sender,
            "data": plain}


def decode_fields(payload: bytes) -> tuple[Any, int, int, str]:
    """Decode an envelope into ``(msg, stamp_ms, seq, sender)`` (the host's hot path).

    Raises:
        DecodeError: with the reason, on any malformed payload.
    """
    return _fields(_unpacked(payload))


def decode_request(payload: bytes) -> tuple[Any, int, int, str, str]:
    """`decode_fields` of a service request, and the caller's reply handler ("" if unnamed).

    Raises:
        DecodeError: with the reason, on any malformed payload.
    """
    raw = _unpacked(payload)
    msg, stamp, seq, sender = _fields(raw)
    reply_to = raw.get("reply_to", "")
    if not isinstance(reply_to, str):
        raise DecodeError("envelope 'reply_to' must be a string")
    return msg, stamp, seq, sender, reply_to


def _unpacked(payload: bytes) -> Any:
    try:
        return _unpackb(payload, raw=False, strict_map_key=False)
    except Exception as exc:  # msgpack raises several unrelated types
        raise DecodeError(f"not msgpack: {exc}") from None


def _fields(raw: Any) -> tuple[Any, int, int, str]:
    """`decode_fields` of an unpacked envelope."""
    try:  # a str index fails on every msgpack value but a map (no cost when it succeeds)
        type_name, data = raw["type"], raw["data"]
    except (KeyError, TypeError):
        raise DecodeError("not a twinfleet envelope (needs 'type' and 'data')") from None
    if type(data) is not dict or type(type_name) is not str:
        raise DecodeError("envelope 'type' must be a string and 'data' a map")
    try:
        msg = _build(type_name, data)
    except RecursionError:
        raise DecodeError("message nested too deeply") from None
    stamp, seq, sender = raw.get("stamp_ms", 0), raw.get("seq", 0), raw.get("sender", "")
    if not isinstance(stamp, int) or not isinstance(seq, int) or not isinstance(sender, str):
        raise DecodeError("envelope 'stamp_ms'/'seq' must be integers and 'sender' a string")
    return msg, stamp, seq, sender


def decode(payload: bytes) -> Envelope:
    """Decode an envelope; raise DecodeError with the reason on any malformed payload."""
    return Envelope(*decode_fields(payload))


@unique
class CallFailure(StrEnum):
    """Why a service call got no reply, as the caller's transport saw it happen."""

    TIMEOUT = "timeout"  # a server took the request and did not answer within the timeout
    NO_SERVER = "no server"  # no server took the request (none serves it, or it went away)
    SERVER_ERROR = "server error"  # the server answered with an error (its handler failed,
    # or it refused or could not read the request)
    BAD_REPLY = "bad reply"  # the server's answer could not be decoded here


@message("twinfleet/CallError")
class CallError:
    """Delivered to a caller's reply handler when a service call fails: `failure` says
    what happened (branch on it), `reason` in words (the server's error text, say)."""

    service: str
    failure: CallFailure
    reason: str = ""

    def __post_init__(self) -> None:
        # decoded from the wire the failure is its text: hand nodes the enum either way
        object.__setattr__(self, "failure", CallFailure(self.failure))


@message("std_msgs/Empty")
class Empty:
    """A message with no fields."""


@message("std_msgs/String")
class String:
    """A text message."""

    data: str = ""


@message("twinfleet/NodeAlive")
class NodeAlive:
    """A node appeared (`alive=True`) or disappeared; delivered to `@subscribe("/_liveliness")`."""

    name: str
    alive: bool


@message("twinfleet/Violation")
class Violation:
    """Published on `/violations` when a handler calls `ctx.fail` or raises."""

    node: str
    handler: str
    reason: str
