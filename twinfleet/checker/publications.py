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

Nodes of one class run the same handlers, so a send seen from one of them is
entered for each of the others too (`peers`; not into the sender's own class,
where "the other one" would need a mapping between instances). This adds
edges, which only grows closures, so it is sound whether or not a twin ever
sends it; it saves the restart that would come when the twin is first seen
sending it (the station's two askers: 2 restarts become 1).

A breadth-first search learns level by level (`freeze`): while frozen, what
handlers are seen to send is only noted (`learned`), the reduction keeps
reading the relation it started the level with, and the search restarts at
the end of a level that learned something, with everything learned added
(`commit`). Every world of a level is then expanded under the same
relation, whatever the order of its expansions or the process it runs in, so
a search on several workers (`checker.cluster`), which merges what each
learned, finds the graph of the search in one process.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Any, Final, final

from twinfleet.runtime.contract.kinds import EventKind

if TYPE_CHECKING:
    from twinfleet.checker.transition import Variant

Handler = tuple[int, str]  # (node index, method name)
Edge = tuple[int, Handler, str, int]  # (target node, sending handler, method, priority)

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
        version: grows whenever the relation grows, or, frozen, learns (a search compares it).
        unknown: the first event kind outside `KNOWN_KINDS` seen, or None.
        frozen: new edges are noted in `pending` (and an unknown kind in
            `pending_unknown`) instead of entering the relation (`freeze`).
        peers: per node, the other nodes of its class, whose handlers get its sends too.
        derived: what `checker.closure` derives from the relation and from variant lists,
            kept across worlds; emptied whenever the relation grows, so nothing in it was
            derived from an older relation.
    """

    __slots__ = ("derived", "frozen", "into", "out", "peers", "pending", "pending_unknown",
                 "unknown", "version")

    def __init__(self, nodes: int, peers: Sequence[Sequence[int]] = ()) -> None:
        #: per node, the other nodes of its class (`_add` gives their handlers its sends)
        self.peers: Sequence[Sequence[int]] = peers or [()] * nodes
        self.into: list[dict[Handler, set[tuple[str, int]]]] = [{} for _ in range(nodes)]
        self.out: dict[Handler, set[Handler]] = {}
        self.version = 0
        self.unknown: str | None = None
        self.derived: dict[Any, Any] = {}
        self.frozen = False
        self.pending: set[Edge] = set()
        self.pending_unknown: str | None = None

    def freeze(self) -> None:
        """From now on note what is learned without using it (module docstring)."""
        self.frozen = True

    def learned(self) -> tuple[frozenset[Edge], str | None]:
        """What was noted while frozen, not yet committed: edges, and an unknown kind."""
        return frozenset(self.pending), self.pending_unknown

    def commit(self, edges: Iterable[Edge] = (), unknown: str | None = None) -> None:
        """Add what was noted here, and `edges` and `unknown` (learned by other workers),
        to the relation."""
        for target, sender, method, priority in (*self.pending, *edges):
            self._add(target, sender, (method, priority))
        unknown = self.pending_unknown or unknown
        if unknown is not None and self.unknown is None:
            self.unknown = unknown
            self._grew()
        self.pending.clear()
        self.pending_unknown = None

    def observe(self, sender: Handler, now: int, variants: Sequence[Variant]) -> None:
        """Record the zero-delay events that handler `sender`'s run at `now` created."""
        into = self.into
        for v in variants:
            for e in v.events:
                if e.kind not in KNOWN_KINDS and self.unknown is None:
                    self._unknown(str(e.kind))
                if e.due != now:
                    continue
                made = into[e.target].get(sender)
                item = (e.method, e.priority)
                if made is not None and item in made:
                    continue
                if not self.frozen:
                    self._add(e.target, sender, item)
                elif (edge := (e.target, sender, e.method, e.priority)) not in self.pending:
                    self.pending.add(edge)
                    self.version += 1

    def _unknown(self, kind: str) -> None:
        if not self.frozen:
            self.unknown = kind
            self._grew()
        elif self.pending_unknown is None:
            self.pending_unknown = kind
            self.version += 1

    def _add(self, target: int, sender: Handler, item: tuple[str, int]) -> None:
        node, method = sender
        peers = self.peers[node]
        for y in (node, *peers) if target != node and target not in peers else (node,):
            made = self.into[target].setdefault((y, method), set())
            if item not in made:
                made.add(item)
                self.out.setdefault((y, method), set()).add((target, item[0]))
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
        return (self.into, self.out, self.version, self.unknown, self.frozen, self.pending,
                self.pending_unknown)

    def __setstate__(self, state: tuple[Any, ...]) -> None:
        self.into, self.out, self.version, self.unknown = state[:4]
        self.frozen, self.pending, self.pending_unknown = (
            state[4:] if len(state) > 4 else (False, set(), None))
        self.derived = {}
        if not hasattr(self, "peers"):  # unpickled alone: no class information
            self.peers = [()] * len(self.into)
