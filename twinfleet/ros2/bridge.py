"""The bridge's ROS 2 side: fleet messages in, rmw_zenoh samples out, on a ROS 2 Zenoh network.

`RosSide` owns one Zenoh session on the ROS 2 network (a client of a router,
``tcp/127.0.0.1:7447`` by default, where ``rmw_zenohd`` listens). Each fleet node
is a ROS node of its own name (`graph.BridgeGraph`), declared with its liveliness
token when the bridge first hears of it (`add_node`, or its first message); the
bridge's own node holds what has no fleet node behind it. The first time the
mapping makes a message of a (node, topic, type), that publisher's token and a
publisher on its data key are declared: an advanced publisher with a cache of one
sample for the mapping's latched topics (what rmw_zenoh does for TRANSIENT_LOCAL,
so a late ``ros2 topic echo /map`` or RViz gets the map), a plain one otherwise,
both with congestion control BLOCK. Every sample carries the 33-byte attachment.

`deliver(key, payload)` takes a fleet sample as a `runtime.tools.monitor.tap.FleetTap`
hands it over (``twinfleet/<fleet>/<topic>`` and a msgpack envelope) and publishes
what the mapping makes of it, as the envelope's sender. `subscribe` declares an
inbound subscription (with its token, as the node that will take it); each sample
is checked (`graph.Inbound`) on Zenoh's thread and what passes is handed to
`on_inbound(topic, ros_type, fields)` there. This module publishes nothing into
the fleet (`ros2.live` does).
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import msgpack
import zenoh
from zenoh import ext

from twinfleet.ros2.graph import BridgeGraph, Declared, Inbound
from twinfleet.ros2.interfaces import Interfaces, ros_messages
from twinfleet.ros2.mapping import Ros2Mapping
from twinfleet.ros2.wire import EntityKind
from twinfleet.runtime.host.keys import ANY, topic_in_fleet
from twinfleet.runtime.host.zenoh_transport import zenoh_config

DEFAULT_ROUTER = "tcp/127.0.0.1:7447"
OnInbound = Callable[[str, str, dict[str, Any]], None]


def ros_config(router: str) -> zenoh.Config:
    """A client session on the ROS 2 network's router (loopback rules as the fleet's)."""
    return zenoh_config(connect=[router], mode="client")


class RosSide:
    """The bridge's ROS 2 session (module docstring)."""

    def __init__(self, session: zenoh.Session, mapping: Ros2Mapping, *, domain: int = 0,
                 inbound: Mapping[str, str] | None = None,
                 on_inbound: OnInbound | None = None) -> None:
        self.session, self.mapping = session, mapping
        self.graph = BridgeGraph(domain, str(session.zid()))
        self.check = Inbound(self.graph.types)
        self.on_inbound = on_inbound
        #: the types carried by their fields when the mapping makes nothing of a message
        self.interfaces: Interfaces | None = None
        self.published = 0
        self._tokens: list[Any] = []
        self._publishers: dict[str, Any] = {}  # by endpoint token
        self._subscribers: list[Any] = []
        self.add_node(None)
        for topic, ros_type in (inbound or {}).items():
            self.subscribe(topic, ros_type)

    def add_node(self, fleet_node: str | None) -> None:
        """Make `fleet_node` (None: the bridge itself) a ROS node, if it is not one yet."""
        _, token = self.graph.node(fleet_node)
        if token is not None:
            self._tokens.append(self.session.liveliness().declare_token(token))

    def deliver(self, key: str, payload: bytes) -> int:
        """Publish what one fleet sample maps to; how many ROS 2 messages that was."""
        where = topic_in_fleet(ANY, key)
        if where is None:
            return 0
        try:
            env = msgpack.unpackb(payload, raw=False, strict_map_key=False)
        except Exception:  # msgpack raises several unrelated types: not a fleet message
            return 0
        if not isinstance(env, dict) or not isinstance(env.get("data"), dict):
            return 0
        outputs = ros_messages(self.mapping, self.interfaces, where.topic, str(env.get("type")),
                               env["data"], int(env.get("stamp_ms") or 0))
        sender = env.get("sender") if isinstance(env.get("sender"), str) else None
        for topic, ros_type, fields in outputs:
            self.publish(topic, ros_type, fields, owner=sender or None)
        return len(outputs)

    def publish(self, topic: str, ros_type: str, fields: Mapping[str, Any], *,
                owner: str | None = None) -> None:
        """Publish one ROS 2 message as `owner`'s (declaring the publisher the first time)."""
        declared, new = self.graph.declare(EntityKind.PUBLISHER, topic, ros_type, owner=owner,
                                           latched=topic in self.mapping.latched)
        if new:
            self.add_node(owner)
            self._declare_publisher(declared)
        payload = self.graph.types.encode(ros_type, fields)
        attachment = self.graph.attachment(declared, time.time_ns())
        self._publishers[declared.token].put(payload, attachment=attachment)
        self.published += 1

    def _declare_publisher(self, declared: Declared) -> None:
        pub: zenoh.Publisher | ext.AdvancedPublisher
        if declared.endpoint.qos.depth == 1 and declared.endpoint.topic in self.mapping.latched:
            pub = ext.declare_advanced_publisher(
                self.session, declared.key, cache=ext.CacheConfig(max_samples=1),
                publisher_detection=True, congestion_control=zenoh.CongestionControl.BLOCK)
        else:
            pub = self.session.declare_publisher(
                declared.key, congestion_control=zenoh.CongestionControl.BLOCK)
        self._publishers[declared.token] = pub
        self._tokens.append(self.session.liveliness().declare_token(declared.token))

    def subscribe(self, topic: str, ros_type: str, *, owner: str | None = None) -> Declared:
        """Take `topic` from ROS 2, as `owner`'s subscription (None: the bridge's)."""
        declared, new = self.graph.declare(EntityKind.SUBSCRIPTION, topic, ros_type,
                                           owner=owner)
        if not new:
            return declared
        self.add_node(owner)

        def on_sample(sample: zenoh.Sample) -> None:
            attachment = sample.attachment.to_bytes() if sample.attachment is not None else None
            fields = self.check.check(ros_type, sample.payload.to_bytes(), attachment)
            if fields is not None and self.on_inbound is not None:
                self.on_inbound(topic, ros_type, fields)

        self._subscribers.append(self.session.declare_subscriber(declared.key, on_sample))
        self._tokens.append(self.session.liveliness().declare_token(declared.token))
        return declared

    def close(self) -> None:
        """Undeclare everything (advanced publishers too); the caller closes the session."""
        for entity in [*self._subscribers, *self._publishers.values(), *self._tokens]:
            with contextlib.suppress(Exception):  # already gone with the session
                entity.undeclare()
        self._subscribers.clear()
        self._publishers.clear()
        self._tokens.clear()


def parse_routes(items: Sequence[str]) -> dict[str, str]:
    """``/goal_pose=/r1/goal`` items (ROS 2 topic = fleet topic) as {ROS topic: fleet topic}.

    Raises:
        ValueError: an item without ``=``, or a side that is not an absolute topic name.
    """
    out = {}
    for item in items:
        ros_topic, sep, fleet_topic = item.partition("=")
        if not sep or not ros_topic.startswith("/") or not fleet_topic.startswith("/"):
            raise ValueError(f"inbound {item!r}: expected /ros_topic=/fleet_topic, "
                             "e.g. /goal_pose=/r1/goal")
        out[ros_topic] = fleet_topic
    return out
