"""Weak fairness for `eventually` properties: no message may be dropped for ever.

Without fairness (`Fairness.NONE`) an `eventually` property is violated by any
reachable cycle on which its expression never holds (`checker.paths.find_lasso`).
With drop faults on, every retry loop then has such a cycle: the one in which
the same message is lost on every try. Under `Fairness.WEAK` such a cycle does
not count. A *message* is identified by its content and route, `Event.key`
(kind, sender, target, handler, arguments): the same request sent again is the
same message. On a cycle (the part of a lasso that repeats for ever):

- a message is *dropped* by a step when a fault branch lost it on the way
  (`check.faults.drop`, BEST_EFFORT, a lost service request: `Transition.lost`)
  or when KEEP_LAST threw it away while it waited (`Drop`, semantics Rule 6);
- it is *handled* by a step that runs its handler.

A cycle is *fair* when every message dropped on it is also handled on it:
a message that is sent again and again is not lost every time. Only a fair
cycle violates an `eventually` property; a path that ends in a world with
nothing pending violates it as before (a finite run is never unfair).

The search: the worlds where the expression is false that are reachable from an
initial world through such worlds; their strongly connected components; in each
one, the steps between its worlds re-run and labelled with what they drop and
handle. A component holds a fair cycle exactly when, after repeatedly removing
the steps that drop a message no remaining step handles and splitting what is
left into components again, some component with a step remains (the usual test
for a Streett condition). In it, `_cycle` builds a closed walk that handles
every message it drops. Only the worlds of those components are expanded again,
and only when fairness was asked for.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Hashable, Iterable
from dataclasses import dataclass
from functools import partial
from typing import TypeVar

from twinfleet.checker.store import StateStore
from twinfleet.checker.system import System
from twinfleet.checker.transition import Drop, RunEvent, Step
from twinfleet.checker.world import World

WorldOf = Callable[[int], World]
N = TypeVar("N", bound=Hashable)


@dataclass(frozen=True, slots=True)
class _Edge:
    """One step between two worlds of a component: what it drops and what it handles."""

    source: int
    target: int
    step: Step
    dropped: frozenset[bytes]
    handled: frozenset[bytes]


@dataclass(frozen=True, slots=True)
class FairPath:
    """A counterexample under weak fairness: state ids from an initial world to the
    cycle's first world (`stem`), then the cycle's steps (none: `stem` ends in a world
    with nothing pending)."""

    stem: list[int]
    cycle: list[Step]


def fair_violation(system: System, store: StateStore, prop: str, world_of: WorldOf
                   ) -> FairPath | None:
    """A path on which `prop` never holds ending in a fair cycle or a world with nothing
    pending; None if there is none (the property holds under weak fairness). `world_of`
    rebuilds the world of a state id (`checker.paths.world_finder`)."""
    holds, terminal = store.holds[prop], store.terminal
    parents, order = _reachable(store, holds)
    ends = [s for s in order if terminal[s]]
    if ends:
        return FairPath(_stem(parents, ends[0]), [])
    position = {s: i for i, s in enumerate(order)}
    for component in cyclic_components(order, partial(_graph_successors, store, holds)):
        edges = _labelled(system, store, set(component), world_of)
        if not edges:
            continue
        fair = _fair_part(edges)
        if fair is not None:
            anchor = min({e.source for e in fair}, key=position.__getitem__)
            return FairPath(_stem(parents, anchor), [e.step for e in _cycle(anchor, fair)])
    return None


def _graph_successors(store: StateStore, holds: bytearray, sid: int) -> list[int]:
    edges = store.edges
    assert edges is not None, "fairness needs a store recorded with edges"
    targets = edges.targets
    return [w for k in edges.out(sid) if not holds[w := targets[k]]]


def _reachable(store: StateStore, holds: bytearray) -> tuple[dict[int, int], list[int]]:
    """The worlds where `prop` is false reachable through such worlds, in BFS order, and
    each one's BFS parent (-1 for an initial world)."""
    parents: dict[int, int] = {}
    order: list[int] = []
    queue = deque(r for r in store.roots if not holds[r])
    for root in queue:
        parents[root] = -1
    while queue:
        sid = queue.popleft()
        order.append(sid)
        for w in _graph_successors(store, holds, sid):
            if w not in parents:
                parents[w] = sid
                queue.append(w)
    return parents, order


