"""The live bridge: a running fleet as ROS 2 nodes (`twinfleet ros2 bridge`, `launch --ros2`).

Two Zenoh sessions. On the fleet's router, a `FleetTap` hears every sample of the
fleet (as the viewers do) and a liveliness subscriber its nodes; each node
becomes a ROS node of its own name and each sample is handed to `RosSide.deliver`,
which publishes what the mapping makes of it on the ROS 2 network. On the ROS 2
router (``rmw_zenohd``'s), `RosSide` speaks rmw_zenoh's protocol.

Inbound (``routes``: ROS 2 topic → fleet topic). Each routed ROS 2 topic is a
subscription of the fleet node that subscribes to the fleet topic, typed by the
mapping (`mapping.InboundMapping.inbound_type`). A sample passes `graph.Inbound`
(size, attachment, CDR to its end, finite numbers), then the mapping makes the
fleet message of it (`Forwarder`), which is checked against its class's annotations
(`runtime.core.guard.check_message`) and published on the fleet topic signed with
the fleet's *bridge key*: the nodes take it on their ``external_topics`` only and
count it, and the live verdict says the run took external input. The bridge never
signs with the fleet key, and a fleet launched without a bridge has no bridge key:
then nothing is routed in. What fails any step is dropped and counted by reason.
"""

from __future__ import annotations

import asyncio
import contextlib
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import msgpack
import zenoh

from twinfleet.ros2.bridge import DEFAULT_ROUTER, RosSide, ros_config
from twinfleet.ros2.graph import Inbound
from twinfleet.ros2.interfaces import fleet_interfaces
from twinfleet.ros2.mapping import (
    InboundMapping,
    MappingError,
    NoMapping,
    Ros2Mapping,
    load_mapping,
    mapping_of_scene,
)
from twinfleet.runtime.access.fleetauth import MonitorAuth
from twinfleet.runtime.contract.messages import encode
from twinfleet.runtime.contract.names import BRIDGE_SENDER
from twinfleet.runtime.core.guard import Rejected, check_message, signer
from twinfleet.runtime.host.keys import (
    KeyKind,
    fleet_key,
    kind_expr,
    parse_node_key,
    topic_in_fleet,
    topic_key,
)
from twinfleet.runtime.tools.monitor.tap import FleetTap, tap_config

SENDER = BRIDGE_SENDER  # the envelope sender of what the bridge forwards into the fleet
RETRY_S = 0.5
QUERY_S = 1.0


class BridgeError(ValueError):
    """The bridge cannot run as asked; the text says why."""


@dataclass(frozen=True)
class BridgeSettings:
    """Where the bridge connects and what it routes."""

    fleet: str
    endpoint: str  # the fleet's router
    auth: MonitorAuth = field(default_factory=MonitorAuth)
    domain: int = 0
    router: str = DEFAULT_ROUTER  # the ROS 2 network's
    routes: Mapping[str, str] = field(default_factory=dict)  # ROS 2 topic → fleet topic
    mapping: str | None = None  # module:Name; default: the scene's, else `NoMapping`
    near: tuple[Path, ...] = ()  # folders the mapping's module is searched in too


class Forwarder:
    """Routed ROS 2 messages as signed fleet samples (sans I/O)."""

    def __init__(self, fleet: str, mapping: InboundMapping, routes: Mapping[str, str],
                 bridge_key: bytes, check: Inbound) -> None:
        self.fleet, self.mapping, self.routes = fleet, mapping, dict(routes)
        self.bridge_key, self.check = bridge_key, check
        self.now_ms = 0  # fleet time: the latest stamp the bridge heard from the fleet
        self.forwarded = 0
        self._seq: dict[str, int] = {}
        # one signer per key: one sender id, numbers 0, 1, ... as the nodes' replay windows expect
        self._signers: dict[str, Callable[[bytes], bytes | None]] = {}

    def forward(self, ros_topic: str, ros_type: str,
                fields: Mapping[str, Any]) -> tuple[str, bytes, bytes | None] | None:
        """(fleet key, payload, attachment) of one checked ROS 2 message, or None (counted)."""
        fleet_topic = self.routes[ros_topic]
        try:
            msg = self.mapping.inbound(fleet_topic, ros_type, fields)
            check_message(msg)
        except Rejected:
            self.check.refuse("invalid fleet message")
            return None
        except ValueError as exc:  # the mapping's reason
            self.check.refuse(str(exc) or "not mappable")
            return None
        except (KeyError, TypeError):
            self.check.refuse("not mappable")
            return None
        seq = self._seq[fleet_topic] = self._seq.get(fleet_topic, 0) + 1
        payload = encode(msg, stamp_ms=self.now_ms, seq=seq, sender=SENDER)
        key = topic_key(self.fleet, fleet_topic)
        self.forwarded += 1
        attach = self._signers.setdefault(key, signer(self.bridge_key, key))
        return key, payload, attach(payload)


