"""Where ROS 2 interface definitions come from, as small value types (no classes generated here).

Two sources, both the field's own, neither copied into this repository:

* the ``.msg`` and ``.srv`` files that an interface package installs under
  ``<prefix>/share/<package>/{msg,srv}/`` (the ``ros-jazzy-*`` wheels put them
  under the Python environment's prefix; a ROS 2 installation lists its
  prefixes in ``AMENT_PREFIX_PATH``). They are parsed with rosbags' ``.msg``
  parser and are the only source of default values (``float64 w 1``) and of
  services (a ``.srv`` is a request body, ``---``, a response body);
* rosbags' type store of ROS 2 Jazzy (162 message types, no services), for a
  message type whose package is not installed. rosbags drops default values,
  so such a type takes ROS's zero values (docs/rclpy.md names the two standard
  types this changes).

A service ``pkg/srv/Name`` is two message definitions, ``pkg/srv/Name_Request``
and ``pkg/srv/Name_Response``, as rosidl names them.
"""

from __future__ import annotations

import contextlib
import enum
import importlib.util
import os
import re
import sys
import sysconfig
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

from twinfleet.runtime.contract.environment import EnvVar, env_value

#: the wheel that installs each package's definitions (the one-line hint when one is missing)
WHEEL_OF = "ros-jazzy-{}"
INSTALL_HINT = "pip install 'twinfleet[rclpy]'"
NO_ROSBAGS = f"ROS 2 message definitions need rosbags, which is not installed: {INSTALL_HINT}"
#: rosidl's Python type strings (`get_fields_and_field_types`) of the .msg primitive types
ROSIDL_NAMES = {"bool": "boolean", "byte": "octet", "char": "uint8", "float32": "float",
                "float64": "double"}


class InterfaceError(LookupError):
    """An interface that cannot be loaded; the text (one line) says which and what to install."""


class Container(enum.Enum):
    """How many values a field holds."""

    ONE = "one"
    ARRAY = "array"  # exactly `size` values
    SEQUENCE = "sequence"  # up to `size` values (0: unbounded)


@dataclass(frozen=True, slots=True)
class FieldType:
    """The type of one field: a primitive (``float64``, ``string``) or a nested type name."""

    base: str  # a primitive name, or ``pkg/msg/Name`` when `nested`
    nested: bool = False
    container: Container = Container.ONE
    size: int = 0
    string_bound: int = 0  # ``string<=N``: N

    def rosidl(self) -> str:
        """rosidl's Python type string: 'double', 'string<5>', 'sequence<geometry_msgs/Point>'."""
        if self.nested:
            pkg, _, name = self.base.rpartition("/")
            item = f"{pkg.split('/')[0]}/{name}"
        elif self.string_bound:
            item = f"string<{self.string_bound}>"
        else:
            item = ROSIDL_NAMES.get(self.base, self.base)
        if self.container is Container.ARRAY:
            return f"{item}[{self.size}]"
        if self.container is Container.SEQUENCE:
            return f"sequence<{item}, {self.size}>" if self.size else f"sequence<{item}>"
        return item

    def msg(self) -> str:
        """The type as a ``.msg`` file writes it: 'float64[9]', 'geometry_msgs/Point[]'."""
        if self.nested:
            pkg, _, name = self.base.rpartition("/")
            item = f"{pkg.split('/')[0]}/{name}"
        else:
            item = f"string<={self.string_bound}" if self.string_bound else self.base
        if self.container is Container.ARRAY:
            return f"{item}[{self.size}]"
        if self.container is Container.SEQUENCE:
            return f"{item}[<={self.size}]" if self.size else f"{item}[]"
        return item


@dataclass(frozen=True, slots=True)
class FieldDef:
    """One field: its name, type and default (None: ROS's zero value)."""

    name: str
    type: FieldType
    default: Any = None


@dataclass(frozen=True, slots=True)
class Constant:
    """A constant of a message type (``uint8 STATUS_FIX=0``)."""

    name: str
    base: str
    value: Any


@dataclass(frozen=True, slots=True)
class Definition:
    """One message type: its ROS 2 name (``pkg/msg/Name``), fields and constants."""

    name: str
    fields: tuple[FieldDef, ...]
    constants: tuple[Constant, ...] = ()
    source: str = ""  # where it was read: a file, or rosbags' store

    @property
    def package(self) -> str:
        """The package: ``geometry_msgs``."""
        return self.name.split("/")[0]

    @property
    def short(self) -> str:
        """The type's own name: ``Twist`` (``SetBool_Request`` for a service's request)."""
        return self.name.rsplit("/", 1)[-1]

    def nested(self) -> Iterator[str]:
        """The names of the types its fields name."""
        return (f.type.base for f in self.fields if f.type.nested)


