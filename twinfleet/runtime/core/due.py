"""`DueEntries`: a node core's timed entries — `ctx.after` timers, `@every` ticks, call timeouts.

Each is an `Event` with a due time in fleet ms, kept in a heap ordered by
(due, arming order). The core's driver asks `next_due()` and has the due ones
moved to the inbox; an entry leaves the heap when it falls due or when the
replay gate takes it, and then

* a PERIODIC tick arms the next one, one period later — or, when the node is
  so far behind that the next one is a period or more past (a suspended
  process), the first one after now, skipping the missed periods (the rule is
  `runtime.contract.rules.next_tick`, which the checker applies too);
* a TIMEOUT ends its call: a reply that comes later is ignored. A TIMEOUT whose
  call got its answer first is void and never leaves the heap as an event.
"""

from __future__ import annotations

import heapq
import itertools
from collections.abc import Sequence
from typing import final

from twinfleet.runtime.contract.context import Call
from twinfleet.runtime.contract.kinds import EventKind
from twinfleet.runtime.contract.messages import CallError, CallFailure
from twinfleet.runtime.contract.node import HandlerSpec, Node
from twinfleet.runtime.contract.rules import first_tick, next_tick
from twinfleet.runtime.core.events import Event


@final
class DueEntries:
    """The timed entries of one node, and its open calls.

    Args:
        node: the node (its name is the sender of its own timers; its spec gives priorities).
    """

    def __init__(self, node: Node) -> None:
        self.name = node.name
        self.node = node
        self.counter = itertools.count()  # also numbers the core's inbox entries and calls
        self._heap: list[tuple[int, int, int, Event]] = []  # (due, n, priority, entry)
        self._calls: dict[int, Call] = {}
        self._priorities = {s.method: s.priority for s in node.spec().handlers}
        self._periods: dict[str, tuple[int, int]] = {}  # @every method -> (period, phase)

    def priority(self, method: str) -> int:
        """The declared priority of handler `method` (0 if undeclared)."""
        return self._priorities.get(method, 0)

    def start(self, specs: Sequence[HandlerSpec], now_ms: int) -> None:
        """Arm the first tick of every `@every` spec after `now_ms`."""
        for spec in specs:
            period = self.node.period_ms(spec)
            self._periods[spec.method] = (period, spec.phase_ms)
            self.arm(Event(EventKind.PERIODIC, spec.method, (), self.name,
                           due=first_tick(period, spec.phase_ms, now_ms)))

    def arm(self, entry: Event) -> None:
        """Add a timed entry (its `due` set)."""
        assert entry.due is not None
        heapq.heappush(self._heap, (entry.due, next(self.counter), self.priority(entry.handler),
                                    entry))

    def open_call(self, call: Call, now_ms: int) -> int:
        """Register a call made at `now_ms` and arm its TIMEOUT; return the call's id."""
        cid = next(self.counter)
        self._calls[cid] = call
        self.arm(Event(EventKind.TIMEOUT, call.reply_to, (CallError(call.service, CallFailure.TIMEOUT, "timeout"),),
                       self.name, call.service, due=now_ms + call.timeout_ms, call=cid))
        return cid

    def close_call(self, cid: int) -> Call | None:
        """End call `cid` (its answer came); None if it is over already."""
        return self._calls.pop(cid, None)

    def next_due(self) -> int | None:
        """When the earliest live entry is due, or None."""
        heap = self._heap
        while heap and self._void(heap[0][3]):
            heapq.heappop(heap)
        return heap[0][0] if heap else None

    def pop_due(self, now_ms: int) -> list[tuple[int, int, Event]]:
        """Remove the entries due by `now_ms`: (due, priority, entry), in due order."""
        heap, out = self._heap, []
        while heap and heap[0][0] <= now_ms:
            due, _, priority, entry = heapq.heappop(heap)
            if self._leave(entry, now_ms):
                out.append((due, priority, entry))
        return out

    def take(self, entry: Event, now_ms: int) -> bool:
        """Remove `entry` before it falls due (the replay gate); False if it is not here."""
        for i, key in enumerate(self._heap):
            if key[3] is entry:
                del self._heap[i]
                heapq.heapify(self._heap)
                return self._leave(entry, now_ms)
        return False

    def entries(self) -> list[Event]:
        """The live entries, in the order they would run: by due time, then priority."""
        keys = sorted(self._heap, key=lambda key: (key[0], key[2], key[1]))
        return [key[3] for key in keys if not self._void(key[3])]

    def timers(self) -> int:
        """How many `ctx.after` timers and `@every` ticks are armed (call timeouts aside)."""
        return sum(1 for key in self._heap if key[3].kind is not EventKind.TIMEOUT)

    def _void(self, entry: Event) -> bool:
        return entry.kind is EventKind.TIMEOUT and entry.call not in self._calls

    def _leave(self, entry: Event, now_ms: int) -> bool:
        """An entry leaves the heap to run: end its call, or arm the next tick."""
        if entry.kind is EventKind.TIMEOUT:
            return self._calls.pop(entry.call, None) is not None  # type: ignore[arg-type]
        if entry.kind is EventKind.PERIODIC and entry.due is not None:
            period, phase = self._periods[entry.handler]
            self.arm(Event(EventKind.PERIODIC, entry.handler, (), self.name,
                           due=next_tick(entry.due, period, phase, now_ms)))
        return True
