"""twinfleet's node-author API: the contract shared by the live runtime and the checker.

This package must not import Zenoh or asyncio at import time: the checker
imports it. Live modules (`zenoh_transport`, `host`, `launcher`, `cli`) are
imported explicitly where needed.
"""

from runtime.context import Context, ContractError
from runtime.messages import CallError, Empty, String, message
from runtime.node import (
    QOS_DEFAULT,
    QOS_LATCHED,
    QOS_SENSOR_DATA,
    Durability,
    Node,
    NodeDefinitionError,
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
