"""Logic of the monitoring commands, with ROS 2's verbs: `node list|info`, `topic
list|info|type|echo|hz|pub`, `service list|call`, `param list|get`, `interface list|show`.

Each command is a plain function taking a `Connection` (endpoint and fleet,
from --connect or the fleet registry) and returning an exit code (0 ok, 2 bad
input or no answer); `twinfleet.cli.runtime_commands` only parses arguments. What a monitor
knows comes from the fleet itself (`runtime.tools.monitor.graph`): liveliness tokens, the
nodes' ``@info`` and ``@types`` queryables, and the samples; no node code is
imported. A fleet or a topic that is not there is an error after the discovery
timeout, never a silent wait. Subscriber callbacks only append to a deque (no
wake-up per sample); the main thread polls it.

`fleet` may be ``*`` for read-only commands behind --connect (every fleet on
the router); names are then shown as ``fleet:/name``.
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any, TextIO

import yaml
import zenoh

from twinfleet.runtime.access.connection import (
    CommandError,
    Connection,
    unreachable_hint,
    zenoh_conf,
    zenoh_error_text,
)
from twinfleet.runtime.contract.messages import registered_types
from twinfleet.runtime.core.statistics import NodeStatistics
from twinfleet.runtime.host.schemas import dataclass_schema
from twinfleet.runtime.tools.monitor import graph as g
from twinfleet.runtime.tools.monitor.payload import PayloadError, normalise_type

POLL_S = 0.02
SETTLE_S = 5.0  # with a warning to give instead of an error: how long nodes may take to appear


@contextmanager
def open_session(conn: Connection, *, write: bool = False) -> Iterator[zenoh.Session]:
    """A client session to the fleet's router (with the login `conn` holds: the operator's
    for a command that publishes or calls, `write`); a dead endpoint is a `CommandError`."""
    try:
        session = zenoh.open(zenoh_conf(conn.endpoint, conn.auth, write=write))
    except zenoh.ZError as exc:
        how = unreachable_hint(conn.endpoint, conn.auth, registry=conn.found == "registry")
        raise CommandError(f"cannot reach the Zenoh router at {conn.endpoint} ({how}): "
                           f"{zenoh_error_text(exc)}") from None
    try:
        yield session
    finally:
        session.close()


def graph_of(session: zenoh.Session, conn: Connection, timeout_s: float,
             warn: TextIO | None = None) -> g.Graph:
    """The fleet's graph; a fleet with no node is an error naming the fleets that are there
    (with `warn`, a warning line there instead)."""
    graph = g.read_graph(session, conn.fleet, timeout_s)
    settle = time.monotonic() + SETTLE_S
    while warn is not None and conn.fleet != "*" and not graph.nodes and \
            time.monotonic() < settle:  # a fleet just launched: its nodes are starting
        graph = g.read_graph(session, conn.fleet, timeout_s)
    if conn.fleet != "*" and not graph.nodes:
        there = g.read_graph(session, "*", timeout_s).fleets()
        text = (f"no node of fleet {conn.fleet!r} answers at {conn.endpoint} within "
                f"{timeout_s:g} s" + (f"; fleets there: {', '.join(there)}" if there
                                      else "; no fleet runs there"))
        if warn is None:
            raise CommandError(text)
        print(f"warning: {text}; waiting", file=warn, flush=True)
    return graph


def _shown(conn: Connection, fleet: str, name: str) -> str:
    return name if conn.fleet != "*" else f"{fleet}:{name}"


def pick(conn: Connection, graph: g.Graph, name: str, table: str) -> tuple[str, str]:
    """(fleet, name) of a topic/service the user named (``fleet:/name`` behind '*')."""
    fleet, _, bare = name.rpartition(":") if conn.fleet == "*" else (conn.fleet, "", name)
    bare = bare if bare.startswith("/") else "/" + bare
    if conn.fleet == "*" and not fleet:
        fleets = graph.fleets()
        if len(fleets) != 1:
            raise CommandError(f"{name}: several fleets run at {conn.endpoint} "
                               f"({', '.join(fleets)}); give --fleet NAME")
        fleet = fleets[0]
    return fleet, bare


def node_list(conn: Connection, *, out: TextIO, stats: bool = False,
              timeout_s: float = 1.0) -> int:
    """Print the running nodes (one liveliness token each); with `stats`, their counters."""
    with open_session(conn) as session:
        graph = graph_of(session, conn, timeout_s)
        counters = g.node_stats(session, conn.fleet, timeout_s) if stats else {}
    for fleet, name in sorted(graph.nodes):
        line = _shown(conn, fleet, "/" + name)
        extra = counters.get((fleet, name))
        if isinstance(extra, NodeStatistics):
            line += "  " + extra.line()
        elif extra is not None:
            line += f"  (unreadable statistics: {extra})"
        print(line, file=out)
    out.flush()
    return 0


def node_info(conn: Connection, node: str, *, out: TextIO, timeout_s: float = 1.0) -> int:
    """`ros2 node info`: a node's topics with types, services, timers and parameters."""
    name = node.lstrip("/")
    with open_session(conn) as session:
        graph = graph_of(session, conn, timeout_s)
        fleet = _node_fleet(conn, graph, name)
        infos = g.node_infos(session, fleet, timeout_s, name)
        mine = graph.entities_of(fleet, name)
        topics = [(fleet, t) for t in mine["publishers"] + mine["subscribers"]]
        types = g.topic_types(session, fleet, topics, timeout_s, g.node_infos(session, fleet,
                                                                               timeout_s))
    info = infos.get((fleet, name), {})
    print(f"/{name}" + (f"  ({info['class']}, pid {info.get('pid')})" if info else ""), file=out)
    for label, key in (("Subscribers", "subscribers"), ("Publishers", "publishers"),
                       ("Service Servers", "servers")):
        print(f"  {label}:", file=out)
        for topic in mine[key]:
            kind = types.get((fleet, topic))
            print(f"    {topic}" + (f": {kind}" if kind else ""), file=out)
    if info:
        print("  Service Clients:", file=out)
        for service in info.get("clients", []):
            print(f"    {service}", file=out)
        print("  Timers:", file=out)
        for timer in info.get("timers", []):
            when = ("one-shot, set by ctx.after" if timer.get("after") else
                    f"every {timer['period_ms']} ms")
            print(f"    {timer['handler']}: {when}", file=out)
        print("  Parameters:", file=out)
        for key, value in info.get("params", {}).items():
            print(f"    {key}: {inline(value)}", file=out)
    out.flush()
    return 0