@dataclass
class _FleetView:
    """What the bridge learns from the fleet before the first sample."""

    scene: str | None = None
    latched: list[str] = field(default_factory=list)
    nodes: set[str] = field(default_factory=set)
    subscribers: dict[str, str] = field(default_factory=dict)  # fleet topic → a node


def _look(session: zenoh.Session, fleet: str) -> _FleetView:
    """The fleet's description (scene, latched topics), nodes and subscriptions (blocking)."""
    view = _FleetView()
    for reply in session.get(fleet_key(fleet), timeout=QUERY_S):
        if reply.ok is not None:
            with contextlib.suppress(Exception):  # a malformed description: topics only
                doc = msgpack.unpackb(reply.ok.payload.to_bytes(), raw=False)
                view.scene = doc.get("scene")
                view.latched = [t for t in doc.get("latched", ()) if isinstance(t, str)]
    for kind in (KeyKind.NODE, KeyKind.SUB):
        for reply in session.liveliness().get(kind_expr(fleet, kind), timeout=QUERY_S):
            if reply.ok is None:
                continue
            with contextlib.suppress(ValueError):
                key = parse_node_key(str(reply.ok.key_expr), kind)
                view.nodes.add(key.node)
                if kind is KeyKind.SUB and key.name:
                    view.subscribers.setdefault(key.name, key.node)
    return view


class FleetBridge:
    """One fleet bridged to one ROS 2 network (module docstring); `run` until `stop`."""

    def __init__(self, settings: BridgeSettings, out: TextIO = sys.stdout) -> None:
        self.settings, self.out = settings, out
        self.side: RosSide | None = None
        self.forwarder: Forwarder | None = None
        self.tap: FleetTap | None = None
        self.stop = asyncio.Event()
        self.ready = asyncio.Event()
        self.reached = False  # whether the ROS 2 router answered
        self._ros: zenoh.Session | None = None
        self._watch: Any = None
        self._reported: set[str] = set()

    def say(self, text: str) -> None:
        """One line of the bridge's output."""
        print(f"[ros2] {text}", file=self.out, flush=True)

    async def run(self) -> None:
        """Open both sides, bridge until `stop` is set, then close both."""
        s = self.settings
        try:
            self._ros = await self._open_ros()
            if self._ros is None:
                return
            self.reached = True
            operator = MonitorAuth(operator=s.auth.operator or s.auth.monitor)
            self.tap = FleetTap(lambda: tap_config(s.endpoint, operator), s.fleet, self._deliver)
            self._loop = asyncio.get_running_loop()
            await self.tap.open(prepare=self._prepare)
            assert self.side is not None
            self.say(f"fleet {s.fleet!r} on ROS 2 domain {s.domain} at {s.router}: nodes "
                     f"{', '.join(sorted(self.side.graph.nodes))}" + self._routes_text())
            self.ready.set()
            await self.stop.wait()
        finally:
            await self._close()

    async def _open_ros(self) -> zenoh.Session | None:
        said = False
        while not self.stop.is_set():
            try:
                return await asyncio.to_thread(zenoh.open, ros_config(self.settings.router))
            except zenoh.ZError:
                if not said:
                    self.say(f"waiting for the ROS 2 router at {self.settings.router} "
                             "(rmw_zenohd)")
                    said = True
                await asyncio.sleep(RETRY_S)
        return None

    def _prepare(self, session: zenoh.Session) -> None:
        """On a worker thread, before the first sample: learn the fleet, build the ROS side."""
        s = self.settings
        view = _look(session, s.fleet)
        name = s.mapping or mapping_of_scene(view.scene)
        mapping = load_mapping(name, s.near) if name is not None else NoMapping(
            frozenset(view.latched))  # standard types as they are, the others by fields
        assert self._ros is not None
        self.side = RosSide(self._ros, mapping, domain=s.domain, on_inbound=self._on_inbound)
        self.side.interfaces = fleet_interfaces(self.side.graph.types)
        for node in sorted(view.nodes):
            self.side.add_node(node)
        self._route(mapping, view)
        assert self.tap is not None
        self._loop.call_soon_threadsafe(self.tap.add_latched, view.latched)
        self._watch = session.liveliness().declare_subscriber(
            kind_expr(s.fleet, KeyKind.NODE), self._on_node)

    def _route(self, mapping: Ros2Mapping, view: _FleetView) -> None:
        s, side = self.settings, self.side
        assert side is not None
        if not s.routes:
            return
        if not isinstance(mapping, InboundMapping):
            raise BridgeError(f"{type(mapping).__name__} takes nothing from ROS 2 (it has no "
                              "inbound_type/inbound)")
        if s.auth.bridge is None:
            raise BridgeError(f"fleet {s.fleet!r} was not launched to take external input: "
                              "launch it with --ros2 (or a ros2: section) to route topics in")
        for ros_topic, fleet_topic in s.routes.items():
            ros_type = mapping.inbound_type(fleet_topic)
            if ros_type is None:
                raise BridgeError(f"inbound {ros_topic}={fleet_topic}: the mapping routes "
                                  f"nothing into {fleet_topic}")
            side.subscribe(ros_topic, ros_type, owner=view.subscribers.get(fleet_topic))
        self.forwarder = Forwarder(s.fleet, mapping, s.routes, s.auth.bridge, side.check)

    def _routes_text(self) -> str:
        routes = self.settings.routes
        return "; inbound " + ", ".join(f"{r} -> {f}" for r, f in routes.items()) if routes else ""

    def _on_node(self, sample: zenoh.Sample) -> None:
        """On a Zenoh thread: a fleet node appeared; make it a ROS node on the loop."""
        if sample.kind == zenoh.SampleKind.PUT and self.side is not None:
            with contextlib.suppress(ValueError, RuntimeError):
                node = parse_node_key(str(sample.key_expr), KeyKind.NODE).node
                self._loop.call_soon_threadsafe(self.side.add_node, node)

    def _deliver(self, key: str, payload: bytes) -> None:
        if self.side is None:
            return
        if self.forwarder is not None and topic_in_fleet(self.settings.fleet, key) is not None:
            env: Any = None
            with contextlib.suppress(Exception):  # only the stamp and sender are read here
                env = msgpack.unpackb(payload, raw=False)
            if isinstance(env, dict):
                if env.get("sender") == SENDER:
                    return  # what the bridge forwarded comes back: it is ROS 2's already
                if isinstance(env.get("stamp_ms"), int):
                    self.forwarder.now_ms = max(self.forwarder.now_ms, env["stamp_ms"])
        self.side.deliver(key, payload)

    def _on_inbound(self, ros_topic: str, ros_type: str, fields: dict[str, Any]) -> None:
        """On a Zenoh thread: a checked ROS 2 message; forward it on the loop."""
        with contextlib.suppress(RuntimeError):  # the loop is closing
            self._loop.call_soon_threadsafe(self._forward, ros_topic, ros_type, fields)

    def _forward(self, ros_topic: str, ros_type: str, fields: dict[str, Any]) -> None:
        if self.forwarder is None or self.tap is None or self.tap.session is None:
            return
        made = self.forwarder.forward(ros_topic, ros_type, fields)
        if made is None:
            self._report_drops()
            return
        key, payload, attachment = made
        self.tap.session.put(key, payload, attachment=attachment)
        self.say(f"{ros_topic} -> {self.settings.routes[ros_topic]}: forwarded "
                 f"(#{self.forwarder.forwarded})")

    def _report_drops(self) -> None:
        """Say each drop reason the first time it happens (`summary` has the counts)."""
        assert self.side is not None
        for reason in self.side.check.dropped:
            if reason not in self._reported:
                self._reported.add(reason)
                self.say(f"dropped an inbound sample: {reason} (first of its kind)")

    def summary(self) -> str:
        """The counters: published, inbound accepted, forwarded and dropped by reason."""
        if self.side is None:
            return "not connected"
        check = self.side.check
        dropped = ", ".join(f"{r} {n}" for r, n in sorted(check.dropped.items())) or "none"
        forwarded = self.forwarder.forwarded if self.forwarder is not None else 0
        return (f"published {self.side.published} ROS 2 messages; inbound: forwarded "
                f"{forwarded}, dropped {sum(check.dropped.values())} ({dropped})")

    async def _close(self) -> None:
        if self.side is not None and self.ready.is_set():
            self._report_drops()
            self.say(self.summary())
        if self._watch is not None:
            with contextlib.suppress(Exception):
                self._watch.undeclare()
        if self.tap is not None:
            await self.tap.close()
        if self.side is not None:
            self.side.close()
        if self._ros is not None:
            self._ros.close()


