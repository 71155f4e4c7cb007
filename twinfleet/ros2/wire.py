"""rmw_zenoh's names on the wire, sans I/O: data keys, graph tokens, QoS strings, attachments.

What a ROS 2 node on rmw_zenoh (Jazzy, Kilted) expects of a peer, as its design
document (ros2/rmw_zenoh, docs/design.md) describes it and docs/ros2.md restates:

* Data of a topic or service travels on ``<domain>/<name>/<dds type>/<type hash>``:
  the fully qualified name without its leading and trailing ``/``, the DDS type name
  (``sensor_msgs::msg::dds_::LaserScan_``) and the RIHS01 hash
  (`twinfleet.interfaces.typehash`). A key that differs in any part matches nothing: a
  wrong hash is silence, not an error.
* The ROS graph is a set of liveliness tokens under the hermetic ``@ros2_lv`` chunk, one
  per node (``NN``) and one per publisher, subscription, service and client
  (``MP MS SS SC``), each naming its session, node, entity and, for endpoints, the topic,
  type, hash and QoS. A ``/`` inside one field is written ``%``; an empty namespace or
  enclave is ``%``.
* QoS is written ``rel:dur:hist,depth:dl_s,dl_ns:ls_s,ls_ns:liv,lease_s,lease_ns``; a
  value equal to rmw's default profile is left empty, the depth is always written.
* Every sample, request and reply carries a 33-byte attachment: int64 sequence number,
  int64 source timestamp (ns), the GID length 16 and the 16-byte GID, little-endian.
  ROS 2 nodes drop a sample without it.
"""

from __future__ import annotations

import enum
import hashlib
import struct
from dataclasses import dataclass

LIVELINESS_PREFIX = "@ros2_lv"
GID_SIZE = 16
_ATTACHMENT = struct.Struct("<qqB16s")
ATTACHMENT_SIZE = _ATTACHMENT.size  # 33


class WireError(ValueError):
    """A key, token, QoS string or attachment that is not rmw_zenoh's; the text says why."""


class EntityKind(enum.Enum):
    """What a liveliness token announces."""

    NODE = "NN"
    PUBLISHER = "MP"
    SUBSCRIPTION = "MS"
    SERVICE = "SS"
    CLIENT = "SC"


class Reliability(enum.IntEnum):
    """rmw's reliability policy values (0 = the system default)."""

    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    BEST_EFFORT = 2


class Durability(enum.IntEnum):
    """rmw's durability policy values."""

    SYSTEM_DEFAULT = 0
    TRANSIENT_LOCAL = 1
    VOLATILE = 2


class History(enum.IntEnum):
    """rmw's history policy values."""

    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2


class Liveliness(enum.IntEnum):
    """rmw's liveliness policy values."""

    SYSTEM_DEFAULT = 0
    AUTOMATIC = 1
    MANUAL_BY_NODE = 2
    MANUAL_BY_TOPIC = 3