def _node_fleet(conn: Connection, graph: g.Graph, name: str) -> str:
    fleets = sorted({f for f, n in graph.nodes if n == name})
    if not fleets:
        names = ", ".join(sorted(n for _, n in graph.nodes))
        raise CommandError(f"no node named {name!r} runs in fleet {conn.fleet!r} at "
                           f"{conn.endpoint}; nodes: {names}")
    if len(fleets) > 1:
        raise CommandError(f"node {name!r} runs in several fleets ({', '.join(fleets)}); "
                           "give --fleet NAME")
    return fleets[0]


def inline(value: Any) -> str:
    return yaml.safe_dump(value, default_flow_style=True, width=10_000).strip().removesuffix(
        "\n...").removesuffix(" ...").strip()


def topic_list(conn: Connection, *, out: TextIO, verbose: bool = False, types: bool = False,
               timeout_s: float = 1.0) -> int:
    """Print the topics that running nodes publish or subscribe to (`-t`: with their types)."""
    with open_session(conn) as session:
        graph = graph_of(session, conn, timeout_s)
        found = {}
        if types:
            found = g.topic_types(session, conn.fleet, list(graph.topics()), timeout_s)
    for fleet, topic in graph.topics():
        line = _shown(conn, fleet, topic)
        if types:
            line += f" [{found.get((fleet, topic), 'unknown: no message yet')}]"
        if verbose:
            roles = [f"{label}: {', '.join(table.get((fleet, topic), []))}"
                     for label, table in (("publishers", graph.publishers),
                                          ("subscribers", graph.subscribers))
                     if table.get((fleet, topic))]
            line += f"  [{'; '.join(roles)}]"
        print(line, file=out)
    out.flush()
    return 0


