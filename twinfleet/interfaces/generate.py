"""Message and service classes generated from definitions, and their frozen twins.

For each ROS 2 message type two classes are made, once per process (cached):

* the *mutable* class node code uses, shaped like rosidl's: keyword-only
  constructor with ROS defaults (nested messages default-constructed, arrays
  filled), ``__slots__``, ``__eq__``, ``__repr__``, ``get_fields_and_field_types()``,
  the type's constants as class attributes, and ``__ros_type__``
  (``geometry_msgs/msg/Twist``) and ``__type_hash__`` (RIHS01);
* the *frozen* class: a frozen dataclass registered with the contract's
  `@message` under the contract's name of the type (``geometry_msgs/Twist``,
  ``std_srvs/SetBool_Request``: the name `topic pub` and the bridge already use),
  so the wire codec and the checker's canonical encoding take it unchanged.
  A type the contract itself defines with the same fields (``std_msgs/String``)
  keeps the contract's class, so native and rclpy nodes exchange it.

`freeze` and `thaw` convert between them; `thaw` makes a new object each time
(rclpy gives each callback its own message).
"""

from __future__ import annotations

import copy
import dataclasses
import types
from collections.abc import Callable, Mapping
from functools import cache
from typing import Any, ClassVar

from twinfleet.interfaces import frozen
from twinfleet.interfaces.codegen import make_freeze, make_init, make_thaw
from twinfleet.interfaces.definitions import (
    Container,
    Definition,
    InterfaceError,
    message_definition,
    package_types,
)
from twinfleet.interfaces.typehash import rihs01
from twinfleet.interfaces.values import Converter, FieldValueError, hint
from twinfleet.runtime.contract.messages import message, registered_types

#: the module whose attributes the frozen classes are (`twinfleet.interfaces.frozen`)
FROZEN_MODULE = frozen.__name__


def contract_name(ros_type: str) -> str:
    """The contract's name of a ROS 2 type (``geometry_msgs/msg/Twist``): ``geometry_msgs/Twist``."""
    pkg, _, short = ros_type.split("/")
    return f"{pkg}/{short}"


class RosMessage:
    """Base of the generated mutable message classes (module docstring)."""

    __slots__ = ()
    __ros_type__: ClassVar[str]
    __type_hash__: ClassVar[str]
    _converters: ClassVar[tuple[Converter, ...]]
    _frozen: ClassVar[type]
    _freeze_fn: ClassVar[Callable[[Any, str], Any]]
    _thaw_fn: ClassVar[Callable[[Any], Any]]

    def __init__(self, **fields: Any) -> None:  # each generated class has its own (codegen)
        raise TypeError(f"{type(self).__name__} is not a generated message class")

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return False
        return all(getattr(self, c.field.name) == getattr(other, c.field.name)
                   for c in self._converters)

    __hash__ = None  # type: ignore[assignment]  # mutable, as rosidl's messages are

    def __repr__(self) -> str:
        pkg, kind, short = self.__ros_type__.split("/")
        args = ", ".join(f"{c.field.name}={getattr(self, c.field.name)!r}"
                         for c in self._converters)
        return f"{pkg}.{kind}.{short}({args})"

    def __copy__(self) -> RosMessage:
        made = object.__new__(type(self))
        for conv in self._converters:
            setattr(made, conv.field.name, getattr(self, conv.field.name))
        return made

    def __deepcopy__(self, memo: dict[int, Any]) -> RosMessage:
        made = object.__new__(type(self))
        for conv in self._converters:
            setattr(made, conv.field.name, copy.deepcopy(getattr(self, conv.field.name), memo))
        return made

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickled by its type's name and frozen value: the class is generated, so no module
        attribute names it (Ray workers and checkpoints pickle what nodes hold)."""
        return (_thawed, (self.__ros_type__, freeze(self)))

    @classmethod
    def get_fields_and_field_types(cls) -> dict[str, str]:
        """Field name → rosidl's type string ('double', 'sequence<geometry_msgs/Point>')."""
        return {c.field.name: c.field.type.rosidl() for c in cls._converters}


