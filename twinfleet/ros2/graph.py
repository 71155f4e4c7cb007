"""The bridge's side of the ROS graph, sans I/O: its node, its endpoints, their sequence numbers.

The bridge appears to ROS 2 as one node (``/twinfleet_bridge`` by default) that
publishes every mapped topic and subscribes to the inbound ones. Each endpoint
gets an entity id, its liveliness token, its data key, a GID (`wire.gid_of`
its token) and a per-endpoint sequence number for the attachment, as an
rmw_zenoh publisher has. Inbound samples are checked here too (`Inbound`):
size, type and finite numbers; what fails is counted per reason and dropped.
"""

from __future__ import annotations

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


@dataclass(frozen=True)
class Declared:
    """One endpoint as the I/O side declares it."""

    endpoint: Endpoint
    token: str
    key: str
    gid: bytes


class BridgeGraph:
    """The bridge node and its endpoints (module docstring)."""

    def __init__(self, domain: int, zid: str, *, name: str = "twinfleet_bridge",
                 namespace: str = "/", types: RosTypes | None = None) -> None:
        self.node = NodeId(domain, zid, 0, namespace, name)
        self.types = types or RosTypes()
        self.endpoints: dict[tuple[EntityKind, str, str], Declared] = {}
        self._sequence: dict[str, int] = {}

    @property
    def node_token(self) -> str:
        """The bridge node's liveliness token."""
        return node_token(self.node)

    def declare(self, kind: EntityKind, topic: str, ros_type: str, *,
                latched: bool = False) -> tuple[Declared, bool]:
        """The endpoint for (kind, topic, type), and whether it is new (declare it then)."""
        index = (kind, topic, ros_type)
        if index in self.endpoints:
            return self.endpoints[index], False
        qos = LATCHED if latched else Qos()
        ep = Endpoint(self.node, len(self.endpoints) + 1, kind, topic, ros_type,
                      self.types.type_hash(ros_type), qos)
        token = endpoint_token(ep)
        made = Declared(ep, token, ep.key, gid_of(token))
        self.endpoints[index] = made
        return made, True

    def attachment(self, declared: Declared, now_ns: int) -> bytes:
        """The next attachment of `declared`'s samples (sequence numbers from 1)."""
        seq = self._sequence.get(declared.key, 0) + 1
        self._sequence[declared.key] = seq
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
