"""The closure of a seed node under C-in and C-out: a persistent set of one world.

`checker.reduction` explains the conditions; this module computes them for one
world at time t from what the world holds (its events due t, their channels and
priorities), the variants of the events considered (what they create at whom at
t) and the learned send relation (`checker.publications`: which handlers may
still run at t, and what they may create at whom).
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from typing import TYPE_CHECKING, Any, Final, TypeVar, final

from twinfleet.checker.commuting import commute, loose_nodes
from twinfleet.checker.publications import KNOWN_KINDS
from twinfleet.checker.transition import RunEvent

if TYPE_CHECKING:
    from twinfleet.checker.publications import Publications
    from twinfleet.checker.system import System
    from twinfleet.checker.visibility import Visibility
    from twinfleet.checker.world import World

_INF: Final = 1 << 62  # the enabled priority of a node with nothing enabled
_NO_ROOTS: Final[frozenset[tuple[int, str]]] = frozenset()
_T = TypeVar("_T")


@final
class Closure:
    """The facts of one world the closure reads, and the closure (module docstring).

    Args:
        system: the system searched.
        publications: the learned send relation.
        visibility: what the properties read.
        world: the world to expand.
        enabled: indices of its enabled events.
    """

    def __init__(self, system: System, publications: Publications, visibility: Visibility,
                 world: World, enabled: list[int],
                 queued: frozenset[tuple[int, int]] = frozenset()) -> None:
        self.system = system
        self.publications = publications
        self.visibility = visibility
        self.world = world
        self.enabled = enabled
        events = world.events
        self.t = t = events[0].due
        # One pass over the enabled events and one over the events due t, with locals:
        # this runs for nearly every world of a reduced search.
        by_node: dict[int, list[int]] = {}
        p: dict[int, int] = {}
        for i in enabled:
            ev = events[i]
            idxs = by_node.get(ev.target)
            if idxs is None:
                by_node[ev.target] = [i]
                p[ev.target] = ev.priority  # a node's enabled events share one priority
            else:
                idxs.append(i)
        self.by_node = by_node
        self.p = p
        due: set[tuple[int, str]] = set()  # handlers with an event due t
        harmless: set[tuple[int, int]] = set()  # channels with a message at p_target
        unknown = False
        fifo = system.rules.fifo
        for ev in events:
            if ev.due != t:
                break
            if ev.kind not in KNOWN_KINDS:
                unknown = True
            due.add((ev.target, ev.method))
            if fifo and ev.message and ev.priority == p.get(ev.target) and \
                    (ev.target, ev.priority) not in queued:
                # A later message on a FIFO channel cannot overtake this one, so its sender
                # cannot disturb the target; but into a KEEP_LAST queue at this priority
                # (Rule 6) it could push the target over its depth and let a delivery of
                # the target's enabled ones be dropped (`queued`: (node, priority) pairs).
                harmless.add((ev.sender, ev.target))
        self.due = frozenset(due)  # a key of `runnable`'s entries, frozen once
        self.harmless = harmless
        self.unknown = unknown
        self._sends: dict[int, list[tuple[int, int]] | None] = {}
        # the last set `runnable` returned, and its nodes' top priorities (`_top`)
        self._tops: tuple[set[tuple[int, str]] | None, dict[int, int]] = (None, {})
        #: loose node -> its representative (`checker.commuting`)
        self.loose = loose_nodes(system, world, by_node) if system.topology.commuting else {}
        self._commutes: dict[int, bool] = {}  # loose node -> all its pairs commute here
        self.pairs = self.refuted = 0  # pairs checked in both orders; of those, not commuting

    def runnable(self, frozen: set[int], loose: frozenset[int] = frozenset()
                 ) -> set[tuple[int, str]]:
        """Handlers of nodes outside `frozen` that may run at t: those with an event due,
        the handlers of the `loose` nodes of `frozen` (their other events may run), and
        those such handlers may trigger at zero delay (the learned relation). The set is
        shared by the closures of every world with the same due handlers: read only."""
        # Few distinct (due handlers, frozen, loose handlers) recur in many worlds, so the
        # search (and `_top`'s maxima over the set) is done once per key and relation version.
        roots = [self._handler(x) for x in loose if x in frozen] if loose else []
        derived = self.publications.derived
        key = (self.due, frozenset(frozen), frozenset(roots) if roots else _NO_ROOTS)
        entry = derived.get(key)
        if entry is None:
            out = self.publications.out
            reach = [h for h in self.due if h[0] not in frozen] + roots
            seen = set(reach)
            while reach:
                for h in out.get(reach.pop(), ()):
                    if h not in seen and h[0] not in frozen:
                        seen.add(h)
                        reach.append(h)
            entry = remember(derived, key, (seen, {}))
        self._tops = entry
        return entry[0]

    def sends(self, i: int) -> list[tuple[int, int]] | None:
        """(target, priority) of the events due t that some variant of event i creates at
        other nodes; None if one is of a kind the reduction does not know."""
        if i in self._sends:
            return self._sends[i]
        found = self._sends[i] = sends_at(self.system, self.publications, self.world, i)
        return found

    def smallest(self) -> list[int] | None:
        """The smallest of the seeds' persistent sets (the first found of that size), or
        None if no seed gives one."""
        best: list[int] | None = None
        # Seeds with the fewest events first (then by index); plain singletons before a loose
        # node's one event, which costs its pair checks. Tuples sort without a key call.
        loose = self.loose
        for _, seed in sorted([(len(idxs) + (x in loose) / 2, x)
                               for x, idxs in self.by_node.items()]):
            found = self.persistent(seed)
            if found is not None and (best is None or len(found) < len(best)):
                best = found
                if len(best) == 1:
                    break
        return best

    def persistent(self, seed: int) -> list[int] | None:
        """The persistent set grown from `seed`, if smaller than everything and invisible
        (a visible event may still be guarded by adding the nodes of a guard). A loose
        node gives its representative only, unless its other events may disturb the set or
        a pair of its events does not commute here (`checker.commuting`)."""
        loose = frozenset(self.loose)
        nodes = self.grow({seed}, loose)
        for _ in range(len(self.by_node) + len(loose) + 1):
            if nodes is None:
                return None
            chosen = sorted(i for x in nodes for i in self._events(x, loose))
            if len(chosen) == len(self.enabled):
                return None
            bad = self._disturbing(nodes, loose)
            if not bad:
                acyclic = partial(self.acyclic, nodes, loose)
                guard = self.visibility.needs(self.system, self.world, chosen, nodes - loose,
                                              acyclic)
                if guard is not None:
                    if not guard or guard <= nodes:
                        return None
                    nodes = self.grow(nodes | guard, loose)
                    continue
                bad = {x for x in loose & nodes if not self._pairs_commute(x, acyclic)}
                if not bad:
                    return chosen
            loose -= bad
            nodes = self.grow(nodes, loose)
        return None

    def grow(self, start: set[int], loose: frozenset[int] = frozenset()) -> set[int] | None:
        """Close `start` under C-in and C-out; None when it must hold every enabled event.
        Nodes of `loose` that join contribute their representative only."""
        into = self.publications.into
        frozen = set(start)
        work = list(start)
        can = self.runnable(frozen, loose)
        while work:
            x = work.pop()
            added = (self._incoming(x, frozen, can, into[x], loose)
                     + self._outgoing(x, frozen, can, loose))
            added = [y for y in added if y not in frozen]
            if not added:
                continue
            frozen.update(added)
            work += added
            if all(n in frozen for n in self.by_node) and not loose & frozen:
                return None
            can = self.runnable(frozen, loose)
        return frozen

    def acyclic(self, nodes: set[int], loose: frozenset[int]) -> bool:
        """True if the handlers that may run at t beside the set of `nodes` trigger no
        zero-time cycle among themselves (by the learned relation): every path that
        avoids the set is then finite (`checker.visibility`: rising goals)."""
        return self.publications.acyclic(self.runnable(nodes, loose))

    def _events(self, x: int, loose: frozenset[int]) -> list[int]:
        """The enabled events node x contributes: its representative if loose, else all."""
        return [self.loose[x]] if x in loose else self.by_node.get(x, [])

    def _handler(self, x: int) -> tuple[int, str]:
        """The declared commuting handler of loose node x."""
        return (x, self.world.events[self.loose[x]].method)

    def _incoming(self, x: int, frozen: set[int], can: set[tuple[int, str]],
                  senders: dict[tuple[int, str], set[tuple[str, int]]],
                  loose: frozenset[int] = frozenset()) -> list[int]:
        """C-in for node x: the nodes of runnable handlers that may disturb it. Nothing is
        harmless to a loose node: a new message behind one of its waiting ones would run on
        a path that avoids the set, with no pair check."""
        disturbs = self._disturbs
        return [h[0] for h, made in senders.items()
                if h[0] not in frozen and h in can
                and any(disturbs(h[0], q, x, loose) for _, q in made)]

    def _disturbs(self, sender: int, q: int, target: int, loose: frozenset[int]) -> bool:
        """Whether a message created at t with priority `q` by `sender` disturbs node
        `target`: it would run before target's events, or beside them at their priority,
        unless its FIFO channel makes that harmless (never so at a loose node)."""
        pt = self.p.get(target, _INF)
        return q < pt or (q == pt and ((sender, target) not in self.harmless
                                       or target in loose))

    def _disturbing(self, nodes: set[int], loose: frozenset[int]) -> set[int]:
        """The loose nodes of `nodes` whose other events (which may run on a path that avoids
        the set) create at t what C-in forbids at a node of `nodes` (`_disturbs`; at their
        own node, which is loose, anything at or below their priority)."""
        into, disturbs = self.publications.into, self._disturbs
        return {x for x in loose & nodes
                if any(disturbs(x, q, target, loose)
                       for target in nodes for _, q in into[target].get(self._handler(x), ()))}

    def _pairs_commute(self, x: int, acyclic: Callable[[], bool]) -> bool:
        """True if loose node x's representative commutes here with each of its other
        enabled events (`checker.commuting.commute`; each pair checked once per world)."""
        found = self._commutes.get(x)
        if found is None:
            e = self.loose[x]
            found = True
            for j in self.by_node[x]:
                if j == e:
                    continue
                self.pairs += 1
                if not commute(self.system, self.visibility, self.world, e, j, acyclic):
                    self.refuted += 1
                    found = False
                    break
            self._commutes[x] = found
        return found

    def _outgoing(self, x: int, frozen: set[int], can: set[tuple[int, str]],
                  loose: frozenset[int] = frozenset()) -> list[int]:
        """C-out for the events node x contributes: the receivers to add (every node if
        unknown)."""
        out = []
        for i in self._events(x, loose):
            sent = self.sends(i)
            if sent is None:
                return list(self.by_node)
            for b, q in sent:
                if b not in frozen and self._top(b, can) > q:
                    out.append(b)
        return out

    def _top(self, b: int, can: set[tuple[int, str]]) -> int:
        """The highest priority number among node b's handlers that may run at t."""
        if self._tops[0] is not can:  # not the set `runnable` returned last: no maxima yet
            self._tops = (can, {})
        tops = self._tops[1]
        top = tops.get(b)
        if top is None:
            priority = self.system.topology.priority
            top = tops[b] = max((priority(b, m) for n, m in can if n == b), default=-_INF)
        return top