@dataclass(frozen=True)
class Qos:
    """A QoS profile as rmw_zenoh writes it in a token; the defaults are rmw's default profile
    (reliable, volatile, keep last 10, every duration 0 = unset, liveliness system default)."""

    reliability: Reliability = Reliability.RELIABLE
    durability: Durability = Durability.VOLATILE
    history: History = History.KEEP_LAST
    depth: int = 10
    deadline: tuple[int, int] = (0, 0)
    lifespan: tuple[int, int] = (0, 0)
    liveliness: Liveliness = Liveliness.SYSTEM_DEFAULT
    lease: tuple[int, int] = (0, 0)

    def encode(self) -> str:
        """The token's QoS field: values equal to the default profile's left empty."""
        d = Qos()

        def one(value: int, default: int) -> str:
            return "" if value == default else str(int(value))

        def pair(value: tuple[int, int], default: tuple[int, int]) -> str:
            return f"{one(value[0], default[0])},{one(value[1], default[1])}"

        return ":".join((
            one(self.reliability, d.reliability), one(self.durability, d.durability),
            f"{one(self.history, d.history)},{self.depth}",
            pair(self.deadline, d.deadline), pair(self.lifespan, d.lifespan),
            f"{one(self.liveliness, d.liveliness)},{pair(self.lease, d.lease)}"))

    @classmethod
    def decode(cls, text: str) -> Qos:
        """The profile a token's QoS field describes (empty values are the defaults)."""
        parts = text.split(":")
        if len(parts) != 6:
            raise WireError(f"QoS {text!r}: expected 6 ':'-separated fields, got {len(parts)}")
        d = cls()
        try:
            hist, depth = _split(parts[2], 2)
            liv, lease_s, lease_ns = _split(parts[5], 3)
            return cls(
                reliability=Reliability(_int(parts[0], d.reliability)),
                durability=Durability(_int(parts[1], d.durability)),
                history=History(_int(hist, d.history)), depth=_int(depth, d.depth),
                deadline=_pair(parts[3], d.deadline), lifespan=_pair(parts[4], d.lifespan),
                liveliness=Liveliness(_int(liv, d.liveliness)),
                lease=(_int(lease_s, d.lease[0]), _int(lease_ns, d.lease[1])))
        except ValueError as exc:
            raise WireError(f"QoS {text!r}: {exc}") from None


def _split(text: str, n: int) -> list[str]:
    parts = text.split(",")
    if len(parts) != n:
        raise ValueError(f"{text!r} has {len(parts)} ','-separated values, expected {n}")
    return parts


def _int(text: str, default: int) -> int:
    return default if text == "" else int(text)


def _pair(text: str, default: tuple[int, int]) -> tuple[int, int]:
    a, b = _split(text, 2)
    return (_int(a, default[0]), _int(b, default[1]))


#: rmw_zenoh's profile for the map and other latched topics of depth 1
LATCHED = Qos(durability=Durability.TRANSIENT_LOCAL, depth=1)
#: rclpy's qos_profile_sensor_data
SENSOR_DATA = Qos(reliability=Reliability.BEST_EFFORT, depth=5)


def mangle(name: str) -> str:
    """A name as one token field: ``/`` written ``%``; the empty name and ``/`` are ``%``."""
    return "%" if name in ("", "/") else name.replace("/", "%")


def unmangle(field: str) -> str:
    """The name a token field holds (``%`` → ``/``)."""
    return field.replace("%", "/")


def dds_type_name(ros_type: str) -> str:
    """``pkg/msg/Name`` as DDS names it: ``pkg::msg::dds_::Name_``."""
    parts = ros_type.split("/")
    if len(parts) != 3 or not all(parts) or parts[1] not in ("msg", "srv", "action"):
        raise WireError(f"type {ros_type!r}: expected pkg/msg/Name")
    return f"{parts[0]}::{parts[1]}::dds_::{parts[2]}_"


def ros_type_name(dds_name: str) -> str:
    """The inverse of `dds_type_name`."""
    parts = dds_name.split("::")
    if len(parts) != 4 or parts[2] != "dds_" or not parts[3].endswith("_"):
        raise WireError(f"DDS type {dds_name!r}: expected pkg::msg::dds_::Name_")
    return f"{parts[0]}/{parts[1]}/{parts[3][:-1]}"


def data_key(domain: int, name: str, ros_type: str, type_hash: str) -> str:
    """The key a topic's (or a service's) data travels on."""
    stripped = name.strip("/")
    if not stripped:
        raise WireError(f"name {name!r} is empty")
    return f"{domain}/{stripped}/{dds_type_name(ros_type)}/{type_hash}"


@dataclass(frozen=True)
class NodeId:
    """Who owns a token: the domain, the Zenoh session id, the node's id in it, its name."""

    domain: int
    zid: str
    node_id: int
    namespace: str
    name: str
    enclave: str = "/"