def share_dirs() -> tuple[Path, ...]:
    """The ``share`` folders searched for interface packages, first match wins."""
    prefixes = [sysconfig.get_path("data"), sys.prefix]
    ament = env_value(EnvVar.AMENT_PREFIX_PATH) or ""
    prefixes += [p for p in ament.split(os.pathsep) if p]
    seen: list[Path] = []
    for prefix in prefixes:
        share = Path(prefix) / "share"
        if share.is_dir() and share not in seen:
            seen.append(share)
    return tuple(seen)


def _package_dir(package: str, kind: str) -> Path | None:
    for share in share_dirs():
        folder = share / package / kind
        if folder.is_dir():
            return folder
    return None


@cache
def _store_names() -> frozenset[str]:
    """The type names of rosbags' Jazzy store, read from its module's source, not run: running
    it imports every older distribution's store too (about 0.2 s), which a command that only
    registers types of no ROS 2 package must not pay (the guard asks about every type)."""
    spec = importlib.util.find_spec("rosbags")  # a top-level find imports nothing
    if spec is None:
        raise InterfaceError(NO_ROSBAGS)
    names: set[str] = set()
    for folder in spec.submodule_search_locations or ():  # rosbags is a namespace package
        with contextlib.suppress(OSError):
            source = Path(folder) / "typesys" / "stores" / "ros2_jazzy.py"
            names.update(_STORE_KEY.findall(source.read_text()))
    return frozenset(names or _jazzy())  # another layout of rosbags: run the store after all


_STORE_KEY = re.compile(r"'([a-z][a-z0-9_]*/msg/[A-Za-z0-9_]+)'")


@cache
def _jazzy() -> dict[str, Any]:
    """rosbags' Jazzy field definitions (``pkg/msg/Name`` → (constants, fields))."""
    try:
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise InterfaceError(NO_ROSBAGS) from None
    return dict(get_typestore(Stores.ROS2_JAZZY).fielddefs)


def _parse(text: str, name: str, source: str) -> Definition:
    """A definition from the body of a ``.msg`` file (rosbags' parser), defaults kept."""
    try:
        from rosbags.typesys.base import BaseType, Cardinality
        from rosbags.typesys.msg import MSGParser
    except ImportError:
        raise InterfaceError(NO_ROSBAGS) from None

    pkg, _, short = name.split("/")
    try:  # named as a .msg, so that a bare nested name resolves in pkg/msg/ (as rosidl does)
        [parsed] = MSGParser(f"MSG: {pkg}/msg/{short}\n{text}").specification()
    except Exception as exc:  # rosbags raises TypesysError and ValueError with long texts
        raise InterfaceError(f"{source}: not a ROS 2 message definition "
                             f"({' '.join(str(exc).split())[:120]})") from None
    fields = []
    for field in parsed.fields:
        ref, card = field.typ.ref, field.typ.cardinality
        base = ref.name.value if isinstance(ref, BaseType) else _full_name(ref.name, name)
        nested = not isinstance(ref, BaseType)
        container = {Cardinality.SCALAR: Container.ONE, Cardinality.ARRAY: Container.ARRAY,
                     Cardinality.SEQUENCE: Container.SEQUENCE}[card]
        fields.append(FieldDef(field.name, FieldType(base, nested, container, field.typ.size,
                                                     field.typ.str_size), field.value))
    constants = tuple(Constant(c.name, c.typ.value, c.value) for c in parsed.constants)
    return Definition(name, tuple(fields), constants, source)


def _full_name(ref: str, owner: str) -> str:
    """A nested type's ``pkg/msg/Name`` (a bare ``Name`` is of the owner's package)."""
    parts = ref.split("/")
    if len(parts) == 1:
        return f"{owner.split('/')[0]}/msg/{ref}"
    return ref if len(parts) == 3 else f"{parts[0]}/msg/{parts[1]}"


def from_store(name: str, desc: tuple[Any, Any]) -> Definition:
    """A definition from rosbags' store (no defaults: rosbags drops them)."""
    consts, fields = desc
    return Definition(name, tuple(FieldDef(n, _store_type(d)) for n, d in fields),
                      tuple(Constant(n, b, v) for n, b, v in consts), "rosbags ROS2_JAZZY store")


def _store_type(desc: Any) -> FieldType:
    from rosbags.typesys.base import Nodetype

    container, size = Container.ONE, 0
    if desc[0] in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        container = Container.ARRAY if desc[0] == Nodetype.ARRAY else Container.SEQUENCE
        desc, size = desc[1]
    if desc[0] == Nodetype.NAME:
        return FieldType(desc[1], True, container, size)
    base, bound = desc[1]
    return FieldType(base, False, container, size, bound)


