"""A node's counters as one typed record, from the node core to the launcher's verdict.

`NodeStatistics` is what a node process counted since it started: the core's
counters (received, handled, gaps, KEEP_LAST drops, stalls, ...), what its
transport dropped at the hand-off to the loop, and the samples refused before
any handler ran, per `Rejection`. The same record is printed on the node's
``stopped:`` line, served on its ``@stats`` queryable (a msgpack map,
`NodeStatistics.to_dict`), read back by the launcher and ``twinfleet node list
--stats`` (`NodeStatistics.from_dict`) and judged by the live verdict
(`runtime.fleet.live_verdict`), which reads its fields by name: a counter
renamed here is a type error there, not a counter the verdict stops seeing.

The wire form is flat: one integer per counter, a rejection reason as
``rejected_<reason>`` (`Rejection.counter`), the wrong-type lines as a list, and
the input from outside the fleet as ``[source, name, count]`` triples. `from_dict` is strict: a map with
a counter this version does not know, or without one it expects, is refused
with `StatisticsError` rather than read as zero, so a node and a launcher of
different versions say so instead of passing a run on counters nobody read.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum, unique
from types import MappingProxyType
from typing import Any, Final, final

from twinfleet.runtime.contract.names import BRIDGE_SENDER, OPERATOR_SENDER

_REJECTED: Final = "rejected_"  # the wire prefix of a rejection reason's counter


@unique
class Rejection(StrEnum):
    """Why a node refused a sample before any handler saw it (`runtime.core.guard`)."""

    FORGED = "forged"  # unsigned or wrongly signed (the transport checks the fleet key)
    INVALID = "invalid"  # fields that do not fit the message type's annotations
    OVERSIZE = "oversize"  # larger than the topic's payload limit (the transport)
    WRONG_TYPE = "wrong_type"  # a message type the handler does not take
    REPLAYED = "replayed"  # a signed sample let through before (its sender and number)
    RECORDED = "recorded"  # recorded input (`play --into-fleet`) the fleet does not accept

    @property
    def counter(self) -> str:
        """This reason's counter name in the wire form and the printed statistics."""
        return f"{_REJECTED}{self.value}"


@unique
class Outside(StrEnum):
    """Where input from outside the fleet that a node's handlers took came from: the
    envelope's sender says it (`OUTSIDE_SENDERS`)."""

    OPERATOR = "an operator's command (topic pub, service call)"
    BRIDGE = "the ROS 2 bridge"


#: The envelope senders that are not fleet nodes, and what each stands for.
OUTSIDE_SENDERS: Final = {OPERATOR_SENDER: Outside.OPERATOR, BRIDGE_SENDER: Outside.BRIDGE}
#: Handled input from outside the fleet: (source, topic or service, handler runs).
OutsideInput = tuple[Outside, str, int]


class StatisticsError(ValueError):
    """A statistics map that is not the `NodeStatistics` of this version."""


