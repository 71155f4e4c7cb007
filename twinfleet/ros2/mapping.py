"""What a fleet's messages are in ROS 2: the mapping a fleet names, and how it is found.

A mapping is an object with (duck-typed, so that a case study writes it with
the node contract only, as it writes its scene):

* ``latched``: the ROS topics to publish transient-local (late joiners get the
  last sample: ``/map``);
* ``mapped_types``: the fleet message types it maps (the bridge carries every
  other type by its fields: `interfaces`);
* ``outbound(topic, type_name, data, stamp_ms)``: the ROS 2 messages one fleet
  message becomes, as (ROS topic, ``pkg/msg/Name``, fields) triples; none for
  a message it does not map.

A mapping that takes messages from ROS 2 into the fleet also has
``inbound_type(fleet_topic)`` (the ROS 2 type that fleet topic takes, or None)
and ``inbound(fleet_topic, ros_type, fields)`` (the fleet message, or
ValueError with the reason it is dropped for): `InboundMapping`.

It is named by import name (``module:Name``, a class made with no arguments),
resolved as node classes are (the scenario's folder and the working directory are
searched too: `load_mapping`); the default is the one the fleet's scene names in
its ``ros2`` attribute (``Scene.ros2``), so a scenario whose scene names one needs no
option. A fleet with neither needs none: `NoMapping` maps no type, and the bridge and
the bag export carry each standard type under its own name and every other type by
its fields (`interfaces`).
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

from twinfleet.runtime.scenario.suggest import did_you_mean

Output = tuple[str, str, dict[str, Any]]


class MappingError(ValueError):
    """A mapping name that does not name a mapping; the text says why."""


@runtime_checkable
class Ros2Mapping(Protocol):
    """How one kind of fleet looks in ROS 2 (module docstring)."""

    @property
    def latched(self) -> frozenset[str]:
        """The fleet topics that are TRANSIENT_LOCAL on ROS 2."""
        ...

    @property
    def mapped_types(self) -> frozenset[str]:
        """The fleet types this mapping turns into standard messages."""
        ...

    def outbound(self, topic: str, type_name: str, data: Mapping[str, Any],
                 stamp_ms: int) -> Sequence[Output]:
        """The ROS 2 messages one fleet message becomes."""
        ...


@runtime_checkable
class InboundMapping(Protocol):
    """A mapping that also takes ROS 2 messages into the fleet (module docstring)."""

    def inbound_type(self, fleet_topic: str) -> str | None:
        """The ROS 2 type `fleet_topic` takes, or None."""
        ...

    def inbound(self, fleet_topic: str, ros_type: str, fields: Mapping[str, Any]) -> Any:
        """The fleet message a checked ROS 2 message becomes (ValueError: why not)."""
        ...


@dataclass(frozen=True)
class NoMapping:
    """The mapping of a fleet that needs none: it maps no type, so the bridge carries each
    standard type under its own name and every other type by its fields; `latched` are
    the fleet's own latched topics."""

    latched: frozenset[str] = frozenset()
    mapped_types: frozenset[str] = frozenset()

    def outbound(self, topic: str, type_name: str, data: Mapping[str, Any],
                 stamp_ms: int) -> Sequence[Output]:
        """Nothing: no type is mapped."""
        return ()


NO_MAPPING = "no mapping"  # how an export without a mapping names the one it used


def load_mapping(name: str, near: Iterable[Path] = ()) -> Ros2Mapping:
    """A new mapping of the kind `name` (``module:Name``) names, its module searched in
    the folders `near` too (a scenario's folder, the working directory), as a scenario's
    node classes are.

    Raises:
        MappingError: the name is malformed, does not import, or does not make a mapping.
    """
    module_name, _, attr = name.partition(":")
    if not module_name or not attr:
        raise MappingError(f"expected 'module:Mapping', got {name!r}")
    for folder in near:
        if str(folder) not in sys.path:
            sys.path.append(str(folder))
    try:
        module = importlib.import_module(module_name)
        made = getattr(module, attr)()
    except ImportError as exc:
        raise MappingError(f"unknown ROS 2 mapping {name!r} ({exc})") from None
    except AttributeError as exc:
        names = [f"{module_name}:{n}" for n in vars(module) if not n.startswith("_")]
        raise MappingError(f"unknown ROS 2 mapping {name!r} ({exc})"
                           f"{did_you_mean(name, names)}") from None
    except Exception as exc:  # the user's module or constructor: say what it raised
        raise MappingError(f"{name}: {type(exc).__name__}: {exc}") from None
    if not isinstance(made, Ros2Mapping):
        raise MappingError(f"{name}() made a {type(made).__name__}, not a ROS 2 mapping "
                           "(one with latched, mapped_types and outbound)")
    return made


def mapping_of_scene(scene: str | None) -> str | None:
    """The mapping a scene (``module:Name``) names in its ``ros2`` attribute, if any."""
    if not scene:
        return None
    module_name, _, attr = scene.partition(":")
    try:
        value = getattr(getattr(importlib.import_module(module_name), attr), "ros2", None)
    except Exception:  # a scene that cannot be loaded names no mapping
        return None
    return value if isinstance(value, str) else None
