"""twinfleet message types as ROS 2 interfaces, by their fields: ``.msg`` text, CDR, a package.

A message class that no mapping turns into a standard type is carried by its
fields under a ROS-style name (``twinfleet_msgs/Status`` →
``twinfleet_msgs/msg/Status``); a standard ROS 2 type (``geometry_msgs/Twist``
of `twinfleet.interfaces`) under its own name and hash. Each field's annotation gives its ROS type:

    int → int64    float → float64    str → string    bool → bool    bytes → uint8[]
    tuple[T, ...] → T[]               tuple[T, T] (one scalar type) → T[2]
    a message class → its ROS type    tuple[Msg, ...] → Msg[]

ROS has no sequence of arrays, so a sequence of fixed tuples (the robots' cells,
``tuple[tuple[int, int], ...]``) is a sequence of a helper type of the same
package, ``Int64x2`` (one field, ``int64[2] values``). An annotation outside this
table (a union, a dict) makes the type not exportable: `InterfaceError` says which.

`Interfaces` registers the types in a `cdr.RosTypes` store, so their RIHS01 hashes
(`twinfleet.interfaces.typehash`) are computed as the standard types' are, and converts a fleet
message's plain fields into ROS fields. `write_package` writes a colcon package of
them (``package.xml``, ``CMakeLists.txt``, ``msg/*.msg``): a ROS 2 workspace that
builds it has the same types, with the same hashes, as the bridge announces.
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from rosbags.typesys import get_types_from_msg

from twinfleet.interfaces.plain import ros_fields, standard_type
from twinfleet.ros2.cdr import RosTypes
from twinfleet.ros2.mapping import Output, Ros2Mapping
from twinfleet.runtime.contract.messages import registered_types

_SCALARS: dict[Any, str] = {int: "int64", float: "float64", str: "string", bool: "bool"}
Convert = typing.Callable[[Any], Any]


class InterfaceError(ValueError):
    """A message class that cannot be a ROS 2 interface; the text says which field and why."""


def ros_name(type_name: str) -> str:
    """``pkg/Name`` (a twinfleet type name) as ROS 2 names it: ``pkg/msg/Name``."""
    pkg, _, name = type_name.partition("/")
    return f"{pkg}/msg/{name}"


class Interfaces:
    """The by-fields ROS 2 interfaces of some message classes (module docstring)."""

    def __init__(self, classes: Mapping[str, type], types: RosTypes | None = None) -> None:
        self.types = types or RosTypes()
        self.definitions: dict[str, str] = {}  # ROS type → .msg text
        self._convert: dict[str, Convert] = {}  # twinfleet type name → plain → ROS fields
        self.skipped: dict[str, str] = {}  # twinfleet type name → why it is not exported
        for name, cls in sorted(classes.items()):
            if standard_type(name) is not None:
                continue  # carried under its own name (`ros_type`), never redefined
            try:
                self._define(name, cls)
            except InterfaceError as exc:
                self.skipped[name] = str(exc)
        for ros_type, text in sorted(self.definitions.items()):
            self.types.store.register(get_types_from_msg(text, ros_type))

    def _define(self, name: str, cls: type) -> None:
        pkg = name.partition("/")[0]
        lines, converts, helpers = [], {}, {}
        hints = typing.get_type_hints(cls)
        for f in dataclasses.fields(cls):
            ros_type, convert, helper = self._field(pkg, hints.get(f.name), f"{name}.{f.name}")
            lines.append(f"{ros_type} {f.name}")
            converts[f.name] = convert
            helpers.update(helper)
        self.definitions.update(helpers)
        self.definitions[ros_name(name)] = "\n".join(lines) + "\n"

        def to_ros(plain: Any) -> dict[str, Any]:
            return {k: c(plain[k]) for k, c in converts.items() if k in plain}

        self._convert[name] = to_ros

    def _field(self, pkg: str, hint: Any, where: str) -> tuple[str, Convert, dict[str, str]]:
        """(.msg type, plain → ROS value, helper types) of one annotation."""
        if hint in _SCALARS:
            return _SCALARS[hint], _same, {}
        if isinstance(hint, type) and issubclass(hint, str):  # a StrEnum travels as its text
            return "string", str, {}
        if hint is bytes:
            return "uint8[]", bytes, {}
        message = getattr(hint, "__message_type__", None)
        standard = standard_type(message) if isinstance(message, str) else None
        if standard is not None:
            return str(message), lambda plain: ros_fields(standard, plain), {}
        if isinstance(message, str):
            self._define(message, hint)
            return message, self._nested(message), {}
        if typing.get_origin(hint) is tuple:
            return self._tuple(pkg, typing.get_args(hint), where)
        raise InterfaceError(f"{where}: {hint!r} has no ROS 2 field type")

    def _tuple(self, pkg: str, args: tuple[Any, ...],
               where: str) -> tuple[str, Convert, dict[str, str]]:
        if len(args) == 2 and args[1] is Ellipsis:
            item, convert, helpers = self._field(pkg, args[0], where)
            if item.endswith("]"):  # a sequence of arrays: through a helper type
                helper = f"{pkg}/{item.split('[')[0].capitalize()}x{item.split('[')[1][:-1]}"
                helpers = {**helpers, ros_name(helper): f"{item} values\n"}
                return f"{helper}[]", _each(lambda v: {"values": list(v)}), helpers
            return f"{item}[]", _each(convert), helpers
        if args and all(a is args[0] for a in args) and args[0] in _SCALARS:
            return f"{_SCALARS[args[0]]}[{len(args)}]", list, {}
        raise InterfaceError(f"{where}: tuple{list(args)!r} has no ROS 2 field type")

    def _nested(self, name: str) -> Convert:
        return lambda plain: self._convert[name](plain)

    def ros_type(self, type_name: str) -> str | None:
        """The ROS 2 type a twinfleet type is carried as, or None (not exportable): a
        standard ROS 2 type under its own name (`twinfleet.interfaces.plain`)."""
        if type_name in self._convert:
            return ros_name(type_name)
        standard = standard_type(type_name)
        return standard if standard is not None and self.types.known(standard) else None

    def fields(self, type_name: str, plain: Mapping[str, Any]) -> dict[str, Any]:
        """A fleet message's plain fields (an envelope's ``data``) as ROS 2 fields."""
        convert = self._convert.get(type_name)
        if convert is not None:
            return convert(plain)
        return ros_fields(self.ros_type(type_name) or "", plain)

    def package(self, pkg: str) -> dict[str, str]:
        """The .msg texts of package `pkg`, by message name."""
        prefix = f"{pkg}/msg/"
        return {t[len(prefix):]: text for t, text in self.definitions.items()
                if t.startswith(prefix)}


def fleet_interfaces(types: RosTypes | None = None,
                     others: Mapping[str, type] | None = None) -> Interfaces:
    """The by-fields ROS 2 interfaces of the message types this process knows (and of
    `others`, classes of types it does not: `schema_types`): those of the fleet's own
    packages (not the framework's ``twinfleet/`` types, not the types a standard ROS 2
    package already defines)."""
    store = types or RosTypes()
    known = {**(others or {}), **registered_types()}
    classes = {name: cls for name, cls in known.items()
               if not name.startswith("twinfleet/") and not store.known(ros_name(name))}
    return Interfaces(classes, store)


def ros_messages(mapping: Ros2Mapping, interfaces: Interfaces | None, topic: str,
                 type_name: str, data: Mapping[str, Any], stamp_ms: int) -> list[Output]:
    """What one fleet message is in ROS 2: for a type the mapping does not map, the message
    by its fields on its own topic; else what the mapping makes of it, and, when that is
    all on other topics (``/poses`` → ``/r1/pose`` and ``/tf``), the message by its fields
    on its own topic too, so that every fleet topic is there under its name. Nothing for
    a type without interface or data not of its type's shape."""
    by_fields = interfaces.ros_type(type_name) if interfaces is not None else None

    def own() -> list[Output]:
        if by_fields is None or interfaces is None:
            return []
        try:
            return [(topic, by_fields, interfaces.fields(type_name, data))]
        except (KeyError, TypeError, ValueError):  # not of its type's shape
            return []

    if type_name not in mapping.mapped_types and by_fields is not None:
        return own()
    outputs = list(mapping.outbound(topic, type_name, data, stamp_ms))
    if outputs and all(t != topic for t, _, _ in outputs):
        outputs += own()
    return outputs


