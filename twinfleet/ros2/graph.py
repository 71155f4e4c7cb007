"""The bridge's side of the ROS graph, sans I/O: its nodes, their endpoints, sequence numbers.

Each fleet node appears to ROS 2 as a node of its own name (``/r1``,
``/map_server``): the publishers of what it sends and the subscriptions of what
it takes from ROS 2 are that node's endpoints. What has no fleet node behind it
belongs to the bridge's own node, ``/twinfleet_bridge``. All of them live in the
bridge's one Zenoh session, so they share its session id and, as rmw_zenoh's
entities in one context do, one counter of ids (nodes and endpoints alike).

Each endpoint gets its liveliness token, its data key, a GID (`wire.gid_of` its
token) and a per-endpoint sequence number for the attachment, as an rmw_zenoh
publisher has. Inbound samples are checked here too (`Inbound`): size, type and
finite numbers; what fails is counted per reason and dropped.
"""

from __future__ import annotations

import re
from collections import Counter
from dataclasses import dataclass
from typing import Any

from twinfleet.ros2.cdr import MessageError, RosTypes
from twinfleet.ros2.wire import (
    LATCHED,
    Attachment,
    Endpoint,
    EntityKind,
    NodeId,
    Qos,
    WireError,
    endpoint_token,
    gid_of,
    node_token,
)

MAX_INBOUND_BYTES = 64 * 1024  # a goal pose is ~100 bytes; a grid would need more
BRIDGE_NODE = "twinfleet_bridge"
_NOT_ROS = re.compile(r"[^A-Za-z0-9_]")


def ros_node_name(name: str) -> str:
    """A fleet node's name as a ROS 2 node name (letters, digits, ``_``; not a digit first)."""
    text = _NOT_ROS.sub("_", name) or "node"
    return f"n{text}" if text[0].isdigit() else text


@dataclass(frozen=True)
class Declared:
    """One endpoint as the I/O side declares it."""

    endpoint: Endpoint
    token: str
    key: str
    gid: bytes


class BridgeGraph:
    """The bridge's ROS nodes and their endpoints (module docstring)."""

    def __init__(self, domain: int, zid: str, *, namespace: str = "/",
                 types: RosTypes | None = None) -> None:
        self.domain, self.zid, self.namespace = domain, zid, namespace
        self.types = types or RosTypes()
        self.nodes: dict[str, NodeId] = {}
        self.endpoints: dict[tuple[str, EntityKind, str, str], Declared] = {}
        self._ids = 0
        self._sequence: dict[str, int] = {}

    def _next_id(self) -> int:
        self._ids += 1
        return self._ids

    def node(self, fleet_node: str | None) -> tuple[NodeId, str | None]:
        """The ROS node of a fleet node (None: the bridge's own), and its liveliness token
        if it is new (declare it then)."""
        name = ros_node_name(fleet_node) if fleet_node else BRIDGE_NODE
        if name in self.nodes:
            return self.nodes[name], None
        made = NodeId(self.domain, self.zid, self._next_id(), self.namespace, name)
        self.nodes[name] = made
        return made, node_token(made)

    def declare(self, kind: EntityKind, topic: str, ros_type: str, *, owner: str | None = None,
                latched: bool = False) -> tuple[Declared, bool]:
        """The endpoint of `owner` (a fleet node; None: the bridge's node) for (kind, topic,
        type), and whether it is new (declare it then; its node first: `node`)."""
        node, _ = self.node(owner)
        index = (node.name, kind, topic, ros_type)
        if index in self.endpoints:
            return self.endpoints[index], False
        qos = LATCHED if latched else Qos()
        ep = Endpoint(node, self._next_id(), kind, topic, ros_type,
                      self.types.type_hash(ros_type), qos)
        token = endpoint_token(ep)
        made = Declared(ep, token, ep.key, gid_of(token))
        self.endpoints[index] = made
        return made, True

    def attachment(self, declared: Declared, now_ns: int) -> bytes:
        """The next attachment of `declared`'s samples (sequence numbers from 1)."""
        seq = self._sequence.get(declared.token, 0) + 1
        self._sequence[declared.token] = seq
        return Attachment(seq, now_ns, declared.gid).encode()


class Inbound:
    """Checks what ROS 2 sends the fleet: accepted messages as fields, the rest counted."""

    def __init__(self, types: RosTypes, *, max_bytes: int = MAX_INBOUND_BYTES) -> None:
        self.types, self.max_bytes = types, max_bytes
        self.accepted = 0
        self.dropped: Counter[str] = Counter()

    def check(self, ros_type: str, payload: bytes,
              attachment: bytes | None) -> dict[str, Any] | None:
        """The fields of a valid sample; None (and a count by reason) for any other."""
        if len(payload) > self.max_bytes:
            self.dropped["too large"] += 1
            return None
        if attachment is None:
            self.dropped["no attachment"] += 1
            return None
        try:
            Attachment.decode(attachment)
            fields = self.types.decode(ros_type, payload, strict=True)
        except WireError:
            self.dropped["bad attachment"] += 1
            return None
        except MessageError as exc:
            self.dropped["not finite" if "finite" in str(exc) else "malformed"] += 1
            return None
        self.accepted += 1
        return fields

    def refuse(self, reason: str) -> None:
        """Count a sample that passed the checks but that the mapping cannot take."""
        self.accepted -= 1
        self.dropped[reason] += 1