def _stem(parents: dict[int, int], sid: int) -> list[int]:
    path = [sid]
    while parents[path[-1]] >= 0:
        path.append(parents[path[-1]])
    return path[::-1]


def cyclic_components(nodes: Iterable[N], successors: Callable[[N], Iterable[N]]
                      ) -> list[list[N]]:
    """The strongly connected components of the graph on `nodes` (Tarjan's algorithm,
    iterative) that hold a cycle: two nodes or more, or one with an edge to itself."""
    index: dict[N, int] = {}
    low: dict[N, int] = {}
    on_stack: set[N] = set()
    stack: list[N] = []
    found: list[list[N]] = []
    for root in nodes:
        if root in index:
            continue
        work = [(root, iter(successors(root)))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(successors(w))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                component = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    component.append(w)
                    if w == v:
                        break
                if len(component) > 1 or v in successors(v):
                    found.append(component)
    return found


def _labelled(system: System, store: StateStore, component: set[int], world_of: WorldOf
              ) -> list[_Edge]:
    """Every step between two worlds of `component`, by re-running their successors."""
    first = min(component)
    worlds = {first: world_of(first)}
    queue = [first]
    edges = []
    while queue:
        u = queue.pop()
        world = worlds[u]
        for t in system.successors(world):
            v = store.find(t.world.key)
            if t.failure is not None or v not in component:
                continue
            action = t.step.action
            dropped = set(t.lost)
            if isinstance(action, Drop):
                dropped.add(world.events[action.index].key)
            handled = frozenset((t.event.key,)) if isinstance(action, RunEvent) and \
                t.event.message else frozenset()
            edges.append(_Edge(u, v, t.step, frozenset(dropped), handled))
            if v not in worlds:
                worlds[v] = t.world
                queue.append(v)
    return edges


def _fair_part(edges: list[_Edge]) -> list[_Edge] | None:
    """The steps of a strongly connected part of `edges` on which every message dropped is
    also handled, or None: steps dropping a message no step handles cannot be on a fair
    cycle, so they are removed and what is left is split into components again."""
    work = [edges]
    while work:
        part = work.pop()
        dropped = frozenset().union(*(e.dropped for e in part))
        handled = frozenset().union(*(e.handled for e in part))
        starved = dropped - handled
        if not starved:
            return part
        kept = [e for e in part if not e.dropped & starved]
        out: dict[int, list[int]] = {}
        for e in kept:
            out.setdefault(e.source, []).append(e.target)
        nodes = sorted({e.source for e in kept} | {e.target for e in kept})
        for component in cyclic_components(nodes, partial(_targets, out)):
            inside = set(component)
            sub = [e for e in kept if e.source in inside and e.target in inside]
            if sub:
                work.append(sub)
    return None


def _targets(out: dict[int, list[int]], v: int) -> list[int]:
    return out.get(v, [])


def _cycle(anchor: int, edges: list[_Edge]) -> list[_Edge]:
    """A closed walk from `anchor` over `edges` (strongly connected, every message dropped
    on them handled on them) that handles every message it drops: a first cycle, then,
    while it drops a message it does not handle, a detour through a step that handles it.
    Each detour handles one more message, so this ends."""
    out: dict[int, list[_Edge]] = {}
    for e in edges:
        out.setdefault(e.source, []).append(e)
    first = min(out[anchor], key=lambda e: len(e.dropped))
    walk = [first, *_path(out, first.target, anchor)]
    while True:
        dropped = frozenset().union(*(e.dropped for e in walk))
        handled = frozenset().union(*(e.handled for e in walk))
        missing = sorted(dropped - handled)
        if not missing:
            return walk
        via = next(e for e in edges if missing[0] in e.handled)
        walk += [*_path(out, anchor, via.source), via, *_path(out, via.target, anchor)]


def _path(out: dict[int, list[_Edge]], source: int, target: int) -> list[_Edge]:
    """A shortest walk of steps from `source` to `target` (none when they are the same)."""
    if source == target:
        return []
    came: dict[int, _Edge | None] = {source: None}
    queue = deque([source])
    while queue:
        u = queue.popleft()
        for e in out.get(u, ()):
            if e.target not in came:
                came[e.target] = e
                if e.target == target:
                    path = []
                    node = target
                    while (step := came[node]) is not None:
                        path.append(step)
                        node = step.source
                    return path[::-1]
                queue.append(e.target)
    raise AssertionError("the steps of a component are strongly connected")