def launch_driver(routes: Mapping[str, str], *, domain: int, router: str,
                  mapping: str | None, near: tuple[Path, ...] = ()) -> Any:
    """A `run_fleet` driver that runs the bridge beside the fleet it launched, until the run
    ends (the fleet's credentials are the launcher's own, bridge key included). A bridge
    that fails, or never reaches its router, makes the run INCONCLUSIVE with that reason
    (`Fleet.unmet`): the run was asked to be on ROS 2 and was not."""
    from twinfleet.runtime.fleet.live_fleet import Fleet

    async def drive(fleet: Fleet) -> str:
        creds = fleet.creds
        auth = MonitorAuth(creds.key, creds.node, creds.monitor, creds.bridge)
        settings = BridgeSettings(fleet.scenario.fleet, fleet.endpoint, auth, domain, router,
                                  routes, mapping, near)
        bridge = FleetBridge(settings, fleet.out)
        try:
            await fleet.all_alive.wait()  # every node's subscriptions are known then
            await bridge.run()
        except (BridgeError, MappingError) as exc:
            fleet.unmet.append(f"the ROS 2 bridge failed: {exc}")
            return f"ros2 bridge: {exc}"
        finally:
            if fleet.all_alive.is_set() and not bridge.reached and not fleet.unmet:
                fleet.unmet.append(f"the ROS 2 bridge never reached its router at {router} "
                                   "(is rmw_zenohd running there?)")
        return "ros2 bridge stopped"

    return drive
