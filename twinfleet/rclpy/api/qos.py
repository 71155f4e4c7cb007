"""`rclpy.qos`: QoS profiles and policies with rclpy's names, mapped onto the contract's QoS.

Depth, history, reliability and durability act in both drivers (KEEP_LAST drops the
oldest waiting sample; TRANSIENT_LOCAL replays the last samples to a late joiner);
deadline, lifespan and liveliness are accepted and have no effect, as in rmw_zenoh.
"""

from __future__ import annotations

from enum import Enum, IntEnum
from typing import Any

from twinfleet.runtime.contract.node import Durability as _Durability
from twinfleet.runtime.contract.node import QoS
from twinfleet.runtime.contract.node import Reliability as _Reliability

#: The depth a KEEP_ALL queue gets: bounded, so that a checker state stays finite.
KEEP_ALL_DEPTH = 1000


class HistoryPolicy(IntEnum):
    """How many samples a queue keeps."""

    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2
    UNKNOWN = 3


class ReliabilityPolicy(IntEnum):
    """Whether samples may be lost."""

    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    BEST_EFFORT = 2
    UNKNOWN = 3
    BEST_AVAILABLE = 4


class DurabilityPolicy(IntEnum):
    """Whether a late joiner gets the last samples."""

    SYSTEM_DEFAULT = 0
    TRANSIENT_LOCAL = 1
    VOLATILE = 2
    UNKNOWN = 3
    BEST_AVAILABLE = 4


class LivelinessPolicy(IntEnum):
    """Accepted; no effect."""

    SYSTEM_DEFAULT = 0
    AUTOMATIC = 1
    MANUAL_BY_TOPIC = 3
    UNKNOWN = 4
    BEST_AVAILABLE = 5


class QoSProfile:
    """A QoS profile; `depth` is needed with KEEP_LAST, as in rclpy."""

    def __init__(self, *, history: HistoryPolicy | int = HistoryPolicy.KEEP_LAST,
                 depth: int | None = None,
                 reliability: ReliabilityPolicy | int = ReliabilityPolicy.RELIABLE,
                 durability: DurabilityPolicy | int = DurabilityPolicy.VOLATILE,
                 **ignored: Any) -> None:
        self.history = HistoryPolicy(history)
        if self.history is HistoryPolicy.KEEP_LAST and depth is None:
            raise ValueError("QoSProfile: a KEEP_LAST profile needs a depth")
        self.depth = 0 if depth is None else int(depth)
        self.reliability = ReliabilityPolicy(reliability)
        self.durability = DurabilityPolicy(durability)
        self.ignored = dict(ignored)  # deadline, lifespan, liveliness: no effect

    def __eq__(self, other: object) -> bool:
        return isinstance(other, QoSProfile) and self.contract() == other.contract()

    def __hash__(self) -> int:
        return hash(self.contract())

    def __repr__(self) -> str:
        return (f"QoSProfile(history={self.history.name}, depth={self.depth}, "
                f"reliability={self.reliability.name}, durability={self.durability.name})")

    def contract(self) -> QoS:
        """The contract's QoS for this profile (KEEP_ALL becomes a deep KEEP_LAST)."""
        depth = KEEP_ALL_DEPTH if self.history is HistoryPolicy.KEEP_ALL else max(1, self.depth)
        reliability = (_Reliability.BEST_EFFORT if self.reliability is ReliabilityPolicy.BEST_EFFORT
                       else _Reliability.RELIABLE)
        durability = (_Durability.TRANSIENT_LOCAL
                      if self.durability is DurabilityPolicy.TRANSIENT_LOCAL
                      else _Durability.VOLATILE)
        return QoS(reliability, durability, depth)


def as_profile(qos: QoSProfile | int) -> QoSProfile:
    """A profile from what `create_publisher`/`create_subscription` take: a depth or a profile."""
    if isinstance(qos, QoSProfile):
        return qos
    if isinstance(qos, int) and not isinstance(qos, bool) and qos >= 0:
        return QoSProfile(depth=qos)
    raise TypeError(f"qos_profile must be a QoSProfile or a depth (int >= 0), got {qos!r:.60}")


qos_profile_default = QoSProfile(depth=10)
qos_profile_system_default = QoSProfile(depth=10)
qos_profile_sensor_data = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
qos_profile_services_default = QoSProfile(depth=10)
qos_profile_parameters = QoSProfile(depth=1000)
qos_profile_parameter_events = QoSProfile(depth=1000)
qos_profile_best_available = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_AVAILABLE,
                                        durability=DurabilityPolicy.BEST_AVAILABLE)


class QoSPresetProfiles(Enum):
    """The named profiles."""

    DEFAULT = qos_profile_default
    SYSTEM_DEFAULT = qos_profile_system_default
    SENSOR_DATA = qos_profile_sensor_data
    SERVICES_DEFAULT = qos_profile_services_default
    PARAMETERS = qos_profile_parameters
    PARAMETER_EVENTS = qos_profile_parameter_events
    BEST_AVAILABLE = qos_profile_best_available

    @classmethod
    def get_from_short_key(cls, name: str) -> QoSProfile:
        """The profile of a short name such as ``sensor_data``."""
        return cls[name.upper()].value
