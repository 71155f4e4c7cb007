"""The node graph of a scenario, read once from the nodes' declared handlers.

Who subscribes to which topic (and to `/_liveliness`: the liveliness events of
a start or a crash are made here), who serves which service, each handler's
priority and each periodic timer's period, and every node's initial state
(as snapshot bytes): what a `System` needs to turn a handler's effects into
pending events, without running any node code.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import final

from twinfleet.checker.diagnosis import FIX_ENCODABLE, ContractBreachError, breach_line
from twinfleet.checker.world import Event
from twinfleet.runtime.contract.kinds import EventKind, FailureKind
from twinfleet.runtime.contract.messages import NodeAlive
from twinfleet.runtime.contract.node import (
    LIVELINESS_TOPIC,
    Durability,
    HandlerSpec,
    Node,
    Reliability,
)
from twinfleet.runtime.contract.rules import first_tick, keep_last_depth
from twinfleet.runtime.contract.snapshot import SnapshotError, snapshot
from twinfleet.runtime.scenario.spec import ScenarioError

Target = tuple[int, str, int]  # (node index, handler method, handler priority)


@final
class Topology:
    """Subscribers, servers, priorities and periods of a scenario's nodes.

    Args:
        nodes: the node objects, in scenario order.
        where: the scenario file, for error messages.

    Raises:
        ScenarioError: two nodes serve the same service, or a node declares what the checker
            does not model.
    """

    def __init__(self, nodes: Sequence[Node], where: object) -> None:
        self.nodes = tuple(nodes)
        self.subscribers: dict[str, list[Target]] = {}
        self.servers: dict[str, Target] = {}
        self.service_of: dict[tuple[int, str], str] = {}
        self._priorities: list[dict[str, int]] = []
        self._periods: dict[tuple[int, str], tuple[int, int]] = {}  # (period, phase)
        self.depths: dict[tuple[int, str], int] = {}  # KEEP_LAST depth per (node, handler)
        self.lossy: set[tuple[str, int]] = set()  # (topic, subscriber) BEST_EFFORT on a side
        self.liveliness: list[Target] = []  # the `/_liveliness` subscribers
        self.commuting: set[tuple[int, str]] = set()  # handlers declared `commutes=True`
        self.initial_states = tuple(_initial(node) for node in self.nodes)
        for i, node in enumerate(self.nodes):
            spec = node.spec()
            self._priorities.append({h.method: h.priority for h in spec.handlers})
            self.commuting.update((i, h.method) for h in spec.handlers if h.commutes)
            for h in spec.of_kind("subscribe"):
                topic = node.resolve(h.name or "")
                self.subscribers.setdefault(topic, []).append((i, h.method, h.priority))
                self.depths[(i, h.method)] = keep_last_depth(h.qos.depth)
            for h in spec.of_kind("service"):
                name = node.resolve(h.name or "")
                if name in self.servers:
                    other = self.nodes[self.servers[name][0]].name
                    raise ScenarioError(f"{where}: nodes: service {name} is served by both "
                                        f"{other} and {node.name}")
                self.servers[name] = (i, h.method, h.priority)
                self.service_of[(i, h.method)] = name
            for h in spec.of_kind("every"):
                self._periods[(i, h.method)] = (node.period_ms(h), h.phase_ms)
        self._qos(where)

    def _qos(self, where: object) -> None:
        """Which deliveries may be lost (BEST_EFFORT on the subscription or on the publishing
        node's declared `publications`), and who subscribes to `/_liveliness`."""
        best_effort = {node.resolve(topic) for node in self.nodes
                       for topic, q in node.spec().publications.items()
                       if q.reliability is Reliability.BEST_EFFORT}
        for i, node in enumerate(self.nodes):
            spec = node.spec()
            for h in spec.of_kind("subscribe"):
                topic = node.resolve(h.name or "")
                if topic == LIVELINESS_TOPIC:
                    self.liveliness.append((i, h.method, h.priority))
                    continue
                if h.qos.reliability is Reliability.BEST_EFFORT or topic in best_effort:
                    self.lossy.add((topic, i))

    def refuse_late_joiners(self, crashing: Sequence[int], where: object) -> None:
        """Refuse TRANSIENT_LOCAL subscriptions of nodes that may crash: restarted, such a
        node gets the latched samples replayed live, which the checker does not model. (With
        no restart every subscription exists before any `@on_start` runs, live too: nodes
        wait for their peers, so durability changes nothing.)"""
        for i in crashing:
            node = self.nodes[i]
            for h in node.spec().of_kind("subscribe"):
                if h.qos.durability is Durability.TRANSIENT_LOCAL:
                    raise ScenarioError(
                        f"{where}: node {node.name}: {h.method} ({h.name}) has qos durability "
                        "TRANSIENT_LOCAL and the node may crash: the replay to a restarted "
                        "node is not modelled; use VOLATILE or no crash fault for it")

    def started(self) -> Iterator[Event]:
        """The liveliness events of a fleet's start: every node appearing, at t=0, to every
        `/_liveliness` subscriber (itself included, as a Zenoh liveliness subscriber sees
        its own session's tokens)."""
        for k, method, prio in self.liveliness:
            for n, node in enumerate(self.nodes):
                yield Event(0, EventKind.LIVELINESS, k, method, n, (NodeAlive(node.name, True),),
                            prio)

    def crashed(self, j: int, now: int) -> Iterator[Event]:
        """The liveliness events of node `j` crashing and restarting at `now`: to every
        other subscriber `j` gone then back; to `j` itself every node that is alive."""
        name = self.nodes[j].name
        for k, method, prio in self.liveliness:
            if k == j:
                for n, node in enumerate(self.nodes):
                    yield Event(now, EventKind.LIVELINESS, k, method, n,
                                (NodeAlive(node.name, True),), prio)
                continue
            for alive in (False, True):
                yield Event(now, EventKind.LIVELINESS, k, method, j, (NodeAlive(name, alive),),
                            prio)

    def priority(self, node: int, method: str) -> int:
        """Handler priority of `method` on node index `node` (0 if undeclared)."""
        return self._priorities[node].get(method, 0)

    def period(self, node: int, method: str) -> tuple[int, int]:
        """(period, phase) in ms of the `@every` handler `method` of node `node`."""
        return self._periods[(node, method)]

    def periodic(self, node: int, now: int) -> Iterator[Event]:
        """The first firing after `now` of each `@every` timer of node `node`, as live
        (`runtime.contract.rules.first_tick`)."""
        for h in self.nodes[node].spec().of_kind("every"):
            yield Event(first_tick(*self._periods[(node, h.method)], now), EventKind.PERIODIC,
                        node, h.method, node, (), h.priority)

    def starts(self, node: int) -> tuple[HandlerSpec, ...]:
        """The `@on_start` handlers of node `node`, in declaration order."""
        return self.nodes[node].spec().of_kind("start")

    def start_event(self, node: int, spec: HandlerSpec, now: int) -> Event:
        """The event that runs start handler `spec` of node `node` at `now`."""
        return Event(now, EventKind.START, node, spec.method, node, (), spec.priority)


def _initial(node: Node) -> bytes:
    """The encoded initial state of `node`; one that cannot be encoded is a breach."""
    try:
        return snapshot(node.initial_state())
    except SnapshotError as exc:
        raise ContractBreachError(breach_line(
            FailureKind.CONTRACT, node.name, "initial_state", f"its initial state cannot be "
            f"encoded ({exc}); fix: {FIX_ENCODABLE}")) from None
