"""The ROS 2 graph on a Zenoh network, for twinfleet's `node list` / `topic list` (``--ros2-domain``).

rmw_zenoh's graph is its liveliness tokens (`wire`); a query of
``@ros2_lv/<domain>/**`` on a router answers with every token alive behind it.
`RosGraph.of` reads them (sans I/O; a token that is not rmw_zenoh's is skipped),
`ros_graph` asks a router, `graph_lines` words it as the twinfleet listings do,
each line marked ``(ros2)``.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from twinfleet.ros2.wire import (
    LIVELINESS_PREFIX,
    Endpoint,
    EntityKind,
    NodeId,
    WireError,
    parse_token,
)


@dataclass
class RosGraph:
    """Nodes and topics that one domain's tokens announce."""

    nodes: set[str] = field(default_factory=set)  # fully qualified: /ns/name
    types: dict[str, set[str]] = field(default_factory=dict)  # topic → types
    publishers: dict[str, set[str]] = field(default_factory=dict)  # topic → nodes
    subscribers: dict[str, set[str]] = field(default_factory=dict)

    @classmethod
    def of(cls, keys: Iterable[str]) -> RosGraph:
        """The graph the token keys announce."""
        graph = cls()
        for key in keys:
            try:
                entity = parse_token(key)
            except WireError:
                continue
            node = entity if isinstance(entity, NodeId) else entity.node
            name = f"{node.namespace.rstrip('/')}/{node.name}"
            graph.nodes.add(name)
            if isinstance(entity, Endpoint) and entity.kind in (EntityKind.PUBLISHER,
                                                                EntityKind.SUBSCRIPTION):
                graph.types.setdefault(entity.topic, set()).add(entity.ros_type)
                table = graph.publishers if entity.kind is EntityKind.PUBLISHER \
                    else graph.subscribers
                table.setdefault(entity.topic, set()).add(name)
        return graph


def ros_graph(session: Any, domain: int, timeout_s: float) -> RosGraph:
    """Ask the routers `session` reaches for domain `domain`'s tokens."""
    keys = []
    for reply in session.liveliness().get(f"{LIVELINESS_PREFIX}/{domain}/**", timeout=timeout_s):
        if reply.ok is not None:
            with contextlib.suppress(Exception):
                keys.append(str(reply.ok.key_expr))
    return RosGraph.of(keys)


def graph_lines(graph: RosGraph, what: str, *, types: bool = False,
                verbose: bool = False) -> list[str]:
    """The lines `node list` (`what` = "nodes") or `topic list` ("topics") adds."""
    if what == "nodes":
        return [f"{name}  (ros2)" for name in sorted(graph.nodes)]
    lines = []
    for topic in sorted(graph.types):
        line = topic + (f" [{', '.join(sorted(graph.types[topic]))}]" if types else "")
        if verbose:
            roles = [f"{label}: {', '.join(sorted(table[topic]))}"
                     for label, table in (("publishers", graph.publishers),
                                          ("subscribers", graph.subscribers))
                     if table.get(topic)]
            line += f"  [{'; '.join(roles)}]"
        lines.append(line + "  (ros2)")
    return lines
