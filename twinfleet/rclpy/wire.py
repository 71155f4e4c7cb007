"""ROS messages at the node's edge: mutable ones in node code, frozen contract values in
effects, events and states. The classes and the conversion are `twinfleet.interfaces`'s
(generated from the ROS 2 definitions); this module is the one place that calls them.
"""

from __future__ import annotations

import functools
import types
from typing import Any


def load_interface(package: str, kind: str) -> types.ModuleType:
    """The module of a ROS interface package, e.g. (``std_msgs``, ``msg``)."""
    from twinfleet.interfaces import load_interface as load
    return load(package, kind)


def freeze(msg: Any) -> Any:
    """The frozen contract value of a mutable message (a copy: later changes do not leak)."""
    from twinfleet.interfaces import freeze as frozen
    return frozen(msg)


def thaw(frozen: Any) -> Any:
    """A fresh mutable message from a frozen one (each callback gets its own)."""
    from twinfleet.interfaces import thaw as thawed
    return thawed(frozen)


def is_ros_message(value: Any) -> bool:
    """True for instances of the generated mutable message classes."""
    return isinstance(value, _ros_message_class())


@functools.cache
def _ros_message_class() -> type:
    from twinfleet.interfaces import RosMessage
    return RosMessage


@functools.cache
def _known_packages() -> frozenset[str]:
    from twinfleet.interfaces.definitions import known_packages
    return frozenset(known_packages())


#: How ROS 2 interface packages are named; other names are not looked up (that would load
#: the definitions, rosbags' store included, for every module a node imports).
INTERFACE_SUFFIXES = ("_msgs", "_srvs", "_interfaces")


def is_known_package(name: str) -> bool:
    """True when `name` is an interface package twinfleet generates (std_msgs, ...)."""
    return name.endswith(INTERFACE_SUFFIXES) and name in _known_packages()