@cache
def message_definition(name: str) -> Definition:
    """The definition of ``pkg/msg/Name`` or ``pkg/srv/Name_Request|_Response``.

    Raises:
        InterfaceError: no installed package and no store defines it.
    """
    pkg, kind, short = _split(name)
    if kind == "srv":
        return _service_part(pkg, short)
    folder = _package_dir(pkg, "msg")
    path = folder / f"{short}.msg" if folder else None
    if path is not None and path.is_file():
        return _parse(path.read_text(), name, str(path))
    if name in _store_names():
        return from_store(name, _jazzy()[name])
    raise InterfaceError(f"unknown ROS 2 message type {name!r}: " + _missing(pkg, "msg"))


def _service_part(pkg: str, short: str) -> Definition:
    """A service's request, response or event message, or the service type itself: the
    four types rosidl hashes a service with."""
    service, _, part = short.rpartition("_")
    if part not in ("Request", "Response", "Event"):
        service, part = short, ""
    request, response = service_definitions(f"{pkg}/srv/{service}")
    prefix = f"{pkg}/srv/{service}"
    if part == "Request":
        return request
    if part == "Response":
        return response
    if part == "Event":
        return Definition(f"{prefix}_Event", (
            FieldDef("info", FieldType("service_msgs/msg/ServiceEventInfo", True)),
            FieldDef("request", FieldType(request.name, True, Container.SEQUENCE, 1)),
            FieldDef("response", FieldType(response.name, True, Container.SEQUENCE, 1))),
            (), request.source)
    return Definition(prefix, tuple(
        FieldDef(f"{role}_message", FieldType(f"{prefix}_{kind}", True))
        for role, kind in (("request", "Request"), ("response", "Response"), ("event", "Event"))),
        (), request.source)


@cache
def service_definitions(name: str) -> tuple[Definition, Definition]:
    """The request and response definitions of the service ``pkg/srv/Name``."""
    pkg, _, short = _split(name)
    folder = _package_dir(pkg, "srv")
    path = folder / f"{short}.srv" if folder else None
    if path is None or not path.is_file():
        raise InterfaceError(f"unknown ROS 2 service type {name!r}: " + _missing(pkg, "srv"))
    parts = re.split(r"^---[ \t]*$", path.read_text(), maxsplit=1, flags=re.MULTILINE)
    if len(parts) != 2:
        raise InterfaceError(f"{path}: a .srv needs a '---' line between request and response")
    request, response = parts
    return (_parse(request, f"{pkg}/srv/{short}_Request", str(path)),
            _parse(response, f"{pkg}/srv/{short}_Response", str(path)))


def ros_name(type_name: str) -> str | None:
    """The ROS 2 name of a contract type name, or None: ``geometry_msgs/Twist`` →
    ``geometry_msgs/msg/Twist``, ``std_srvs/SetBool_Request`` → ``std_srvs/srv/SetBool_Request``
    (a ROS 2 name is its own)."""
    parts = type_name.split("/")
    if len(parts) == 3 and parts[1] in ("msg", "srv") and all(parts):
        return type_name
    if len(parts) != 2 or not all(parts):
        return None
    pkg, short = parts
    kind = "srv" if short.endswith(("_Request", "_Response")) else "msg"
    return f"{pkg}/{kind}/{short}"


def _split(name: str) -> tuple[str, str, str]:
    parts = name.split("/")
    if len(parts) != 3 or parts[1] not in ("msg", "srv") or not all(parts):
        raise InterfaceError(f"{name!r}: expected a ROS 2 type name like geometry_msgs/msg/Twist "
                             "or std_srvs/srv/SetBool")
    return parts[0], parts[1], parts[2]


def _missing(pkg: str, kind: str) -> str:
    if _package_dir(pkg, kind) is not None or (kind == "msg" and package_types(pkg, kind)):
        return f"package {pkg} has no such {kind}"
    return (f"no definitions of package {pkg} are installed "
            f"(install {WHEEL_OF.format(pkg.replace('_', '-'))}, or {INSTALL_HINT})")


def package_types(package: str, kind: str) -> tuple[str, ...]:
    """The type names (``Twist``, ``SetBool``) of a package's messages or services, sorted."""
    found: set[str] = set()
    folder = _package_dir(package, kind)
    if folder is not None:
        found.update(p.stem for p in folder.glob(f"*.{kind}"))
    if kind == "msg":
        prefix = f"{package}/msg/"
        found.update(n[len(prefix):] for n in _store_names() if n.startswith(prefix))
    return tuple(sorted(found))


def known_packages() -> tuple[str, ...]:
    """Every package whose interfaces are known: rosbags' store and the installed packages
    (an `import` of one of these in rclpy node code resolves to generated classes)."""
    names = set(standard_packages())
    for share in share_dirs():
        names.update(p.parent.name for p in share.glob("*/msg") if p.is_dir())
        names.update(p.parent.name for p in share.glob("*/srv") if p.is_dir())
    return tuple(sorted(names))


def standard_packages() -> frozenset[str]:
    """The packages of rosbags' Jazzy store: ROS 2's own (an empty set without rosbags)."""
    try:
        return frozenset(n.split("/")[0] for n in _store_names())
    except InterfaceError:
        return frozenset()