_DERIVED_LIMIT: Final = 8_192  # entries kept in `Publications.derived`


def sends_at(system: System, publications: Publications, world: World, i: int
             ) -> list[tuple[int, int]] | None:
    """(target, priority) of the events due at `world`'s instant that some variant of its
    enabled event i creates at other nodes; None if one is of a kind the reduction does
    not know. Read only: kept beside the variant list."""
    variants = system.variants(world, RunEvent(i))
    # System keeps one variant list per (node state, event, time), met in many worlds:
    # what it sends is kept beside it (the entry holds the list, so its id stays unique)
    derived = publications.derived
    entry = derived.get(id(variants))
    if entry is not None and entry[0] is variants:
        found: list[tuple[int, int]] | None = entry[1]
        return found
    events = world.events
    target, t = events[i].target, events[0].due
    found = []
    for v in variants:
        for e in v.events:
            if e.kind not in KNOWN_KINDS:
                found = None
                break
            if e.due == t and e.target != target:
                found.append((e.target, e.priority))
        if found is None:
            break
    return remember(derived, id(variants), (variants, found))[1]


def shape(system: System, publications: Publications, world: World, enabled: list[int]
          ) -> tuple[Any, ...] | None:
    """Everything a `Closure` of `world` reads but the visibility proviso, as a key: the
    events due at its instant (whose handler, from whom, at what priority), which of them
    are enabled, and what each enabled one may send there. Worlds of one shape whose
    enabled events change no property atom have the same persistent sets while the
    relation stays as it is (head-on's 242 closures have 55 shapes, C1a's 7,436 have
    172). None when a node is loose: its pairs are run in the world."""
    events = world.events
    commuting = system.topology.commuting
    sent: list[tuple[tuple[int, int], ...] | None] = []
    declared = False  # an enabled event's handler is declared commuting
    for i in enabled:
        ev = events[i]
        found = sends_at(system, publications, world, i)
        sent.append(None if found is None else tuple(found))
        declared = declared or (ev.target, ev.method) in commuting
    if declared:
        by_node: dict[int, list[int]] = {}
        for i in enabled:
            by_node.setdefault(events[i].target, []).append(i)
        if loose_nodes(system, world, by_node):
            return None
    t = events[0].due
    due = []
    for ev in events:
        if ev.due != t:
            break
        due.append((ev.target, ev.method, ev.sender, ev.priority, ev.kind))
    return (_SHAPE, tuple(due), tuple(enabled), tuple(sent))


_SHAPE: Final = "persistent set by shape"  # a key of `Publications.derived` (`shape`)


def remember(derived: dict[Any, Any], key: object, value: _T) -> _T:
    """Store `value` under `key` in `derived` (emptied first when full); return it."""
    if len(derived) >= _DERIVED_LIMIT:
        derived.clear()
    derived[key] = value
    return value

