"""The learned send relation the partial-order reduction relies on (`checker.reduction`).

Node code declares what it subscribes to and serves, not what it publishes
(topic names may be computed: the map server publishes ``f"/{robot}/scan"``).
So the reduction learns, from every handler run the system computes, which
node creates which events *at the same instant* at which node, with which
handler priorities (`Publications.observe`, called by `System` on every
fresh variant list). Events created with a delay play no part in one
instant (semantics Rule 1), so only zero-delay ones are recorded.

The relation is an assumption while it is incomplete. It is checked, not
trusted: a reduced search that learns a new edge is started again from
scratch (`Search`), so a finished reduced search has seen every edge of
every reachable transition. Why that suffices: if some reachable transition
sends outside the relation, take a shortest path to the *first* such
transition f. Every transition before f respects the relation, so the
persistence argument of `checker.reduction` holds along the path and moves
it into the reduced graph; f itself only has to stay enabled and do the same
thing, which depends on its own node's state and event only (the node
contract). So the reduced search also meets a transition outside the
relation, and restarts.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Final, final

from twinfleet.runtime.contract.kinds import EventKind

if TYPE_CHECKING:
    from twinfleet.checker.transition import Variant

Handler = tuple[int, str]  # (node index, method name)

#: Event kinds whose rules `checker.reduction` knows; any other kind turns it off for the run.
KNOWN_KINDS: Final = frozenset({EventKind.DELIVERY, EventKind.REQUEST, EventKind.REPLY,
                                EventKind.TIMEOUT, EventKind.TIMER, EventKind.PERIODIC})


@final
class Publications:
    """Zero-delay events handlers have been seen to create, per target and sending handler.

    A *handler* here is (node index, method name). Attributes:
        into: per target node X, sending handler (Y, m) -> the (method, priority) of the
            events m created at X due at the instant of its run (Y == X: zero-delay timers).
        out: per sending handler, the handlers (X, method) those events run.
        version: grows whenever the relation grows (a search compares it).
        unknown: the first event kind outside `KNOWN_KINDS` seen, or None.
        derived: what `checker.closure` derives from the relation and from variant lists,
            kept across worlds; emptied whenever the relation grows, so nothing in it was
            derived from an older relation.
    """

    __slots__ = ("derived", "into", "out", "unknown", "version")

    def __init__(self, nodes: int) -> None:
        self.into: list[dict[Handler, set[tuple[str, int]]]] = [{} for _ in range(nodes)]
        self.out: dict[Handler, set[Handler]] = {}
        self.version = 0
        self.unknown: str | None = None
        self.derived: dict[Any, Any] = {}

    def observe(self, sender: Handler, now: int, variants: Sequence[Variant]) -> None:
        """Record the zero-delay events that handler `sender`'s run at `now` created."""
        into = self.into
        for v in variants:
            for e in v.events:
                if e.kind not in KNOWN_KINDS and self.unknown is None:
                    self.unknown = str(e.kind)
                    self._grew()
                if e.due != now:
                    continue
                made = into[e.target].get(sender)
                if made is None:
                    made = into[e.target][sender] = set()
                item = (e.method, e.priority)
                if item not in made:
                    made.add(item)
                    self.out.setdefault(sender, set()).add((e.target, e.method))
                    self._grew()

    def _grew(self) -> None:
        self.version += 1
        self.derived.clear()

    def acyclic(self, handlers: set[Handler]) -> bool:
        """True if the relation has no cycle among `handlers` (no zero-time cycle can run
        among them, as far as the relation knows)."""
        out, done = self.out, set()
        for root in handlers:
            if root in done:
                continue
            path, stack = {root}, [(root, iter(out.get(root, ())))]
            while stack:  # depth-first; `path` holds the handlers on the stack
                h, it = stack[-1]
                nxt = next((n for n in it if n in handlers and n not in done), None)
                if nxt is None:
                    stack.pop()
                    path.discard(h)
                    done.add(h)
                elif nxt in path:
                    return False
                else:
                    path.add(nxt)
                    stack.append((nxt, iter(out.get(nxt, ()))))
        return True

    def edges(self) -> int:
        """How many (sending handler, target, method, priority) entries are known."""
        return sum(len(p) for per in self.into for p in per.values())

    def __getstate__(self) -> tuple[object, ...]:
        return (self.into, self.out, self.version, self.unknown)

    def __setstate__(self, state: tuple[object, ...]) -> None:
        self.into, self.out, self.version, self.unknown = state  # type: ignore[assignment]
        self.derived = {}