@final
@dataclass(frozen=True, slots=True)
class NodeStatistics:
    """A snapshot of a node's counters (module docstring); every counter starts at 0.

    Attributes:
        received: samples and requests that arrived (refused and undecodable ones too).
        dropped_undecodable: payloads that were not a twinfleet envelope.
        handler_errors: handler runs that raised (or whose effects failed).
        failures: ``ctx.fail`` calls.
        gaps: missing sequence numbers on RELIABLE subscriptions (samples lost below
            the core).
        inbox_depth: entries waiting to run when the snapshot was taken.
        timers_pending: timers, ticks and call timeouts armed.
        published: samples published.
        handled: handler runs.
        dropped_keep_last: samples a KEEP_LAST queue dropped for a newer one.
        dropped_overflow: samples the transport's bounded hand-off to the loop dropped.
        dropped_best_effort: missing sequence numbers on BEST_EFFORT subscriptions.
        sequence_jumps: sequence numbers that leapt too far to be a loss (not gaps).
        dropped_lossless: KEEP_LAST drops on RELIABLE subscriptions (part of
            ``dropped_keep_last``).
        stalls: timed entries released later than the stall threshold.
        max_lateness_ms: the latest a timed entry was released after its due time.
        stall_threshold_ms: that threshold (0: stalls are not counted).
        external_input: samples accepted from outside the fleet (signed with the bridge key,
            on a topic the node declares external: `runtime.core.guard`).
        played: recorded samples let in (`play --into-fleet`, a fleet launched with
            ``--accept-recorded``).
        rejected: samples refused before any handler, per reason (every reason present).
        rejected_external: samples an operator's command sent (sender
            `contract.names.OPERATOR_SENDER`, e.g. ``topic pub --force``) that the node
            refused, for any reason; not in ``rejected``: input from outside the fleet,
            not a loss of the fleet's own.
        wrong_types: one line per (sender, topic) whose messages were of a type the
            receiving handler does not take (`contract.dispatch.wrong_type_line`, with the
            count): a breach of the node contract by the sender, which the verdict names.
        outside_input: the messages and requests from outside the fleet its handlers
            took, per (source, topic or service), sorted: the verdict names them.
    """

    received: int = 0
    dropped_undecodable: int = 0
    handler_errors: int = 0
    failures: int = 0
    gaps: int = 0
    inbox_depth: int = 0
    timers_pending: int = 0
    published: int = 0
    handled: int = 0
    dropped_keep_last: int = 0
    dropped_overflow: int = 0
    dropped_best_effort: int = 0
    sequence_jumps: int = 0
    dropped_lossless: int = 0
    stalls: int = 0
    max_lateness_ms: int = 0
    stall_threshold_ms: int = 0
    rejected_external: int = 0
    external_input: int = 0
    played: int = 0
    rejected: Mapping[Rejection, int] = field(default_factory=dict)
    wrong_types: tuple[str, ...] = ()
    outside_input: tuple[OutsideInput, ...] = ()

    def __post_init__(self) -> None:
        # Every reason present, read-only: readers index it without a default, and a
        # frozen record's mapping must not change under it.
        unknown = [k for k in self.rejected if not isinstance(k, Rejection)]
        if unknown:
            raise StatisticsError(f"node statistics: rejection reasons must be Rejection "
                                  f"members, got {unknown!r}")
        full = {reason: self.rejected.get(reason, 0) for reason in Rejection}
        object.__setattr__(self, "rejected", MappingProxyType(full))

    def to_dict(self) -> dict[str, Any]:
        """The flat wire form: counter name → value, in declaration order, one
        ``rejected_<reason>`` per `Rejection`, then ``wrong_types`` (a list of lines)."""
        out: dict[str, Any] = {name: getattr(self, name) for name in _SCALARS}
        out.update((reason.counter, count) for reason, count in self.rejected.items())
        out[_LINES] = list(self.wrong_types)
        out[_OUTSIDE] = [[source.name, name, count] for source, name, count in self.outside_input]
        return out

    @classmethod
    def from_dict(cls, data: Any) -> NodeStatistics:
        """Read the wire form back, strictly.

        Raises:
            StatisticsError: `data` is not a map of counter names to integers, names a
                counter this version does not know, or lacks one it expects.
        """
        if not isinstance(data, Mapping):
            raise StatisticsError(f"node statistics: expected a map of counters, got "
                                  f"{type(data).__name__}")
        _check_names(data.keys())
        for name, value in data.items():
            if name not in (_LINES, _OUTSIDE) and type(value) is not int:
                raise StatisticsError(f"node statistics: {name} must be an integer, "
                                      f"got {value!r:.40}")
        lines = data[_LINES]
        if not isinstance(lines, list | tuple) or not all(isinstance(x, str) for x in lines):
            raise StatisticsError(f"node statistics: {_LINES} must be a list of lines, "
                                  f"got {lines!r:.40}")
        rejected = {reason: data[reason.counter] for reason in Rejection}
        return cls(**{name: data[name] for name in _SCALARS}, rejected=rejected,
                   wrong_types=tuple(lines), outside_input=_outside(data[_OUTSIDE]))

    def troubled(self) -> bool:
        """Whether a counter says something went wrong: a loss, a refusal, an error, a
        stall (then the node's full counters are worth printing)."""
        return any(getattr(self, name) for name in _TROUBLE) or any(
            self.rejected.values()) or bool(self.wrong_types)

    def nonzero(self) -> str:
        """The counters that are not zero, as ``name=value`` words (settings left out)."""
        return " ".join(f"{k}={v}" for k, v in self.to_dict().items()
                        if v and k not in (_LINES, _OUTSIDE, "stall_threshold_ms"))

    def line(self) -> str:
        """The counters as ``name=value`` words (the ``stopped:`` line, ``node list
        --stats``)."""
        return " ".join(f"{k}={v}" for k, v in self.to_dict().items()
                        if k not in (_LINES, _OUTSIDE))


_LINES: Final = "wrong_types"
_OUTSIDE: Final = "outside_input"
_TROUBLE: Final = ("dropped_undecodable", "handler_errors", "failures", "gaps",
                   "dropped_overflow", "dropped_best_effort", "sequence_jumps",
                   "dropped_lossless", "stalls", "rejected_external")
_SCALARS: Final = tuple(f.name for f in dataclasses.fields(NodeStatistics)
                        if f.name not in ("rejected", _LINES, _OUTSIDE))
WIRE_NAMES: Final = frozenset((*_SCALARS, *(reason.counter for reason in Rejection), _LINES,
                               _OUTSIDE))


def _outside(raw: Any) -> tuple[OutsideInput, ...]:
    """`outside_input` from its wire form, strictly."""
    out = []
    for entry in raw if isinstance(raw, list | tuple) else [None]:
        if (not isinstance(entry, list | tuple) or len(entry) != 3
                or entry[0] not in Outside.__members__ or not isinstance(entry[1], str)
                or type(entry[2]) is not int):
            raise StatisticsError(f"node statistics: {_OUTSIDE} must be a list of [source, "
                                  f"name, count], got {raw!r:.60}")
        out.append((Outside[entry[0]], entry[1], entry[2]))
    return tuple(out)


def _check_names(names: Any) -> None:
    """Raise `StatisticsError` unless `names` are exactly `WIRE_NAMES`."""
    given = set(names)
    unknown = sorted(map(repr, given - WIRE_NAMES))
    missing = sorted(WIRE_NAMES - given)
    if unknown or missing:
        parts = ([f"unknown counters {', '.join(unknown)}"] if unknown else []) + (
            [f"missing counters {', '.join(missing)}"] if missing else [])
        raise StatisticsError(f"node statistics: {'; '.join(parts)} (a node of another "
                              "twinfleet version?)")
