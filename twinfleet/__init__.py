"""twinfleet: ROS-like robot fleets over Eclipse Zenoh, verified by a checker that runs the same code.

This module is the node-author API, the contract shared by the live runtime and
the checker (``from twinfleet import Node, Context, subscribe, ...``). Importing
it loads neither Zenoh nor asyncio. The layers are subpackages:
``twinfleet.runtime`` (contract + live driver), ``twinfleet.checker``,
``twinfleet.agreement`` (both drivers side by side), ``twinfleet.nodes`` (the
robot case study) and ``twinfleet.cli`` on top.
"""

import os as _os

# In a source checkout the layers are folders beside this one (pyproject.toml maps
# `twinfleet.runtime` to `runtime/`, ...): resolve them there, so that a checkout (or a
# git worktree) imports its own code even when another checkout is installed editable.
# An installed wheel has the layers inside this folder and no pyproject.toml beside it.
_checkout = _os.path.dirname(_os.path.dirname(_os.path.abspath(__file__)))
if _os.path.isfile(_os.path.join(_checkout, "pyproject.toml")) and _os.path.isdir(
        _os.path.join(_checkout, "runtime")):
    __path__.append(_checkout)  # noqa: F821 - a package's __path__

from twinfleet.runtime.context import Context, ContractError
from twinfleet.runtime.messages import CallError, Empty, String, message
from twinfleet.runtime.node import (
    QOS_DEFAULT,
    QOS_LATCHED,
    QOS_SENSOR_DATA,
    Durability,
    Node,
    NodeDefinitionError,
    PureMemo,
    QoS,
    Reliability,
    every,
    handler,
    on_start,
    service,
    subscribe,
)

__all__ = [
    "QOS_DEFAULT",
    "QOS_LATCHED",
    "QOS_SENSOR_DATA",
    "CallError",
    "Context",
    "ContractError",
    "Durability",
    "Empty",
    "Node",
    "NodeDefinitionError",
    "PureMemo",
    "QoS",
    "Reliability",
    "String",
    "every",
    "handler",
    "message",
    "on_start",
    "service",
    "subscribe",
]
