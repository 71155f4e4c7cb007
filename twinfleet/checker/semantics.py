"""Every enabling rule of the checker, in one place.

Theory of operation
===================

A world holds pending events; each is "run handler `method` of node
`target` with `args` at time `due`", of an `EventKind`. What may happen next
in a world are its *actions* (`checker.transition.Action`): run one *enabled*
event (`RunEvent`), crash a node (`Crash`, Rule 5), or drop a waiting delivery
(`Drop`, Rule 6). Taking an action runs
the handler to completion (one transition per `ctx.choose` variant, see
`checker.choices`). Which events are enabled is decided here, by rules
applied in this order:

Rule 1 (time). Only events due at the smallest pending due time t* can run.
    Time never passes while something is due now, so no node starves across
    time; a cycle in the state graph is a genuinely infinite behaviour.

Rule 2 (handler priority). Per node, only its events at t* with the lowest
    handler priority (`@subscribe(..., priority=n)` etc.; undeclared methods
    get 0) are enabled. Different nodes never block each other by handler
    priority (except under `rebeca` with `global_priority`, Rule 4).

Rule 3 (send order) -- `ros` only. Events form channels: messages
    (`EventKind.is_message`: deliveries, requests, replies) from one sender to
    one receiver, and the timers (`ctx.after`, `@every`, call timeouts) a node
    sets for itself. Among a channel's events with the same due time and
    priority, only the earliest-sent is enabled, as Zenoh keeps per-publisher
    order and asyncio fires equal-deadline timers in the order they were set.
    The send order is kept as `Event.rank`: the position among pending events
    of the same channel *and due time* (events with different due times can
    never be simultaneously enabled, so a coarser rank would only split
    states). With a `latency` range a later-sent message is never due before
    an earlier one of its channel (its due time is clamped), so FIFO holds
    across times too. Under `rebeca` every rank is 0: RMC's queue is a timed
    bag in canonical order, so all same-time same-priority messages of a node
    are alternatives whoever sent them (R2/R5), and identical duplicates are
    separate alternatives that RMC counts as separate transitions (R10).

Rule 4 (node-instance priority) -- `rebeca` only. Among the nodes that have an
    enabled event, only those with the minimal `NodeConfig.priority` run (R4).
    With `check.global_priority: true` the comparison is instead over the
    handler priorities of the enabled events, across nodes.

Everything still enabled after these rules is a nondeterministic choice the
search explores exhaustively.

Rule 5 (latency and faults, all off by default; see `checker.faults` for the
    scenario keys). `check.latency` gives a message a delivery delay in a
    range, globally or per topic/service, each value a separate branch
    (`Rules.delivery`); with `faults.drop` / `faults.duplicate` each delivery
    on a listed topic is also delivered, lost or delivered twice, each a
    branch (`Rules.copies`). These branches are enumerated like `ctx.choose`
    options after the handler's own choices (per delivery: the fault, then
    the delay of each copy). A crash fault is not an event: it is one more
    action in every world with something pending while the path has fewer
    than `faults.crash.max` crashes (`Rules.crashable`), taken at t*. A
    message due after its deadline (`Rules.delivery` sets it) is a deadline
    miss when it is taken; because of Rule 1 it is taken exactly at its due
    time, so only latency or FIFO clamping can make it late. A call to a
    service nobody serves fails at its timeout with `CallError` failure
    `NO_SERVER` or `TIMEOUT`, each a branch (`Rules.no_server`): live, which one
    depends on how soon Zenoh gives up on the query.

Rule 6 (QoS). A subscription declared `qos=QoS(depth=d)` (KEEP_LAST, default
    10) holds at most d waiting messages live: when one more arrives the
    core drops the oldest waiting one (`runtime.core.node_core`, ``dropped_keep_last``).
    In a world, the deliveries due at t* to one subscription are the ones
    waiting there (Rule 1: nothing pending is due earlier). Whether live
    dropped one depends on whether the handler ran before the newer ones
    arrived, so the drop is an action, not a forced step: a pending delivery
    due at t* may be dropped (`Drop`, `Rules.droppable`) while d other
    deliveries to the same subscription are due at t* and, under `ros`, it
    is the earliest-sent of its stream (the oldest of its sender: Zenoh keeps
    a publisher's order). With one sender per subscription this is exactly
    the live rule; with several, which waiting message is oldest is an order
    the world does not keep, so any sender's oldest may go (more behaviours,
    never fewer). Below the depth nothing is ever dropped, in either driver
    (the depth and the count are `runtime.contract.rules`' KEEP_LAST rule, which
    the live core applies too).
    BEST_EFFORT (on the subscription, or in the publishing node's
    `publications`) makes each delivery to that subscription a branch:
    delivered or lost (`Rules.copies`), as Zenoh's `CongestionControl.DROP`
    may lose it live. `/_liveliness` subscriptions are refused at load, and
    TRANSIENT_LOCAL ones of nodes that may crash (`checker.topology`). Both
    parts of the rule read only the target node's own pending deliveries: a
    node's enabling stays decidable per node.

Rule 7 (timers). An `@every` tick, when it runs, arms the next one a period
    later. Live, a node that takes a tick a period or more later than the next
    one was due skips the missed periods (`runtime.contract.rules.next_tick`).
    With a timer lateness range (`check.timer_lateness`, or a timing model's
    under `--statistical`) whose top reaches that far, the next tick's due time
    is a branch (`Rules.tick_after`): one period on, or each later tick of the
    timer's grid the range reaches, as `runtime.contract.rules.next_ticks` lists
    them. Without one (the default) a tick is always taken on time: one branch,
    the next tick one period on.

Relaxed timing (`Rules.enabled_within`), used only to compare a live run with
the model (`agreement.validate`). A live clock is continuous, so events the
model runs at different times may run live in another order. With a
tolerance T, any pending event due at most T ms after t* (any at all when T is
None) is enabled, provided under `ros` it is the earliest-sent pending
message of its *stream* (`stream`: messages of one kind from one sender to one
handler of one node). Live, that order holds at any timing (Zenoh keeps each
publisher's order and a subscription's queue is FIFO), while Rule 3's wider
channel order only holds among events of equal time and priority.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, final

from twinfleet.checker.choices import ExploringChooser, LatencySite, LatenessSite
from twinfleet.checker.faults import DROP, DUPLICATE, CheckSettings
from twinfleet.checker.options import Semantics
from twinfleet.checker.world import Event
from twinfleet.runtime.contract.kinds import EventKind
from twinfleet.runtime.contract.messages import CallFailure
from twinfleet.runtime.contract.rules import keep_last_excess, next_ticks

if TYPE_CHECKING:
    from twinfleet.checker.world import World


@final
@dataclass(frozen=True, slots=True)
class Rules:
    """The enabling rules a `System` applies (module docstring).

    Attributes:
        semantics: `Semantics.ROS` (per-sender FIFO) or `Semantics.REBECA` (RMC's rules);
            a plain string is accepted and converted.
        node_priorities: per node index, its instance priority (used by `rebeca`).
        global_priority: `rebeca` only: compare handler priorities across nodes.
        settings: the optional `check:` settings of Rule 5 (latency, deadlines, faults).
        depths: KEEP_LAST depth per (node index, subscription handler) (Rule 6).
        lossy: (topic, node index) pairs whose deliveries may be lost (BEST_EFFORT, Rule 6).
    """

    semantics: Semantics = Semantics.ROS
    node_priorities: tuple[int, ...] = ()
    global_priority: bool = False
    settings: CheckSettings = field(default_factory=CheckSettings)
    depths: Mapping[tuple[int, str], int] = field(default_factory=dict)
    lossy: frozenset[tuple[str, int]] = frozenset()
    fifo: bool = field(init=False)
    has_latency: bool = field(init=False)
    _ranges: dict[str, tuple[int, int] | None] = field(init=False, repr=False, compare=False)
    _shallowest: int = field(init=False, repr=False, compare=False)
    _one_node: bool = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        try:
            object.__setattr__(self, "semantics", Semantics(self.semantics))
        except ValueError:
            raise ValueError(f"unknown semantics {self.semantics!r}; expected ros or "
                             "rebeca") from None
        latency = self.settings.latency
        if latency is not None and not 0 <= latency[0] <= latency[1]:
            raise ValueError(f"latency must be [min, max] with 0 <= min <= max, got {latency}")
        object.__setattr__(self, "fifo", self.semantics is Semantics.ROS)
        object.__setattr__(self, "_shallowest", min(self.depths.values(), default=1 << 62))
        # Rule 4 with no two nodes of one instance priority: a single node runs at a time
        prios = self.node_priorities
        object.__setattr__(self, "_one_node", not self.fifo and not self.global_priority
                           and bool(prios) and len(set(prios)) == len(prios))
        ranges = dict(self.settings.topic_latency)
        object.__setattr__(self, "_ranges", ranges)
        object.__setattr__(self, "has_latency", latency is not None
                           or any(r is not None for r in ranges.values()))

    @property
    def latency(self) -> tuple[int, int] | None:
        """The global (min, max) delivery delay of messages in ms, or None."""
        return self.settings.latency

    def latency_range(self, name: str) -> tuple[int, int] | None:
        """The delivery-delay range of messages on topic/service `name` (None: no delay)."""
        return self._ranges.get(name, self.settings.latency)

    # ------------------------------------------------------------ Rules 1-4

    def enabled(self, events: Sequence[Event]) -> list[int]:
        """Indices (into the canonically sorted `events`) of the events that may run next."""
        if not events:
            return []
        now = events[0].due
        if len(events) == 1 or events[1].due != now:
            return [0]  # alone at t* (most steps of a fleet whose latencies spread them)
        if self._one_node:
            return _lowest(events, now, self.node_priorities)
        # One pass over the events at t* (a prefix: they are sorted by due) for each node's
        # lowest handler priority; Rule 4 then narrows the nodes, not the events.
        best: dict[int, int] = {}
        n = 0
        for ev in events:
            if ev.due != now:
                break
            n += 1
            target = ev.target
            if target not in best or ev.priority < best[target]:
                best[target] = ev.priority
        if self.fifo:
            return _earliest_sent(events, [i for i in range(n)
                                           if events[i].priority == best[events[i].target]])
        if len(best) > 1 and (self.global_priority or self.node_priorities):
            best = self._across_nodes(best)
        get = best.get
        return [i for i in range(n) if get(events[i].target) == events[i].priority]

    def _across_nodes(self, best: dict[int, int]) -> dict[int, int]:
        """Rule 4: of `best` (each node's lowest handler priority at t*), the nodes that run:
        the lowest handler priority across nodes, or the lowest instance priority."""
        if self.global_priority:
            top = min(best.values())
            return {t: p for t, p in best.items() if p == top}
        prios = self.node_priorities
        top = min([prios[t] for t in best])
        return {t: p for t, p in best.items() if prios[t] == top}

    def add(self, pending: list[Event], ev: Event) -> None:
        """Append `ev` to `pending`, giving it its rank (and FIFO clamping) under `ros`."""
        if not self.fifo:
            pending.append(ev)
            return
        sender, target, msg = ev.sender, ev.target, ev.message
        mates = [other.due for other in pending
                 if other.target == target and other.sender == sender and other.message == msg]
        due = ev.due
        if mates and self.has_latency and msg:
            due = max(due, *mates)
        rank = mates.count(due)
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
        sender, target, msg = gone.sender, gone.target, gone.message
        for i in range(len(rest)):
            ev = rest[i]
            if ev.due != due:
                if ev.due > due:
                    break
                continue
            if (ev.rank > rank and ev.sender == sender and ev.target == target
                    and ev.message == msg):
                rest[i] = ev.with_rank(ev.rank - 1)
        return rest

    # ------------------------------------------------------------ Rule 5

    def delivery(self, now: int, name: str, chooser: ExploringChooser,
                 publish: int | None = None) -> tuple[int, int | None]:
        """(due time, deadline or None) of a message on `name` sent at `now` (a copy of
        the handler's publish number `publish`, if it is one); a latency range makes the
        due time a branch of `chooser`."""
        due = now
        span = self._ranges.get(name, self.settings.latency)
        if span is not None:
            low, high = span
            due = now + low + (chooser.branch(high - low + 1,
                                              LatencySite(name, low, now, publish))
                               if high > low else 0)
        settings = self.settings
        limit = settings.deadline_for(name) if settings.has_deadlines else None
        return due, None if limit is None else now + limit

    def copies(self, name: str, chooser: ExploringChooser, target: int = -1) -> tuple[int, str]:
        """How many copies of one message on `name` to node `target` arrive (a branch of
        `chooser` when `name` may be dropped or duplicated, or is BEST_EFFORT for `target`,
        Rule 6), and the fault taken ("" for none)."""
        options = self.settings.delivery_options(name)
        if len(options) == 1 and not self.lossy:
            return 1, ""
        if (name, target) in self.lossy and DROP not in options:
            options = (*options, DROP)
        if len(options) == 1:
            return 1, ""
        pick = options[chooser.branch(len(options))]
        if pick == DROP:
            return 0, "dropped"
        if pick == DUPLICATE:
            return 2, "duplicated"
        return 1, ""

    def no_server(self, chooser: ExploringChooser) -> CallFailure:
        """Rule 5: the failure a call to a service nobody serves ends with, a branch of
        `chooser`: live, Zenoh finalises such a query with no reply (`NO_SERVER`), or a
        server that took it and went away leaves it to its timeout (`TIMEOUT`); either
        way at the call's timeout here."""
        return _NO_SERVER[chooser.branch(len(_NO_SERVER))]

    def may_drop(self, events: Sequence[Event]) -> bool:
        """False when `droppable(events)` is surely empty: fewer events are due at t* than
        the shallowest KEEP_LAST subscription holds (read off one index; a search asks this
        of every world it expands, and a fleet's queues are mostly that short)."""
        shallowest = self._shallowest
        return len(events) > shallowest and events[shallowest].due == events[0].due

    def droppable(self, events: Sequence[Event], tolerance_ms: int | None = 0) -> list[int]:
        """Rule 6: indices (into the sorted `events`) of the deliveries KEEP_LAST may drop
        now: due at t*, with at least their subscription's depth of other deliveries to it
        due at t*, and under `ros` the earliest-sent of their stream. Under relaxed timing
        (`enabled_within`'s `tolerance_ms`, None: any) "at t*" is "by t* + tolerance"."""
        if len(events) <= self._shallowest:
            return []
        limit = None if tolerance_ms is None else events[0].due + tolerance_ms
        waiting: dict[tuple[int, str], list[int]] = {}
        for i, ev in enumerate(events):
            if limit is not None and ev.due > limit:
                break
            if ev.kind is EventKind.DELIVERY:
                waiting.setdefault((ev.target, ev.method), []).append(i)
        depths, out = self.depths, []
        for sub, found in waiting.items():
            if keep_last_excess(len(found), depths.get(sub, len(found))):
                out += _stream_heads(events, found) if self.fifo else found
        return sorted(out)

    # ------------------------------------------------------------ Rule 7

    def tick_after(self, due: int, timer: tuple[int, int], chooser: ExploringChooser) -> int:
        """The due time of the tick after an `@every` tick due at `due` with `timer`'s
        (period, phase): one period on, or, where the timer lateness reaches so far, a
        branch of `chooser` over the ticks a late node skips to (Rule 7)."""
        period = timer[0]
        lateness = self.settings.timer_lateness
        if lateness is None or lateness[1] < 2 * period:  # never a period behind
            return due + period
        ticks = next_ticks(due, *timer, lateness)
        if len(ticks) == 1:
            return ticks[0][0]
        k = chooser.branch(len(ticks), LatenessSite(tuple(late for _, late in ticks)))
        return ticks[k][0]

    def crashable(self, world: World) -> tuple[int, ...]:
        """The nodes that may crash in `world`: none with nothing pending or once the path
        has had `faults.crash.max` crashes."""
        crash = self.settings.crash
        if crash is None or not world.events or world.crashes >= crash.max:
            return ()
        return crash.nodes

    # ------------------------------------------------------------ relaxed timing

    def enabled_within(self, events: Sequence[Event], tolerance_ms: int | None) -> set[int]:
        """Events due by t* + `tolerance_ms` (None: any) that are, under `ros`, the
        earliest-sent pending message of their stream (module docstring)."""
        if not events:
            return set()
        limit = None if tolerance_ms is None else events[0].due + tolerance_ms
        fifo = self.fifo
        first: dict[tuple[int, int, str, str], int] = {}
        for j, ev in enumerate(events):
            key = stream(ev) if fifo else None
            if key is not None:
                k = first.get(key)
                if k is None or (ev.due, ev.rank) < (events[k].due, events[k].rank):
                    first[key] = j
        heads = set(first.values())
        return {j for j, ev in enumerate(events) if (limit is None or ev.due <= limit)
                and (j in heads or not fifo or not ev.message)}

    def stream_head(self, events: Sequence[Event], ev: Event) -> Event:
        """The earliest-sent pending message of `ev`'s stream (`ev` itself for timers)."""
        key = stream(ev)
        if key is None:
            return ev
        return min((e for e in events if stream(e) == key), key=lambda e: (e.due, e.rank))


_NO_SERVER = (CallFailure.NO_SERVER, CallFailure.TIMEOUT)


def stream(ev: Event) -> tuple[int, int, str, str] | None:
    """The live FIFO stream of a message (module docstring); None for timers."""
    return (ev.sender, ev.target, ev.kind, ev.method) if ev.message else None


def _stream_heads(events: Sequence[Event], found: list[int]) -> list[int]:
    """Of the deliveries `found` (indices into `events`), the earliest-sent of each sender."""
    first: dict[int, int] = {}
    for i in found:
        j = first.get(events[i].sender)
        if j is None or events[i].rank < events[j].rank:
            first[events[i].sender] = i
    return list(first.values())


def _lowest(events: Sequence[Event], now: int, prios: tuple[int, ...]) -> list[int]:
    """Rules 2 and 4 where no two nodes share an instance priority: the node of the lowest
    instance priority with an event at `now` runs its events of its lowest handler priority,
    so the events at `now` of the lowest (instance priority, handler priority) are enabled."""
    picked: list[int] = []
    top = handler = 0
    for i, ev in enumerate(events):
        if ev.due != now:
            break
        p = prios[ev.target]
        if not picked or p < top or (p == top and ev.priority < handler):
            top, handler, picked = p, ev.priority, [i]
        elif p == top and ev.priority == handler:
            picked.append(i)
    return picked


def _earliest_sent(events: Sequence[Event], picked: list[int]) -> list[int]:
    """Per channel, keep only the lowest-ranked of the picked events."""
    first: dict[tuple[int, int, bool], int] = {}
    for i in picked:
        ev = events[i]
        chan = (ev.sender, ev.target, ev.message)  # Event.channel, without a property call
        j = first.get(chan)
        if j is None or ev.rank < events[j].rank:
            first[chan] = i
    return sorted(first.values())