@cache
def message_type(ros_type: str) -> type[RosMessage]:
    """The mutable class of ``pkg/msg/Name`` (or a service's ``pkg/srv/Name_Request``).

    Raises:
        InterfaceError: the type, or a type it names, has no definition.
    """
    definition = message_definition(ros_type)
    for nested in definition.nested():
        message_type(nested)  # nested first: their frozen classes annotate this one's
    convs = tuple(Converter(f, message_type) for f in definition.fields)
    namespace: dict[str, Any] = {
        "__slots__": tuple(c.field.name for c in convs),
        "__ros_type__": ros_type,
        "__type_hash__": rihs01(ros_type, message_definition),
        "__module__": f"{definition.package}.{ros_type.split('/')[1]}",
        "__qualname__": definition.short,
        "__doc__": f"ROS 2 {ros_type} ({definition.source}).",
        "_converters": convs,
        **{c.name: c.value for c in definition.constants},
    }
    cls: type[RosMessage] = type(definition.short, (RosMessage,), namespace)
    cls._frozen = _frozen_class(definition, convs)
    cls.__init__ = make_init(convs, ros_type)  # type: ignore[method-assign]
    cls._freeze_fn = make_freeze(convs, ros_type, cls._frozen, cls, _freeze_fn_of, _slow)
    cls._thaw_fn = make_thaw(convs, cls, _thaw_fn_of)
    _MUTABLE_OF[cls._frozen] = cls
    return cls


def _freeze_fn_of(ros_type: str) -> Callable[[Any, str], Any]:
    return message_type(ros_type)._freeze_fn


def _thaw_fn_of(ros_type: str) -> Callable[[Any], Any]:
    return message_type(ros_type)._thaw_fn


def _slow(value: Any, where: str, conv: Converter) -> Any:
    """A field value the generated fast tests did not pass: converted, or refused."""
    return conv.freeze(value, where, _freeze)


_MUTABLE_OF: dict[type, type[RosMessage]] = {}


def _frozen_class(definition: Definition, convs: tuple[Converter, ...]) -> type:
    name = contract_name(definition.name)
    existing = registered_types().get(name)
    names = tuple(c.field.name for c in convs)
    if existing is not None:
        theirs = tuple(f.name for f in dataclasses.fields(existing))
        if theirs != names:
            raise InterfaceError(
                f"{name}: {existing.__module__}.{existing.__qualname__} defines it with fields "
                f"({', '.join(theirs)}), not ROS 2's ({', '.join(names)})")
        return existing
    frozen_of = _frozen_of
    spec = [(c.field.name, hint(c.field.type, frozen_of),
             dataclasses.field(default=c.frozen_default(frozen_of))) for c in convs]
    cls = dataclasses.make_dataclass(definition.short, spec, frozen=True, slots=True)
    cls.__module__ = FROZEN_MODULE  # it finds the class by this name (snapshot, pickle)
    cls.__qualname__ = definition.name.replace("/", ".")
    cls.__doc__ = f"ROS 2 {definition.name}, frozen (twinfleet.interfaces.generate)."
    cls.__ros_definition__ = definition.name  # type: ignore[attr-defined]
    return message(name)(cls)


def _thawed(ros_type: str, frozen: Any) -> Any:
    return message_type(ros_type)._thaw_fn(frozen)


def contract_type(ros_type: str) -> type:
    """The frozen contract class of a ROS 2 message type: what a native twinfleet node
    publishes and names in its handlers' annotations (``geometry_msgs/msg/Twist``)."""
    return message_type(ros_type)._frozen


_frozen_of = contract_type


def freeze(msg: Any) -> Any:
    """The frozen contract message of a mutable one (a frozen one is returned as it is).

    Raises:
        FieldValueError: a field holds a value its type does not allow (one line).
        TypeError: `msg` is not a message.
    """
    if isinstance(msg, RosMessage):
        return _freeze(msg, type(msg).__ros_type__, type(msg).__ros_type__)
    if hasattr(type(msg), "__message_type__"):
        return msg
    raise TypeError(f"expected a ROS 2 message, got {type(msg).__name__}")


