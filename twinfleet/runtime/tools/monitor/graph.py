"""Reading a running fleet's graph over one Zenoh session: nodes, topics, services, types.

What the monitors (`runtime.tools.monitor.graph_verbs`) and the Foxglove bridge know about a
fleet comes from these sources, all served by the fleet's own processes:

* liveliness tokens (`runtime.host.keys`, ``@node``, ``@pub``, ``@sub``, ``@srv``):
  who runs, publishes, subscribes and serves;
* ``@info/<node>`` (`runtime.host.introspect`): class, parameters, declared QoS;
* ``@fleet`` (`runtime.host.keys.fleet_key`, served by the launcher): the
  fleet's scene and latched topics;
* ``@types/<node>`` (`runtime.host.schemas`): the JSON Schemas of the message
  types each process knows;
* the samples themselves: a topic's type is the ``type`` of its envelopes
  (publishers are not declared ahead in twinfleet, so `sample_types` listens,
  with history for latched topics, for at most the discovery timeout).

Functions here are synchronous and take an open `zenoh.Session`.
"""

from __future__ import annotations

import contextlib
import json
import time
from collections.abc import Iterable
from collections.abc import Set as AbstractSet
from dataclasses import dataclass, field
from typing import Any

import msgpack
import zenoh
from zenoh import ext

from twinfleet.runtime.contract.node import Durability
from twinfleet.runtime.core.statistics import NodeStatistics, StatisticsError
from twinfleet.runtime.fleet.node_main import read_statistics
from twinfleet.runtime.host.keys import (
    ANY,
    InvalidKey,
    KeyKind,
    NodeKey,
    kind_expr,
    node_key,
    parse_node_key,
    topic_expr,
    topic_in_fleet,
)

_POLL_S = 0.02


@dataclass
class Graph:
    """Who is there: node names and, per (fleet, name), the nodes on each side."""

    nodes: list[tuple[str, str]] = field(default_factory=list)
    publishers: dict[tuple[str, str], list[str]] = field(default_factory=dict)
    subscribers: dict[tuple[str, str], list[str]] = field(default_factory=dict)
    servers: dict[tuple[str, str], list[str]] = field(default_factory=dict)

    def fleets(self) -> list[str]:
        """The fleets that have at least one node."""
        return sorted({f for f, _ in self.nodes})

    def topics(self) -> list[tuple[str, str]]:
        """(fleet, topic) of every topic with a publisher or a subscriber."""
        return sorted({*self.publishers, *self.subscribers})

    def entities_of(self, fleet: str, node: str) -> dict[str, list[str]]:
        """The topics `node` publishes and subscribes and the services it serves."""
        def mine(table: dict[tuple[str, str], list[str]]) -> list[str]:
            return sorted(n for (f, n), who in table.items() if f == fleet and node in who)
        return {"publishers": mine(self.publishers), "subscribers": mine(self.subscribers),
                "servers": mine(self.servers)}


def liveliness_keys(session: zenoh.Session, key_expr: str, timeout_s: float) -> list[str]:
    """Keys of the liveliness tokens matching `key_expr`."""
    keys = {str(r.ok.key_expr) for r in session.liveliness().get(key_expr, timeout=timeout_s)
            if r.ok is not None}
    return sorted(keys)


def read_graph(session: zenoh.Session, fleet: str, timeout_s: float) -> Graph:
    """The graph of `fleet` (``*``: every fleet behind the router)."""
    graph = Graph()
    tables = {KeyKind.PUB: graph.publishers, KeyKind.SUB: graph.subscribers,
              KeyKind.SRV: graph.servers}
    for kind in (KeyKind.NODE, *tables):
        for token in _tokens(session, kind_expr(fleet, kind), kind, timeout_s):
            if kind is KeyKind.NODE:
                graph.nodes.append((token.fleet, token.node))
            else:
                tables[kind].setdefault((token.fleet, token.name), []).append(token.node)
    for table in tables.values():
        for who in table.values():
            who.sort()
    return graph


