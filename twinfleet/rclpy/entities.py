"""What an rclpy node creates, as the engine keeps it: its entities and the records of
what changes while it runs (timers, waiting callbacks, suspended coroutines, calls).

Entities made in the node's `__init__` (publishers, subscriptions, services, clients,
callback groups) never change; they become the contract node's declared handlers. The
rest is the engine's part of the node's state (`Dynamic`): `twinfleet.rclpy.state`
writes it as plain values for the checker and builds it again.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

from twinfleet.runtime.contract.node import QoS


class EntityKind(StrEnum):
    """What made a callback ready: rclpy's waitable kinds."""

    TIMER = "timer"
    SUBSCRIPTION = "subscription"
    SERVICE = "service"
    CLIENT = "client"


@dataclass(frozen=True, slots=True)
class PublisherEntry:
    """A publisher: its topic as given, message class and QoS."""

    topic: str
    msg_type: type
    qos: QoS


@dataclass(frozen=True, slots=True)
class SubscriptionEntry:
    """A subscription: topic, message class, callback, group index and QoS."""

    topic: str
    msg_type: type
    callback: Callable[..., Any]
    group: int
    qos: QoS


@dataclass(frozen=True, slots=True)
class ServiceEntry:
    """A service server: name, service class, callback(request, response), group index."""

    name: str
    srv_type: type
    callback: Callable[..., Any]
    group: int


@dataclass(frozen=True, slots=True)
class ClientEntry:
    """A service client: name, service class, group index (the group its replies need)."""

    name: str
    srv_type: type
    group: int


@dataclass(slots=True)
class TimerSlot:
    """A timer. `pending` counts its firing events scheduled and not yet handled: only the
    last one is live (a cancel or reset leaves earlier ones stale; they fire as no-ops)."""

    period_ms: int
    callback: Callable[..., Any]
    group: int
    canceled: bool = False
    pending: int = 0
    destroyed: bool = False
    ref: Any = None  # the callback as a state holds it (twinfleet.rclpy.state), once known


@dataclass(frozen=True, slots=True)
class Waiting:
    """A ready callback held back because its group is busy."""

    kind: EntityKind
    index: int
    args: tuple[Any, ...]


@dataclass(slots=True)
class Suspended:
    """A coroutine callback suspended at an `await`, as values: what it runs, the state it
    began in (snapshot bytes), the results of its earlier awaits, the time each of its
    steps read (None: it read none), the future it waits for and, for a service callback,
    the request its return value answers."""

    callback: Callable[..., Any]
    args: bytes  # encoded arguments (twinfleet.rclpy.state.encode_args)
    group: int | None  # None: a done callback, outside every group
    start: bytes
    results: list[Any] = field(default_factory=list)
    clocks: list[int | None] = field(default_factory=list)
    awaiting: Any = None  # the Future
    reply: Any = None  # a service callback's ReplyToken: its return value answers that request


@dataclass(slots=True)
class Dynamic:
    """The engine's part of the node state."""

    timers: list[TimerSlot | None] = field(default_factory=list)
    params: dict[str, Any] = field(default_factory=dict)
    waiting: list[Waiting] = field(default_factory=list)
    tasks: list[Suspended] = field(default_factory=list)
    # per client: the Future of each call slot waiting for its reply (None: a free slot)
    calls: list[list[Any]] = field(default_factory=list)
    on_set: list[Callable[..., Any]] = field(default_factory=list)
