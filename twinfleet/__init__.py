"""twinfleet: ROS-like robot fleets over Eclipse Zenoh, verified by a checker that runs the same code.

This module is the node-author API, the contract shared by the live runtime and
the checker (``from twinfleet import Node, Context, subscribe, ...``). Importing
it loads neither Zenoh nor asyncio. The layers are subpackages:
``twinfleet.runtime`` (the contract and the live driver, in wings), ``twinfleet.checker``,
``twinfleet.agreement`` (both drivers side by side), ``twinfleet.nodes`` (the
robot case study) and ``twinfleet.cli`` on top.
"""

from twinfleet.runtime.contract.context import Context, ContractError, ReplyToken
from twinfleet.runtime.contract.messages import CallError, CallFailure, Empty, String, message
from twinfleet.runtime.contract.node import (
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
from twinfleet.runtime.contract.params import file_param

__all__ = [
    "QOS_DEFAULT",
    "QOS_LATCHED",
    "QOS_SENSOR_DATA",
    "CallError",
    "CallFailure",
    "Context",
    "ContractError",
    "Durability",
    "Empty",
    "Node",
    "NodeDefinitionError",
    "PureMemo",
    "QoS",
    "Reliability",
    "ReplyToken",
    "String",
    "every",
    "file_param",
    "handler",
    "message",
    "on_start",
    "service",
    "subscribe",
]