def _tokens(session: zenoh.Session, key: str, kind: KeyKind, timeout_s: float) -> list[NodeKey]:
    """The liveliness tokens of `kind` matching `key`, parsed; malformed ones are skipped."""
    found = []
    for token in liveliness_keys(session, key, timeout_s):
        with contextlib.suppress(InvalidKey):
            found.append(parse_node_key(token, kind))
    return found


def _query(session: zenoh.Session, key: str, timeout_s: float) -> list[tuple[str, bytes]]:
    return [(str(r.ok.key_expr), r.ok.payload.to_bytes())
            for r in session.get(key, timeout=timeout_s) if r.ok is not None]


def node_infos(session: zenoh.Session, fleet: str, timeout_s: float,
               node: str = "*") -> dict[tuple[str, str], dict[str, Any]]:
    """(fleet, node) → the node's self-description (`runtime.host.introspect.node_description`)."""
    return _node_replies(session, node_key(fleet, KeyKind.INFO, node), KeyKind.INFO, timeout_s)


def node_stats(session: zenoh.Session, fleet: str, timeout_s: float
               ) -> dict[tuple[str, str], NodeStatistics | StatisticsError]:
    """(fleet, node) → the node's counters (`@stats`), or why they could not be read (a
    node of another twinfleet version: `NodeStatistics.from_dict` is strict)."""
    found: dict[tuple[str, str], NodeStatistics | StatisticsError] = {}
    for reply_key, payload in _query(session, kind_expr(fleet, KeyKind.STATS), timeout_s):
        try:
            where = parse_node_key(reply_key, KeyKind.STATS)
        except ValueError:  # InvalidKey: not a node's statistics key
            continue
        try:
            found[(where.fleet, where.node)] = read_statistics(payload)
        except StatisticsError as exc:
            found[(where.fleet, where.node)] = exc
    return found


def fleet_infos(session: zenoh.Session, fleet: str, timeout_s: float) -> dict[str, dict[str, Any]]:
    """fleet → its description (`runtime.host.introspect.fleet_description`): scene, latched."""
    found = {}
    for key, payload in _query(session, kind_expr(fleet, KeyKind.FLEET), timeout_s):
        with contextlib.suppress(ValueError, TypeError):  # InvalidKey is a ValueError
            where = parse_node_key(key, KeyKind.FLEET)
            doc = msgpack.unpackb(payload, raw=False)
            if isinstance(doc, dict):
                found[where.fleet] = doc
    return found


def _node_replies(session: zenoh.Session, key: str, kind: KeyKind, timeout_s: float
                  ) -> dict[tuple[str, str], Any]:
    """(fleet, node) → the msgpack reply of each node's `kind` queryable matching `key`."""
    found = {}
    for reply_key, payload in _query(session, key, timeout_s):
        with contextlib.suppress(ValueError, TypeError):  # InvalidKey is a ValueError
            where = parse_node_key(reply_key, kind)
            found[(where.fleet, where.node)] = msgpack.unpackb(payload, raw=False)
    return found


def served_schemas(session: zenoh.Session, fleet: str, timeout_s: float
                   ) -> dict[str, tuple[dict[str, Any], list[str]]]:
    """Type name → (data schema, the nodes that serve it), from every ``@types`` queryable."""
    found: dict[str, tuple[dict[str, Any], list[str]]] = {}
    for key, payload in _query(session, kind_expr(fleet, KeyKind.TYPES), timeout_s):
        try:
            node = parse_node_key(key, KeyKind.TYPES).node
            schemas = json.loads(payload)
        except ValueError:  # InvalidKey is one too
            continue
        for name, schema in schemas.items() if isinstance(schemas, dict) else ():
            found.setdefault(name, (schema, []))[1].append(node)
    return found


_LATCHED = Durability.TRANSIENT_LOCAL.value  # as `introspect` writes a QoS's durability