def _freeze(msg: Any, ros_type: str, where: str) -> Any:
    return message_type(ros_type)._freeze_fn(msg, where)


def thaw(frozen: Any) -> Any:
    """A new mutable message equal to a frozen one (a native twinfleet message: unchanged)."""
    cls = _MUTABLE_OF.get(type(frozen))
    return frozen if cls is None else cls._thaw_fn(frozen)


def from_fields(ros_type: str, fields: Mapping[str, Any], where: str = "") -> RosMessage:
    """A mutable message from plain values as ROS 2 users type them (``{linear: {x: 1.0}}``):
    nested maps, lists; a missing field keeps its default.

    Raises:
        FieldValueError: an unknown field, or a value that does not fit (one line).
    """
    cls = message_type(ros_type)
    where = where or ros_type
    if not isinstance(fields, Mapping):
        raise FieldValueError(f"{where}: expected a mapping of fields, got {fields!r}")
    convs = {c.field.name: c for c in cls._converters}
    msg = cls()
    for key, value in fields.items():
        conv = convs.get(key)
        if conv is None:
            raise FieldValueError(f"{where}: unknown field {key!r} (fields of {ros_type}: "
                                  f"{', '.join(convs) or 'none'})")
        t = conv.field.type
        if t.nested and t.container is Container.ONE:
            value = from_fields(t.base, value, f"{where}.{key}")
        elif t.nested:
            if not isinstance(value, list | tuple):
                raise FieldValueError(f"{where}.{key}: expected a list, got {value!r}")
            value = [from_fields(t.base, v, f"{where}.{key}[{i}]") for i, v in enumerate(value)]
        setattr(msg, key, value)
    return msg


@cache
def service_type(ros_type: str) -> type:
    """The class of the service ``pkg/srv/Name``: ``.Request``, ``.Response``, ``__ros_type__``."""
    request = message_type(f"{ros_type}_Request")
    response = message_type(f"{ros_type}_Response")
    pkg, _, short = ros_type.split("/")
    return type(short, (), {
        "__module__": f"{pkg}.srv", "__qualname__": short,
        "__doc__": f"ROS 2 service {ros_type}.",
        "__ros_type__": ros_type, "__type_hash__": rihs01(ros_type, message_definition),
        "Request": request, "Response": response,
    })


@cache
def load_interface(package: str, kind: str) -> types.ModuleType:
    """The module ``package.kind`` (``std_msgs.msg``, ``std_srvs.srv``) of generated classes.

    Its classes are made when first named (``from sensor_msgs.msg import Imu`` makes
    Imu and the types it names, not the whole package).

    Raises:
        InterfaceError: `kind` is not msg or srv, or no definition of `package` is installed.
    """
    if kind not in ("msg", "srv"):
        raise InterfaceError(f"{package}.{kind}: ROS 2 interfaces are .msg or .srv")
    names = package_types(package, kind)
    if not names:
        raise InterfaceError(f"unknown ROS 2 interface package {package}.{kind}: "
                             + _no_package(package, kind))
    module = types.ModuleType(f"{package}.{kind}", f"ROS 2 {kind} types of {package}, "
                              "generated from their definitions (twinfleet.interfaces).")
    module.__all__ = list(names)  # type: ignore[attr-defined]
    made = service_type if kind == "srv" else message_type

    def attribute(name: str) -> Any:
        if name not in names:
            raise AttributeError(f"ROS 2 package {package} has no {kind} {name!r} (it has: "
                                 f"{', '.join(names)})")
        value = made(f"{package}/{kind}/{name}")
        setattr(module, name, value)
        return value

    module.__getattr__ = attribute  # type: ignore[method-assign]
    return module


def _no_package(package: str, kind: str) -> str:
    from twinfleet.interfaces.definitions import INSTALL_HINT, WHEEL_OF

    return (f"no definitions installed (install {WHEEL_OF.format(package.replace('_', '-'))}, "
            f"or {INSTALL_HINT})")


frozen.answer_with(contract_type)  # the frozen module answers its names with our classes