def topic_info(conn: Connection, topic: str, *, out: TextIO, verbose: bool = False,
               timeout_s: float = 1.0) -> int:
    """`ros2 topic info`: type, publisher and subscription counts (`-v`: nodes and QoS)."""
    with open_session(conn) as session:
        graph = graph_of(session, conn, timeout_s)
        where = pick(conn, graph, topic, "topic")
        known_topic(conn, graph, where)
        infos = g.node_infos(session, where[0], timeout_s)
        kind = g.topic_types(session, where[0], [where], timeout_s, infos).get(where)
    pubs, subs = graph.publishers.get(where, []), graph.subscribers.get(where, [])
    print(f"Type: {kind or f'unknown (no message within {timeout_s:g} s)'}", file=out)
    print(f"Publisher count: {len(pubs)}", file=out)
    if verbose:
        _endpoints(out, where, pubs, infos, "PUBLISHER", "publication_qos")
    print(f"Subscription count: {len(subs)}", file=out)
    if verbose:
        _endpoints(out, where, subs, infos, "SUBSCRIPTION", "subscriptions")
    out.flush()
    return 0


def _endpoints(out: TextIO, where: tuple[str, str], nodes: Sequence[str],
               infos: dict[tuple[str, str], dict[str, Any]], kind: str, table: str) -> None:
    for node in nodes:
        info = infos.get((where[0], node), {})
        qos = (info.get(table) or {}).get(where[1]) or {"reliability": "reliable",
                                                        "durability": "volatile", "depth": 10}
        print(f"  Node name: {node}\n  Endpoint type: {kind}\n  QoS profile:\n"
              f"    Reliability: {qos['reliability'].upper()}\n"
              f"    History (Depth): KEEP_LAST ({qos['depth']})\n"
              f"    Durability: {qos['durability'].upper()}", file=out)


def known_topic(conn: Connection, graph: g.Graph, where: tuple[str, str]) -> None:
    if where not in graph.publishers and where not in graph.subscribers:
        topics = ", ".join(t for f, t in graph.topics() if f == where[0])
        raise CommandError(f"no node publishes or subscribes {where[1]} in fleet {where[0]!r}; "
                           f"topics: {topics}")


def topic_type(conn: Connection, topic: str, *, out: TextIO, timeout_s: float = 1.0) -> int:
    """`ros2 topic type`: the message type seen on a topic."""
    with open_session(conn) as session:
        graph = graph_of(session, conn, timeout_s)
        where = pick(conn, graph, topic, "topic")
        known_topic(conn, graph, where)
        kind = g.topic_types(session, where[0], [where], timeout_s).get(where)
    if kind is None:
        raise CommandError(f"{where[1]}: no message within {timeout_s:g} s, so its type is not "
                           "known yet (twinfleet types travel with the messages)")
    print(kind, file=out, flush=True)
    return 0


def _service_types(session: Any, conn: Connection, timeout_s: float
                   ) -> dict[tuple[str, str], list[str]]:
    """(fleet, service) → [request type, reply type], as the serving nodes describe them."""
    infos = g.node_infos(session, conn.fleet, timeout_s)
    return {(f, name): kinds for (f, _), info in infos.items()
            for name, kinds in (info.get("service_types") or {}).items()}


