"""`rclpy.node.Node` on twinfleet's node contract.

A subclass is written as for rclpy: its `__init__` creates publishers, subscriptions,
timers, services and clients and declares parameters. Under twinfleet the loader
builds it with the scenario's name, namespace and parameters (as ``--ros-args -r
__node:= -r __ns:= -p`` would), and `twinfleet.rclpy.adapter` turns what it created
into a contract node. Subscriptions, services and clients belong to `__init__`
(the contract declares them before anything runs); timers and publishers may also be
made later, in a callback.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from twinfleet.rclpy.api.callback_groups import CallbackGroup, MutuallyExclusiveCallbackGroup
from twinfleet.rclpy.api.client import Client
from twinfleet.rclpy.api.clock import Clock
from twinfleet.rclpy.api.exceptions import NotSupportedError
from twinfleet.rclpy.api.logging import RcutilsLogger
from twinfleet.rclpy.api.node_parameters import ParametersMixin
from twinfleet.rclpy.api.parameter import Parameter
from twinfleet.rclpy.api.publisher import Publisher
from twinfleet.rclpy.api.qos import QoSProfile, as_profile
from twinfleet.rclpy.api.service import Service
from twinfleet.rclpy.api.subscription import Subscription
from twinfleet.rclpy.api.timer import Rate, Timer
from twinfleet.rclpy.engine import Engine, construction
from twinfleet.rclpy.entities import (
    ClientEntry,
    PublisherEntry,
    ServiceEntry,
    SubscriptionEntry,
)
from twinfleet.runtime.contract.names import normalise_namespace, validate_token


class Node(ParametersMixin):
    """An rclpy node (module docstring)."""

    def __init__(self, node_name: str, *, context: Any = None, cli_args: Any = None,
                 namespace: str | None = None, use_global_arguments: bool = True,
                 enable_rosout: bool = True, start_parameter_services: bool = True,
                 parameter_overrides: list[Parameter] | None = None,
                 allow_undeclared_parameters: bool = False,
                 automatically_declare_parameters_from_overrides: bool = False,
                 **_ignored: Any) -> None:
        made = construction()
        name = made.name or node_name
        validate_token(name, "node name")
        ns = normalise_namespace(made.namespace if made.namespace is not None else namespace)
        engine = Engine(self, name, ns, made.adapter)
        engine.overrides = dict(made.overrides)
        engine.overrides.update({p.name: p.value for p in parameter_overrides or ()})
        self.__dict__["_tf_engine"] = engine
        engine.group_index(MutuallyExclusiveCallbackGroup())
        engine.handles[("logger", 0)] = RcutilsLogger(name, engine)
        engine.handles[("clock", 0)] = Clock(now_ms=engine.now_ms)
        if automatically_declare_parameters_from_overrides:
            for key, value in engine.overrides.items():
                self.declare_parameter(key, value)

    def _tf_ref(self) -> tuple[str, int] | None:
        return ("node", 0)

    # --------------------------------------------------------------- names, clock, logger

    def get_name(self) -> str:
        """The node's name (the scenario's `name:` when launched by twinfleet)."""
        return str(self._tf_engine.name)

    def get_namespace(self) -> str:
        """The namespace, "/" for the root."""
        return str(self._tf_engine.namespace or "/")

    def get_fully_qualified_name(self) -> str:
        """Namespace and name."""
        return f"{self._tf_engine.namespace}/{self._tf_engine.name}"

    def get_logger(self) -> RcutilsLogger:
        """The node's logger; lines keep their severity in the event log."""
        return self._tf_engine.handles[("logger", 0)]

    def get_clock(self) -> Clock:
        """The node's clock: the fleet's time (logical in the checker)."""
        return self._tf_engine.handles[("clock", 0)]

    @property
    def default_callback_group(self) -> CallbackGroup:
        """The mutually exclusive group of callbacks made without a group."""
        return self._tf_engine.groups[0]

    @property
    def executor(self) -> None:
        """No executor object: twinfleet runs the callbacks."""
        return None

    # --------------------------------------------------------------- entities

    def _group(self, group: CallbackGroup | None) -> int:
        return 0 if group is None else self._tf_engine.group_index(group)

    def _init_only(self, what: str) -> None:
        if self._tf_engine.ctx is not None:
            raise NotSupportedError(
                f"{self._tf_engine.name}: {what} in a callback; twinfleet nodes create "
                "subscriptions, services and clients in __init__ (the contract declares them "
                "before the node runs)")

    def create_publisher(self, msg_type: type, topic: str, qos_profile: QoSProfile | int,
                         **_options: Any) -> Publisher:
        """A publisher of `msg_type` on `topic` (relative names resolve in the namespace)."""
        engine = self._tf_engine
        engine.publishers.append(PublisherEntry(topic, msg_type, as_profile(qos_profile).contract()))
        return Publisher(engine, len(engine.publishers) - 1)

    def create_subscription(self, msg_type: type, topic: str, callback: Callable[..., Any],
                            qos_profile: QoSProfile | int, *,
                            callback_group: CallbackGroup | None = None,
                            **_options: Any) -> Subscription:
        """`callback(msg)` for each sample on `topic`; it may be a coroutine function."""
        self._init_only("create_subscription")
        engine = self._tf_engine
        engine.subscriptions.append(SubscriptionEntry(
            topic, msg_type, callback, self._group(callback_group),
            as_profile(qos_profile).contract()))
        return Subscription(engine, len(engine.subscriptions) - 1)

    def create_service(self, srv_type: type, srv_name: str, callback: Callable[..., Any], *,
                       callback_group: CallbackGroup | None = None,
                       **_options: Any) -> Service:
        """`callback(request, response) -> response` answers each request."""
        self._init_only("create_service")
        engine = self._tf_engine
        engine.services.append(ServiceEntry(srv_name, srv_type, callback,
                                            self._group(callback_group)))
        return Service(engine, len(engine.services) - 1)

    def create_client(self, srv_type: type, srv_name: str, *,
                      callback_group: CallbackGroup | None = None, **_options: Any) -> Client:
        """A client; its replies are taken in `callback_group` (the default group if None)."""
        self._init_only("create_client")
        engine = self._tf_engine
        engine.clients.append(ClientEntry(srv_name, srv_type, self._group(callback_group)))
        engine.dyn.calls.append([])
        return Client(engine, len(engine.clients) - 1)

    def create_timer(self, timer_period_sec: float, callback: Callable[..., Any],
                     callback_group: CallbackGroup | None = None, clock: Any = None,
                     autostart: bool = True) -> Timer:
        """`callback()` every `timer_period_sec` seconds (whole milliseconds, at least 1)."""
        period_ms = round(timer_period_sec * 1000)
        if period_ms < 1:
            raise ValueError(f"{self._tf_engine.name}: create_timer needs a period of at least "
                             f"1 ms (twinfleet's time unit), got {timer_period_sec!r} s")
        index = self._tf_engine.add_timer(period_ms, callback, self._group(callback_group),
                                          autostart)
        return Timer(self._tf_engine, index)

    def create_rate(self, frequency: float, clock: Any = None) -> Rate:
        """A rate; its `sleep` is refused inside callbacks (use a timer)."""
        return Rate(self._tf_engine, frequency)

    def create_guard_condition(self, *_args: Any, **_kwargs: Any) -> Any:
        """Not supported."""
        raise NotSupportedError("guard conditions are not supported by twinfleet nodes yet")

    @property
    def timers(self) -> list[Timer]:
        """The node's live timers."""
        engine = self._tf_engine
        return [engine.handle("timer", i) for i, t in enumerate(engine.dyn.timers)
                if t is not None and not t.destroyed]

    @property
    def publishers(self) -> list[Publisher]:
        """The node's publishers."""
        return [self._tf_engine.handle("publisher", i)
                for i in range(len(self._tf_engine.publishers))]

    @property
    def subscriptions(self) -> list[Subscription]:
        """The node's subscriptions."""
        return [self._tf_engine.handle("subscription", i)
                for i in range(len(self._tf_engine.subscriptions))]

    @property
    def services(self) -> list[Service]:
        """The node's services."""
        return [self._tf_engine.handle("service", i) for i in range(len(self._tf_engine.services))]

    @property
    def clients(self) -> list[Client]:
        """The node's clients."""
        return [self._tf_engine.handle("client", i) for i in range(len(self._tf_engine.clients))]

    def destroy_timer(self, timer: Timer) -> bool:
        """Remove a timer."""
        timer.destroy()
        return True

    def destroy_publisher(self, publisher: Publisher) -> bool:
        """Accepted; publishers live as long as the node."""
        return True

    def destroy_subscription(self, subscription: Subscription) -> bool:
        """Accepted; subscriptions live as long as the node."""
        return True

    def destroy_client(self, client: Client) -> bool:
        """Accepted; clients live as long as the node."""
        return True

    def destroy_service(self, service: Service) -> bool:
        """Accepted; services live as long as the node."""
        return True

    def destroy_rate(self, rate: Rate) -> bool:
        """Accepted."""
        return True

    def destroy_node(self) -> None:
        """Accepted: the node lives as long as its process (or the checker's run)."""
