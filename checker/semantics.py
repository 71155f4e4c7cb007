"""Every enabling rule of the checker, in one place.

Theory of operation
===================

A world holds pending events; each is "run handler `method` of node
`target` with `args` at time `due`". A transition takes one *enabled* event
and runs its handler to completion (one transition per `ctx.choose` variant,
see `checker.choices`). Which events are enabled is decided here, by rules
applied in this order:

Rule 1 (time). Only events due at the smallest pending due time t* can run.
    Time never passes while something is due now, so no node starves across
    time; a cycle in the state graph is a genuinely infinite behaviour.

Rule 2 (handler priority). Per node, only its events at t* with the lowest
    handler priority (`@subscribe(..., priority=n)` etc.; undeclared methods
    get 0) are enabled. Different nodes never block each other by handler
    priority (except under `rebeca` with `global_priority`, Rule 4).

Rule 3 (send order) -- `ros` only. Events form channels: messages
    (deliveries, requests, replies) from one sender to one receiver, and the
    timers (`ctx.after`, `@every`, call timeouts) a node sets for itself. Among
    a channel's events with the same due time and priority, only the
    earliest-sent is enabled, as Zenoh keeps per-publisher order and asyncio
    fires equal-deadline timers in the order they were set. The send order is
    kept as `Event.rank`: the position among pending events of the same
    channel *and due time* (events with different due times can never be
    simultaneously enabled, so a coarser rank would only split states). With
    a `latency` range a later-sent message is never due before an earlier one
    of its channel (its due time is clamped), so FIFO holds across times too.
    Under `rebeca` every rank is 0: RMC's queue is a timed bag in canonical
    order, so all same-time same-priority messages of a node are alternatives
    whoever sent them (R2/R5), and identical duplicates are separate
    alternatives that RMC counts as separate transitions (R10).

Rule 4 (node-instance priority) -- `rebeca` only. Among the nodes that have an
    enabled event, only those with the minimal `NodeConfig.priority` run (R4).
    With `check.global_priority: true` the comparison is instead over the
    handler priorities of the enabled events, across nodes.

Everything still enabled after these rules is a nondeterministic choice the
search explores exhaustively.

Rule 5 (latency and faults, all off by default; see `checker.faults` for the
    scenario keys). `check.latency` gives a message a delivery delay in a
    range, globally or per topic/service, each value a separate branch; with
    `faults.drop` / `faults.duplicate` each delivery on a listed topic is
    also delivered, lost or delivered twice, each a branch. These branches
    are enumerated like `ctx.choose` options after the handler's own choices
    (per delivery: the fault, then the delay of each copy). A crash fault is
    not an event: it is one more alternative in every world with something
    pending (`checker.system.System.successors`), taken at t*. A message due
    after its deadline is a deadline miss when it is taken; because of Rule 1
    it is taken exactly at its due time, so only latency or FIFO clamping can
    make it late.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Final, final

from twinfleet.checker.world import MESSAGE_KINDS, Event

ROS: Final = "ros"
REBECA: Final = "rebeca"


@final
@dataclass(frozen=True, slots=True)
class Semantics:
    """The message rules a `System` applies.

    Attributes:
        name: "ros" (per-sender FIFO) or "rebeca" (RMC's rules).
        node_priorities: per node index, its instance priority (used by `rebeca`).
        global_priority: `rebeca` only: compare handler priorities across nodes.
        latency: (min, max) extra delivery delay of messages in ms, or None.
        topic_latency: per topic/service name, a range overriding `latency`
            (None: no delay on that name).
    """

    name: str = ROS
    node_priorities: tuple[int, ...] = ()
    global_priority: bool = False
    latency: tuple[int, int] | None = None
    topic_latency: tuple[tuple[str, tuple[int, int] | None], ...] = ()
    fifo: bool = field(init=False)
    has_latency: bool = field(init=False)
    _ranges: dict[str, tuple[int, int] | None] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.name not in (ROS, REBECA):
            raise ValueError(f"unknown semantics {self.name!r}; expected ros or rebeca")
        if self.latency is not None and not 0 <= self.latency[0] <= self.latency[1]:
            raise ValueError(f"latency must be [min, max] with 0 <= min <= max, got {self.latency}")
        object.__setattr__(self, "fifo", self.name == ROS)
        ranges = dict(self.topic_latency)
        object.__setattr__(self, "_ranges", ranges)
        object.__setattr__(self, "has_latency", self.latency is not None
                           or any(r is not None for r in ranges.values()))

    @property
    def latency_options(self) -> int:
        """How many delivery delays each message may take (1 without latency)."""
        if self.latency is None:
            return 1
        return self.latency[1] - self.latency[0] + 1

    def latency_range(self, name: str) -> tuple[int, int] | None:
        """The delivery-delay range of messages on topic/service `name` (None: no delay)."""
        return self._ranges.get(name, self.latency)

    def enabled(self, events: Sequence[Event]) -> list[int]:
        """Indices (into the canonically sorted `events`) of the events that may run next."""
        if not events:
            return []
        now = events[0].due
        group = []
        best: dict[int, int] = {}
        for i, ev in enumerate(events):
            if ev.due != now:
                break
            group.append(i)
            if ev.priority < best.get(ev.target, ev.priority + 1):
                best[ev.target] = ev.priority
        picked = [i for i in group if events[i].priority == best[events[i].target]]
        if self.fifo:
            picked = _earliest_sent(events, picked)
        elif len(best) > 1:
            picked = self._across_nodes(events, picked)
        return picked

    def _across_nodes(self, events: Sequence[Event], picked: list[int]) -> list[int]:
        if self.global_priority:
            top = min(events[i].priority for i in picked)
            return [i for i in picked if events[i].priority == top]
        if not self.node_priorities:
            return picked
        prios = self.node_priorities
        top = min(prios[events[i].target] for i in picked)
        return [i for i in picked if prios[events[i].target] == top]

    def message_due(self, now: int, delay_index: int) -> int:
        """Due time of a message sent at `now` taking latency option `delay_index`."""
        if self.latency is None:
            return now
        return now + self.latency[0] + delay_index

    def add(self, pending: list[Event], ev: Event) -> None:
        """Append `ev` to `pending`, giving it its rank (and FIFO clamping) under `ros`."""
        if not self.fifo:
            pending.append(ev)
            return
        sender, target, kind = ev.sender, ev.target, ev.kind
        is_msg = kind in MESSAGE_KINDS
        due = ev.due
        if self.has_latency and is_msg:
            for other in pending:
                if (other.due > due and other.target == target and other.sender == sender
                        and (other.kind in MESSAGE_KINDS) == is_msg):
                    due = other.due
        rank = 0
        for other in pending:
            if (other.due == due and other.target == target and other.sender == sender
                    and (other.kind in MESSAGE_KINDS) == is_msg):
                rank += 1
        if due != ev.due or rank:
            ev = ev.moved(due, rank)
        pending.append(ev)

    def remove(self, events: Sequence[Event], index: int) -> list[Event]:
        """`events` without `events[index]`, ranks of its channel-mates renumbered."""
        rest = list(events)
        gone = rest.pop(index)
        if not self.fifo:
            return rest
        # Only events with gone's due time can share its rank numbering; events are
        # sorted by due, so they sit next to each other.
        due, rank = gone.due, gone.rank
        chan = gone.channel
        for i in range(len(rest)):
            ev = rest[i]
            if ev.due != due:
                if ev.due > due:
                    break
                continue
            if ev.rank > rank and ev.channel == chan:
                rest[i] = ev.with_rank(ev.rank - 1)
        return rest


def _earliest_sent(events: Sequence[Event], picked: list[int]) -> list[int]:
    """Per channel, keep only the lowest-ranked of the picked events."""
    first: dict[tuple[int, int, bool], int] = {}
    for i in picked:
        chan = events[i].channel
        j = first.get(chan)
        if j is None or events[i].rank < events[j].rank:
            first[chan] = i
    return sorted(first.values())