def service_list(conn: Connection, *, out: TextIO, verbose: bool = False, types: bool = False,
                 timeout_s: float = 1.0) -> int:
    """Print the services that running nodes serve (`types`: with request and reply types)."""
    with open_session(conn) as session:
        graph = graph_of(session, conn, timeout_s)
        kinds = _service_types(session, conn, timeout_s) if types else {}
    for (fleet, name), servers in sorted(graph.servers.items()):
        line = _shown(conn, fleet, name)
        if types:
            line += f" [{service_type_name(*kinds.get((fleet, name), ['?', '?']))}]"
        if verbose:
            line += f"  [servers: {', '.join(servers)}]"
        print(line, file=out)
    out.flush()
    return 0


def service_type(conn: Connection, service: str, *, out: TextIO, timeout_s: float = 1.0) -> int:
    """`ros2 service type`: a service's request type and reply type, as `REQUEST -> REPLY`."""
    with open_session(conn) as session:
        graph = graph_of(session, conn, timeout_s)
        where = pick(conn, graph, service, "service")
        if where not in graph.servers:
            raise CommandError(f"{where[1]}: no running node serves it (`twinfleet service list`)")
        kinds = _service_types(session, conn, timeout_s).get(where, ["?", "?"])
    print(service_type_name(*kinds), file=out, flush=True)
    return 0


def service_type_name(request: str, reply: str) -> str:
    """A service's type as ros2 names it (``pkg/srv/Name`` for ``pkg/Name_Request`` and
    ``pkg/Name_Response``), else ``REQUEST -> REPLY``."""
    stem = request.removesuffix("_Request")
    if stem != request and reply == f"{stem}_Response" and "/" in stem:
        package, name = stem.rsplit("/", 1)
        return f"{package}/srv/{name}"
    return f"{request} -> {reply}"


def checked_type(type_name: str, *, service: bool = False) -> str:
    """`normalise_type`, a bad name being a `CommandError`."""
    try:
        return normalise_type(type_name, service=service)
    except PayloadError as exc:
        raise CommandError(str(exc)) from None


def param_list(conn: Connection, node: str | None, *, out: TextIO, timeout_s: float = 1.0) -> int:
    """`ros2 param list`: every node's parameters (or one node's), as served in ``@info``."""
    with open_session(conn) as session:
        graph = graph_of(session, conn, timeout_s)
        if node is not None:
            _node_fleet(conn, graph, node.lstrip("/"))
        infos = g.node_infos(session, conn.fleet, timeout_s, (node or "*").lstrip("/"))
    for (fleet, name), info in sorted(infos.items()):
        print(_shown(conn, fleet, f"/{name}") + ":", file=out)
        for key in info.get("params", {}):
            print(f"  {key}", file=out)
    out.flush()
    return 0


def param_get(conn: Connection, node: str, name: str, *, out: TextIO,
              timeout_s: float = 1.0) -> int:
    """`ros2 param get NODE NAME`: one parameter's value."""
    bare = node.lstrip("/")
    with open_session(conn) as session:
        graph = graph_of(session, conn, timeout_s)
        fleet = _node_fleet(conn, graph, bare)
        info = g.node_infos(session, fleet, timeout_s, bare).get((fleet, bare))
    if info is None:
        raise CommandError(f"node {bare!r} does not describe itself (an older twinfleet?)")
    params = info.get("params", {})
    if name not in params:
        raise CommandError(f"node {bare!r} has no parameter {name!r}; parameters: "
                           + (", ".join(params) or "none"))
    value = params[name]
    kind = {bool: "Boolean", int: "Integer", float: "Double", str: "String"}.get(type(value),
                                                                                "List")
    print(f"{kind} value is: {inline(value)}", file=out, flush=True)
    return 0


def param_dump(conn: Connection, node: str, *, out: TextIO, timeout_s: float = 1.0) -> int:
    """`ros2 param dump NODE`: the parameters in force, as a ROS 2 parameter file (YAML)."""
    bare = node.lstrip("/")
    with open_session(conn) as session:
        graph = graph_of(session, conn, timeout_s)
        fleet = _node_fleet(conn, graph, bare)
        info = g.node_infos(session, fleet, timeout_s, bare).get((fleet, bare))
    if info is None:
        raise CommandError(f"node {bare!r} does not describe itself (an older twinfleet?)")
    doc = {f"/{bare}": {"ros__parameters": info.get("params", {})}}
    out.write(yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=100))
    out.flush()
    return 0