def _same(value: Any) -> Any:
    return value


def _each(convert: Convert) -> Convert:
    return lambda values: [convert(v) for v in values]


PACKAGE_XML = """<?xml version="1.0"?>
<?xml-model href="http://download.ros.org/schema/package_format3.xsd" schematypens="http://www.w3.org/2001/XMLSchema"?>
<package format="3">
  <name>{pkg}</name>
  <version>0.1.0</version>
  <description>The messages of a twinfleet fleet, by their fields (twinfleet interface export --ros2).</description>
  <maintainer email="nobody@example.com">twinfleet</maintainer>
  <license>Apache-2.0</license>
  <buildtool_depend>ament_cmake</buildtool_depend>
  <buildtool_depend>rosidl_default_generators</buildtool_depend>
  <exec_depend>rosidl_default_runtime</exec_depend>
  <member_of_group>rosidl_interface_packages</member_of_group>
  <export>
    <build_type>ament_cmake</build_type>
  </export>
</package>
"""

CMAKE = """cmake_minimum_required(VERSION 3.8)
project({pkg})
find_package(ament_cmake REQUIRED)
find_package(rosidl_default_generators REQUIRED)
rosidl_generate_interfaces(${{PROJECT_NAME}}
{files}
)
ament_export_dependencies(rosidl_default_runtime)
ament_package()
"""


def write_package(interfaces: Interfaces, pkg: str, directory: str | Path) -> list[Path]:
    """Write package `pkg` (its .msg files, package.xml, CMakeLists.txt) into `directory`/`pkg`;
    the files written."""
    root = Path(directory) / pkg
    (root / "msg").mkdir(parents=True, exist_ok=True)
    messages = interfaces.package(pkg)
    if not messages:
        raise InterfaceError(f"no message type of package {pkg!r} is known")
    written = []
    for name, text in sorted(messages.items()):
        path = root / "msg" / f"{name}.msg"
        path.write_text(text)
        written.append(path)
    files = "\n".join(f'  "msg/{name}.msg"' for name in sorted(messages))
    for name, text in (("package.xml", PACKAGE_XML.format(pkg=pkg)),
                       ("CMakeLists.txt", CMAKE.format(pkg=pkg, files=files))):
        (root / name).write_text(text)
        written.append(root / name)
    return written