def latched_topics(infos: dict[tuple[str, str], dict[str, Any]]) -> set[tuple[str, str]]:
    """(fleet, topic) of every topic that some node declares transient-local."""
    latched = set()
    for (fleet, _), info in infos.items():
        for table in ("publication_qos", "subscriptions"):
            for topic, qos in (info.get(table) or {}).items():
                if isinstance(qos, dict) and qos.get("durability") == _LATCHED:
                    latched.add((fleet, topic))
    return latched


def subscribe(session: zenoh.Session, key: str, callback: Any, *, history: bool) -> Any:
    """A subscriber on `key`; with `history`, an advanced one that also gets the latched
    samples that publishers keep (transient-local topics)."""
    if not history:
        return session.declare_subscriber(key, callback)
    return ext.declare_advanced_subscriber(
        session, key, callback,
        history=ext.HistoryConfig(detect_late_publishers=True, max_samples=1))


def envelope_type(payload: bytes) -> str | None:
    """The ``type`` of a raw envelope, or None if it is not one."""
    try:
        env = msgpack.unpackb(payload, raw=False, strict_map_key=False)
    except Exception:  # msgpack raises several unrelated types
        return None
    kind = env.get("type") if isinstance(env, dict) else None
    return kind if isinstance(kind, str) else None


def sample_types(session: zenoh.Session, fleet: str, topics: Iterable[tuple[str, str]],
                 timeout_s: float, latched: AbstractSet[tuple[str, str]] = frozenset()
                 ) -> dict[tuple[str, str], str]:
    """(fleet, topic) → message type, from the first sample of each topic within `timeout_s`."""
    wanted = set(topics)
    seen: dict[tuple[str, str], str] = {}
    if not wanted:
        return seen

    def on_sample(sample: zenoh.Sample) -> None:
        parsed = topic_in_fleet(ANY, str(sample.key_expr))
        where = None if parsed is None else (parsed.fleet, parsed.topic)
        if where in wanted and where not in seen:
            kind = envelope_type(sample.payload.to_bytes())
            if kind is not None:
                seen[where] = kind

    subs = [subscribe(session, topic_expr(f, t), on_sample, history=(f, t) in latched)
            for f, t in sorted(wanted)]
    try:
        deadline = time.monotonic() + timeout_s
        while len(seen) < len(wanted) and time.monotonic() < deadline:
            time.sleep(_POLL_S)
    finally:
        for sub in subs:
            sub.undeclare()
    return dict(seen)


def topic_types(session: zenoh.Session, fleet: str, topics: Iterable[tuple[str, str]],
                timeout_s: float, infos: dict[tuple[str, str], dict[str, Any]] | None = None
                ) -> dict[tuple[str, str], str]:
    """(fleet, topic) → type: what the publishing nodes say (``@info`` ``publications``), else
    the type the subscribing nodes declare they take (``subscription_types``, from their
    handlers' annotations: known before any message), else the first sample within
    `timeout_s` (a publisher that is not a twinfleet node)."""
    infos = node_infos(session, fleet, timeout_s) if infos is None else infos
    said = {(f, topic): kind for table in ("subscription_types", "publications")
            for (f, _), info in infos.items()
            for topic, kind in (info.get(table) or {}).items() if kind != "?"}
    wanted = list(topics)
    found = {t: said[t] for t in wanted if t in said}
    rest = [t for t in wanted if t not in found]
    found.update(sample_types(session, fleet, rest, timeout_s, latched_topics(infos)))
    return found

def fleet_schemas(session: Any, fleet: str, timeout_s: float = 1.0) -> dict[str, dict[str, Any]]:
    """Message data schemas served by the running node processes of `fleet` ('*': all)."""
    found: dict[str, dict[str, Any]] = {}
    if session is None:
        return found
    for reply in session.get(kind_expr(fleet, KeyKind.TYPES), timeout=timeout_s):
        if reply.ok is not None:
            with contextlib.suppress(ValueError, TypeError):  # a node of another version
                found.update(json.loads(reply.ok.payload.to_bytes()))
    return found
