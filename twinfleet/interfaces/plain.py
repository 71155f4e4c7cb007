"""Standard ROS 2 types as plain data: what the bridge and the command line exchange.

The fleet's wire carries a message as a plain map (an envelope's ``data``:
nested maps with a ``_type`` key, arrays, bytes). For a contract type that *is* a
standard ROS 2 type — a generated class, or one of the contract's own with the
same fields (``std_msgs/String``) — `standard_type` names it (``std_msgs/msg/String``)
and `ros_fields` turns its plain data into the fields the bridge's CDR encoder
takes, so the bridge carries it under its real name and RIHS01 with no mapping.
`typed_fields` goes the other way for a ROS 2 user's YAML (``{linear: {x: 1.0}}``):
the complete plain data of the frozen message, defaults filled in.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from functools import cache
from typing import Any

from twinfleet.interfaces.definitions import (
    Container,
    Definition,
    InterfaceError,
    message_definition,
    ros_name,
)
from twinfleet.interfaces.generate import freeze, from_fields
from twinfleet.runtime.contract.messages import registered_types, to_plain


@cache
def _definition(type_name: str) -> Definition | None:
    ros_type = ros_name(type_name)
    try:
        return None if ros_type is None else message_definition(ros_type)
    except InterfaceError:
        return None


@cache
def _standard(type_name: str, cls: type | None) -> str | None:
    ros_type = getattr(cls, "__ros_definition__", None)
    if isinstance(ros_type, str):
        return ros_type
    definition = _definition(type_name)
    if definition is None or cls is None:  # unregistered here: the data's shape decides
        return None if definition is None else definition.name
    if not dataclasses.is_dataclass(cls):
        return None
    names = tuple(f.name for f in dataclasses.fields(cls))
    return definition.name if names == tuple(f.name for f in definition.fields) else None


def standard_type(type_name: str) -> str | None:
    """The ROS 2 type a contract type name is (module docstring), or None. A name this
    process has not registered (a bridge beside a fleet whose node modules it never
    imported) is taken at its word when a definition exists: data of another shape
    then fails to convert, and is not carried."""
    return _standard(type_name, registered_types().get(type_name))


def ros_fields(ros_type: str, data: Mapping[str, Any]) -> dict[str, Any]:
    """The fields of plain message data as the bridge's CDR encoder takes them.

    Raises:
        KeyError, TypeError or ValueError: `data` is not of the type's shape.
    """
    out: dict[str, Any] = {}
    for f in message_definition(ros_type).fields:
        if f.name not in data:
            continue
        value, t = data[f.name], f.type
        if t.nested and t.container is Container.ONE:
            value = ros_fields(t.base, value)
        elif t.nested:
            value = [ros_fields(t.base, v) for v in value]
        elif t.base == "byte":
            value = value[0] if t.container is Container.ONE else [v[0] for v in value]
        out[f.name] = value
    return out


def typed_fields(ros_type: str, fields: Mapping[str, Any]) -> dict[str, Any]:
    """The complete plain data (``_type`` keys, defaults) of the message a ROS 2 user's
    YAML describes; a service's request with ``pkg/srv/Name``.

    Raises:
        FieldValueError or InterfaceError: one line, as `from_fields` and `freeze` give it.
    """
    plain = to_plain(freeze(from_fields(ros_type, fields)))
    plain.pop("_type")
    return dict(plain)


def ros_typed(type_name: str, fields: Mapping[str, Any], *,
              service: bool = False) -> dict[str, Any] | None:
    """`typed_fields` of `type_name` as a command names it (``geometry_msgs/msg/Twist``,
    ``geometry_msgs/Twist``; with `service`, ``std_srvs/srv/SetBool`` means its request),
    or None when it names no standard ROS 2 type.

    Raises:
        FieldValueError or InterfaceError: one line.
    """
    parts = type_name.split("/")
    if service and len(parts) == 3 and parts[1] == "srv":
        type_name = f"{type_name}_Request"
    elif service and len(parts) == 2 and not parts[1].endswith("_Request"):
        type_name = f"{parts[0]}/srv/{parts[1]}_Request"
    definition = _definition(type_name)
    return None if definition is None else typed_fields(definition.name, fields)
