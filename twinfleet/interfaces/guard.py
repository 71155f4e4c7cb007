"""A user's message type that borrows a standard ROS 2 package's name with other fields is refused.

``@message("geometry_msgs/Twist")`` on a flat ``x, y, theta`` dataclass would
travel under ROS 2's name with fields no ROS 2 node (and no rclpy node of the
fleet) reads. `install` adds a check to the contract's message registry
(`add_type_check`): a type named ``pkg/Name`` or ``pkg/msg/Name`` (a service's
``pkg/Name_Request``) that has a definition — in rosbags' store of the standard
packages, or installed under ``share/`` — must have that type's fields, in
order, with values of the same kinds; otherwise registering it raises
`TypeError` with one line, so loading the node module that defines it fails and
says why. A new type in a package of rosbags' store (``geometry_msgs/Pose2DPlus``)
is refused too: those packages are ROS 2's own.

Without rosbags (the default install) no definitions are known and nothing is
refused. twinfleet's own types (``std_msgs/String``) are checked by tests, not
here, so that no command pays for loading the definitions.
"""

from __future__ import annotations

import dataclasses
import typing
from typing import TYPE_CHECKING, Any

from twinfleet.runtime.contract.messages import add_type_check

if TYPE_CHECKING:
    from twinfleet.interfaces.definitions import Definition, FieldType

_KINDS: dict[Any, str] = {bool: "a bool", int: "an integer", float: "a number", str: "a text",
                          bytes: "a bytes"}


def install() -> None:
    """Refuse, from now on and among the types already registered, a borrowed standard name."""
    add_type_check(check_type)


def check_type(type_name: str, cls: type) -> None:
    """Raise TypeError (one line) if `cls` borrows a standard type's name with other fields."""
    if getattr(cls, "__ros_definition__", None) or cls.__module__.startswith("twinfleet."):
        return
    # a user's type: only now the definitions (every command installs the check, and a
    # fleet of twinfleet's own types never needs them)
    from twinfleet.interfaces.definitions import (
        InterfaceError,
        message_definition,
        ros_name,
        standard_packages,
    )

    ros_type = ros_name(type_name)
    if ros_type is None:
        return
    try:
        definition = message_definition(ros_type)
    except InterfaceError:  # no definitions installed, or a type the package does not have
        definition = None
    where = f"{type_name} ({cls.__module__}.{cls.__qualname__})"
    if definition is None:
        if ros_type.split("/")[0] not in standard_packages():
            return
        raise TypeError(f"{where}: {ros_type.split('/')[0]} is a standard ROS 2 package without "
                        f"a type {ros_type.rsplit('/', 1)[-1]}; name the type in a package of "
                        "your own (e.g. my_msgs/...)")
    mismatch = _mismatch(cls, definition)
    if mismatch:
        raise TypeError(f"{where}: {mismatch}, unlike the standard ROS 2 type {ros_type} "
                        f"({_describe(definition)}); use the standard one (from "
                        f"{definition.package}.{ros_type.split('/')[1]} import "
                        f"{definition.short}) or name yours in a package of your own")


def _mismatch(cls: type, definition: Definition) -> str | None:
    """What differs between a dataclass and a definition, or None."""
    if not dataclasses.is_dataclass(cls):
        return None
    names = tuple(f.name for f in dataclasses.fields(cls))
    wanted = tuple(f.name for f in definition.fields)
    if names != wanted:
        return f"its fields are ({', '.join(names)})"
    try:
        hints = typing.get_type_hints(cls)
    except Exception:  # annotations that do not resolve: the names matched, say no more
        return None
    for f in definition.fields:
        kind, expected = _hint_kind(hints.get(f.name)), _type_kind(f.type)
        if kind is not None and kind != expected:
            return f"its field {f.name} holds {kind}, not {expected}"
    return None


def _type_kind(t: FieldType) -> str:
    from twinfleet.interfaces.definitions import Container

    if t.container is not Container.ONE:
        return "a sequence"
    if t.nested:
        return f"a {t.base}"
    if t.base in ("float32", "float64"):
        return "a number"
    return {"bool": "a bool", "string": "a text", "byte": "a bytes"}.get(t.base, "an integer")


def _hint_kind(hint: Any) -> str | None:
    """The kind of value an annotation holds, in `_type_kind`'s words; None: not known."""
    if hint in _KINDS:
        return _KINDS[hint]
    if typing.get_origin(hint) in (tuple, list) or hint in (tuple, list):
        return "a sequence"
    nested = getattr(hint, "__message_type__", None)
    if isinstance(nested, str):
        from twinfleet.interfaces.definitions import ros_name

        return f"a {ros_name(nested) or nested}"
    return None


def _describe(definition: Definition) -> str:
    return ", ".join(f"{f.name}: {f.type.msg()}" for f in definition.fields) or "no fields"
