"""Same-node commutation: one event of a node whose handler is declared `commutes=True`.

A persistent set normally takes a node with all its enabled events (two
events of one node are dependent: each may read what the other writes). A
handler declared ``@subscribe(..., commutes=True)`` (or ``@service``) says
that messages it receives at one instant, from different senders, leave the
node in the same state and send the same messages whichever is handled first
(the map server storing r3's pose, then r7's). A node whose enabled events
are all such messages to one such handler is *loose*: the persistent set may
take just one of them, its *representative* e, and leave the others (E') to
later worlds of the same instant, so an instant where N robots report
together costs N worlds instead of 2^N.

What the closure must then also hold (`checker.closure`, which calls here):

- E' runs on paths that avoid the persistent set, so E''s handler is a
  *sender that may run*: what it creates at t, directly or through other
  nodes, must not disturb a node of the set (C-in), and it creates nothing at
  its own node at a priority <= the representative's (that would disable e or
  bring an event nobody checked). New messages at the loose node's priority
  from others are never "harmless" for it (`Closure._incoming`).
- No KEEP_LAST drop of the handler's queue may become possible at t (Rule 6):
  the deliveries waiting fit its depth.
- e commutes with every event of E' *in the worlds where both may run*. That
  is the declaration; it cannot be derived from one world (docs/reduction.md
  §4 has a counterexample). The checker *checks* every pair it relies on in
  the world where it relies on it (`commute`): both orders run, to the same
  set of worlds, with no failure, each event still enabled after the other,
  and e invisible to the properties after the other as well as before. A pair
  that fails expands the node fully in that world (counted in the summary).
  Along the instant the representatives form a chain, so every pair of the
  instant's messages is checked once, in both orders.

What stays an assumption: that a pair which commutes where it is checked also
commutes after further messages of the instant were handled (three events x,
y, z where only "x handled last" differs pass every pairwise check). A
handler whose effect is a sum of pairwise terms over the senders' slots (the
map server: store the sender's pose, test it against each other robot) meets
it: a pair's outcome reads only the two senders' own slots, which no other
message of the instant writes. The summary names every declared handler the
search relied on.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from twinfleet.checker.transition import RunEvent
from twinfleet.runtime.contract.kinds import EventKind

if TYPE_CHECKING:
    from twinfleet.checker.system import System
    from twinfleet.checker.visibility import Visibility
    from twinfleet.checker.world import Event, World

_MESSAGES = (EventKind.DELIVERY, EventKind.REQUEST)


def loose_nodes(system: System, world: World, by_node: dict[int, list[int]]
                ) -> dict[int, int]:
    """Per loose node of `world` (module docstring), the index of its representative: the
    first of its >= 2 enabled events, all messages to one handler declared commuting whose
    waiting deliveries fit the handler's KEEP_LAST depth."""
    events = world.events
    commuting = system.topology.commuting
    out: dict[int, int] = {}
    dropping: set[tuple[int, str]] | None = None  # handlers Rule 6 may drop from, asked once
    for x, idxs in by_node.items():
        if len(idxs) < 2:
            continue
        first = events[idxs[0]]
        handler = (x, first.method)
        if handler not in commuting or any(
                events[i].kind not in _MESSAGES or events[i].method != first.method
                for i in idxs):
            continue
        if dropping is None:
            dropping = {(events[i].target, events[i].method)
                        for i in system.rules.droppable(events)}
        if handler in dropping:
            continue
        out[x] = idxs[0]
    return out


def commute(system: System, visibility: Visibility, world: World, e: int, j: int,
            acyclic: Callable[[], bool] | None = None) -> bool:
    """True if events `e` and `j` of one node, both enabled in `world`, commute there: both
    orders reach the same worlds with no failure, and `e` changes no property atom after `j`
    (it was checked before `j` by the closure's visibility proviso; `acyclic` as there)."""
    ends = []
    for first, second in ((e, j), (j, e)):
        reached = set()
        for tr in system.outcomes(world, RunEvent(first)):
            if tr.failure is not None:
                return False
            after = tr.world
            k = _find(after, world.events[second])
            if k is None or k not in system.rules.enabled(after.events):
                return False
            if second == e and visibility.changed(system, after, k, acyclic):
                return False
            for tr2 in system.outcomes(after, RunEvent(k)):
                if tr2.failure is not None:
                    return False
                reached.add(tr2.world.key)
        ends.append(reached)
    return ends[0] == ends[1]


def _find(world: World, ev: Event) -> int | None:
    """The index of pending event `ev` in `world` (it, or an equal one: `Event.__eq__`
    compares the canonical sort key, which holds the target)."""
    try:
        return world.events.index(ev)
    except ValueError:
        return None