@dataclass(frozen=True)
class Endpoint:
    """A publisher, subscription, service or client of a node."""

    node: NodeId
    entity_id: int
    kind: EntityKind
    topic: str  # fully qualified: /r1/scan
    ros_type: str  # sensor_msgs/msg/LaserScan
    type_hash: str
    qos: Qos = Qos()

    @property
    def key(self) -> str:
        """The data key this endpoint publishes or listens on."""
        return data_key(self.node.domain, self.topic, self.ros_type, self.type_hash)


def _node_fields(node: NodeId, entity_id: int, kind: EntityKind) -> list[str]:
    for text in (node.name, node.zid):
        if not text or "/" in text:
            raise WireError(f"token field {text!r} is empty or holds '/'")
    return [LIVELINESS_PREFIX, str(node.domain), node.zid, str(node.node_id), str(entity_id),
            kind.value, mangle(node.enclave), mangle(node.namespace), node.name]


def node_token(node: NodeId) -> str:
    """The liveliness token that makes a node appear in ``ros2 node list``."""
    return "/".join(_node_fields(node, node.node_id, EntityKind.NODE))


def endpoint_token(ep: Endpoint) -> str:
    """The liveliness token that makes an endpoint appear in ``ros2 topic list`` / ``info``."""
    if ep.kind is EntityKind.NODE:
        raise WireError("a node's token is node_token's")
    return "/".join([*_node_fields(ep.node, ep.entity_id, ep.kind), mangle(ep.topic),
                     dds_type_name(ep.ros_type), ep.type_hash, ep.qos.encode()])


def parse_token(key: str) -> NodeId | Endpoint:
    """What a liveliness token announces: the node (``NN``) or the endpoint."""
    parts = key.split("/")
    if len(parts) < 9 or parts[0] != LIVELINESS_PREFIX or any(p == "" for p in parts):
        raise WireError(f"{key!r} is not an rmw_zenoh liveliness token")
    try:
        kind = EntityKind(parts[5])
        node = NodeId(int(parts[1]), parts[2], int(parts[3]), unmangle(parts[7]), parts[8],
                      unmangle(parts[6]))
        entity_id = int(parts[4])
    except ValueError as exc:
        raise WireError(f"{key!r}: {exc}") from None
    if kind is EntityKind.NODE:
        if len(parts) != 9:
            raise WireError(f"{key!r}: a node token has 9 fields, not {len(parts)}")
        return node
    if len(parts) != 13:
        raise WireError(f"{key!r}: an endpoint token has 13 fields, not {len(parts)}")
    return Endpoint(node, entity_id, kind, unmangle(parts[9]), ros_type_name(parts[10]),
                    parts[11], Qos.decode(parts[12]))


def gid_of(text: str) -> bytes:
    """A 16-byte GID that names one entity: the first bytes of the SHA-256 of its token."""
    return hashlib.sha256(text.encode()).digest()[:GID_SIZE]


@dataclass(frozen=True)
class Attachment:
    """What travels beside every sample, request and reply."""

    sequence: int
    source_ns: int
    gid: bytes

    def encode(self) -> bytes:
        """The 33 bytes."""
        if len(self.gid) != GID_SIZE:
            raise WireError(f"a GID has {GID_SIZE} bytes, not {len(self.gid)}")
        return _ATTACHMENT.pack(self.sequence, self.source_ns, GID_SIZE, self.gid)

    @classmethod
    def decode(cls, data: bytes) -> Attachment:
        """The attachment in `data` (exactly 33 bytes, GID length 16)."""
        if len(data) != ATTACHMENT_SIZE:
            raise WireError(f"attachment of {len(data)} bytes, expected {ATTACHMENT_SIZE}")
        sequence, source_ns, size, gid = _ATTACHMENT.unpack(data)
        if size != GID_SIZE:
            raise WireError(f"attachment GID length {size}, expected {GID_SIZE}")
        return cls(sequence, source_ns, gid)