def interface_list(conn: Connection | None, *, out: TextIO, timeout_s: float = 1.0) -> int:
    """`ros2 interface list`: the message types this process and the fleet's nodes know."""
    names = set(registered_types())
    if conn is not None:
        with open_session(conn) as session:
            names |= set(g.served_schemas(session, conn.fleet, timeout_s))
    services = sorted({n.removesuffix("_Request") for n in names if n.endswith("_Request")
                       and f"{n.removesuffix('_Request')}_Response" in names})
    parts = {f"{s}_{end}" for s in services for end in ("Request", "Response")}
    print("Messages:", file=out)
    for name in sorted(names - parts):
        print(f"    {name}", file=out)
    print("Services:", file=out)
    for stem in services:
        print(f"    {service_type_name(stem + '_Request', stem + '_Response')}", file=out)
    out.flush()
    return 0


def interface_show(conn: Connection | None, type_name: str, *, out: TextIO,
                   timeout_s: float = 1.0) -> int:
    """`ros2 interface show`: the fields of a message type, from the fleet's ``@types``; of
    a service type (``pkg/srv/Name``), its request, ``---`` and its reply."""
    name = checked_type(type_name)
    served: dict[str, tuple[dict[str, Any], list[str]]] = {}
    if conn is not None:
        with open_session(conn) as session:
            served = g.served_schemas(session, conn.fleet, timeout_s)
    request, reply = f"{name}_Request", f"{name}_Response"
    if name not in served and name not in registered_types() and (
            request in served or request in registered_types()):
        _show_fields(request, served, out)  # a service: its request, ---, its reply
        print("---", file=out)
        _show_fields(reply, served, out)
        out.flush()
        return 0
    _show_fields(name, served, out)
    out.flush()
    return 0


def _show_fields(name: str, served: dict[str, tuple[dict[str, Any], list[str]]],
                 out: TextIO) -> None:
    cls = registered_types().get(name)
    if name in served:
        schema, nodes = served[name]
        source = f"served by {', '.join(sorted(nodes))}"
    elif cls is not None:
        schema, source = dataclass_schema(cls), f"{cls.__module__}.{cls.__qualname__}"
    else:
        known = sorted({*served, *registered_types()})
        raise CommandError(f"unknown message type {name!r}; known: {', '.join(known)}")
    print(f"# {name} ({source})", file=out)
    required = set(schema.get("required") or [])
    for field, sub in (schema.get("properties") or {}).items():
        optional = "" if field in required else "  # optional"
        print(f"{field_type(sub)} {field}{optional}", file=out)


def field_type(schema: dict[str, Any]) -> str:
    """A JSON Schema of one field in .msg-like notation: ``int64[2]``, ``string``, ``uint8[]``."""
    if "anyOf" in schema:
        return " | ".join(field_type(s) for s in schema["anyOf"])
    kind = schema.get("type")
    if kind == "string" and schema.get("contentMediaType"):
        return "uint8[]"
    if kind == "array":
        items = schema.get("prefixItems")
        if items:
            inner = {field_type(i) for i in items}
            return f"{inner.pop()}[{len(items)}]" if len(inner) == 1 else \
                "(" + ", ".join(field_type(i) for i in items) + ")"
        return f"{field_type(schema.get('items') or {})}[]"
    if kind == "object":
        const = ((schema.get("properties") or {}).get("_type") or {}).get("const")
        return const or "map"
    return {"string": "string", "integer": "int64", "number": "float64", "boolean": "bool",
            "null": "none"}.get(kind if isinstance(kind, str) else "", "any")
