"""Partial-order reduction: expand a world by a persistent set of its enabled events.

Theory of operation (the design and its sources: docs/reduction.md)
===================================================================

From a world s at time t a reduced search takes the transitions of a set T
of enabled events instead of all of them. T is *persistent* if every path
from s that avoids T only takes transitions independent of every event in T;
then every terminal world, every failing transition and (with the provisos
below) every property verdict of the full graph is also found in the
reduced one. Two facts of the checker's own rules make this simple:

1. Rule 1 (time): while an event of T is pending, time cannot pass, so a
   T-avoiding path stays at instant t. Persistence is a question about one
   instant; events created with a delay play no part in it.
2. The node contract: a handler's outcome depends only on (its node's state,
   the event, the time). Events of different nodes touch disjoint states;
   their new events go into per-(sender, receiver) channels whose ranks and
   FIFO clamping (`Rules.add`, `Rules.remove`) act within one channel.

So T is node-granular: all enabled events of a set N of nodes, every variant
of each (`ctx.choose`, latency, drop and duplicate branches are one unit).
N is grown from a seed node until closed under (`_Closure`):

- C-in: no node outside N that may still run at t can create, at t, an event
  at a node X of N with a priority below X's enabled priority p_X (it would
  disable X's events, Rule 2), or equal to it on a channel that has no event
  of that priority pending at t (it would be a new enabled event of X, under
  `rebeca` always). Then nodes of N run nothing but T in a T-avoiding path.
  Who may create what at whom is the learned relation of
  `checker.publications` (restarts keep it honest); who "may still run at t"
  is every node with an event due at t and every node such events may reach
  at zero delay through nodes outside N.
- C-out: an event of T that creates, at t, an event of priority q at a node
  B outside N adds B if B may run at t an event of priority > q (it would be
  disabled there), from its pending events or from what may reach it.
- C2 (visibility, `checker.visibility`): if T is not everything enabled, no
  variant in T may change an atom of an invariant, `within` or `eventually`
  expression.
- C3t (zero-time cycles): if some successor by T stays at instant t and is
  already stored, the world is expanded fully. Every cycle of the reduced
  graph that does not let time pass then holds a fully expanded world; a
  cycle that lets time pass runs every event pending at its worlds (Rule 1).

Worlds where a crash may be injected, where an event of a kind the reduction
does not know is due, or where no seed closes to less than everything are
expanded fully. Settings the reduction does not cover turn it off for the
run (`why_off`), and the checker says so.
"""

from __future__ import annotations

import dataclasses
import random
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final, final

from twinfleet.checker.closure import Closure, remember, shape
from twinfleet.checker.commuting import loose_nodes
from twinfleet.checker.faults import CheckSettings
from twinfleet.checker.options import NONE, POR, REDUCTIONS, Semantics
from twinfleet.checker.semantics import Rules
from twinfleet.checker.transition import Action, Drop, RunEvent, Transition, Variant
from twinfleet.checker.visibility import Visibility

if TYPE_CHECKING:
    from twinfleet.checker.properties import PropertySet
    from twinfleet.checker.system import System
    from twinfleet.checker.world import World

_INF: Final = 1 << 62  # larger than any state id
_UNKNOWN: Final = object()  # no persistent set known for a shape yet (`_choose`)
# A BFS walks ahead once (`Reduction.probe`) when a level starts with PROBE_STATES worlds
# stored, taking at most one step per PROBE_SHARE worlds stored: a step runs handlers the
# search mostly finds in its cache, about six times the cost of a stored world (C1a), so
# the walks cost about the search so far; a smaller search, which a restart costs little,
# never walks.
PROBE_STATES: Final = 50_000
PROBE_SHARE: Final = 8
PROBE_WALKS: Final = 2
PROBE_SEED: Final = 1
WALK_ON_STEPS: Final = 512  # fewest steps walked on at a restart (`Reduction.walk_on`)
# The reduction steps aside (`Reduction.steps_aside`) when, after at least ASIDE_WORLDS
# expanded worlds, fewer than ASIDE_SHARE of them were reduced (every shipped case judged
# at 300 worlds keeps its reduction; at 1,000 the small two-phase commit lost a third of
# its search before stepping aside): its bookkeeping costs a
# quarter to a third of an unreduced world (benchmarks/reduction_overhead.py), and a graph
# where so few worlds are reduced is hardly smaller than the full one (a two-phase commit
# with 0-2 ms of latency: 6 % reduced, 0.5 % fewer states, twice the time). The paper's
# cases reduce 60-75 % of their worlds from the first levels on.
ASIDE_WORLDS: Final = 300
ASIDE_SHARE: Final = 0.2
# With none of them reduced it steps aside from ASIDE_NONE_WORLDS expanded worlds on: every
# shipped case reduces some of its first 100, and such a pass is the unreduced search's so
# far, which then goes on in place (`Search`), so its earlier worlds cost only their
# bookkeeping (the small two-phase commit: 400 worlds of it, 5-8 % of its time).
ASIDE_NONE_WORLDS: Final = 100
# Handler outcomes a reduced search keeps per cache generation (`System.widen_cache`): its
# restarts run the handlers of the first levels again (C1a: 1.53 -> 1.22 s of CPU with the
# outcomes kept across restarts; ~4.5 MB).
RESTART_CACHE: Final = 4_096

# A world's persistent set is looked up by its shape (`closure.shape`) once the run has
# computed SHAPES_AFTER closures: a shape reads the sends of every enabled event (a closure
# only those of the nodes it adds), and pays once shapes recur, which they do in all but
# the smallest searches (station: 16 shapes in 16 closures; head-on: 55 in 242; C1a: 172
# in 7,436). From the start, the station cost 5 % more; from 16 or 64, head-on's check
# took 1.07-1.13 or 1.14-1.16 times the unreduced one (two runs each, a loaded machine).
SHAPES_AFTER: Final = 16

# The fields of the settings the closure's rules were written for: a new rule (a field
# set to anything but its default) turns the reduction off until it is covered here.
_KNOWN_SETTINGS: Final = frozenset({"latency", "topic_latency", "deadline_default",
                                    "deadlines", "queue_bounds", "drop", "duplicate", "crash"})
_KNOWN_RULES: Final = frozenset({"semantics", "node_priorities", "global_priority",
                                 "settings", "depths", "lossy", "fifo", "has_latency",
                                 "_ranges", "_shallowest", "_one_node"})
# The code of the enabling and effect rules the closure was argued for is pinned by
# tests/checker/test_reduction_rules.py: a change there fails that test until the closure
# has been reviewed for it (docs/reduction.md §5).


def default_reduction(semantics: Semantics | str) -> str:
    """`por` under `ros`; `none` under `rebeca` (its counts are compared with RMC's)."""
    return POR if Semantics(semantics) is Semantics.ROS else NONE


def why_off(rules: Rules, properties: PropertySet, strategy: str) -> str | None:
    """Why the reduction cannot run on this system and these properties, or None."""
    if strategy == "random":
        return "random walks pick among all actions"
    if properties.queue_bounds:
        return "check.queue_bound reads the pending counts"
    if properties.reads()[1]:
        return "a property reads now"
    if rules.semantics is Semantics.REBECA and (
            rules.global_priority or len(set(rules.node_priorities)) > 1):
        return "node-instance priorities under rebeca (Rule 4)"
    return _unknown_rule(rules)


def _unknown_rule(rules: Rules) -> str | None:
    for f in dataclasses.fields(rules):
        if f.name not in _KNOWN_RULES:
            return f"rule {f.name} is not covered"
    for f in dataclasses.fields(CheckSettings):
        if f.name in _KNOWN_SETTINGS:
            continue
        value = getattr(rules.settings, f.name)
        default = f.default if f.default is not dataclasses.MISSING else (
            f.default_factory() if f.default_factory is not dataclasses.MISSING else None)
        if value != default:
            return f"check setting {f.name} is not covered"
    return None


@final
@dataclass
class ReductionStatistics:
    """What the reduction did in one search."""

    reduced: int = 0  # worlds expanded by a proper subset of their enabled events
    full: int = 0  # worlds expanded fully (one enabled event counts here too)
    cycle_proviso: int = 0  # of those, expanded fully by C3t
    restarts: int = 0  # searches started again after the send relation grew
    edges: int = 0  # (sender, target, priority) triples learned
    commuted: int = 0  # worlds where a node declared commuting gave one of its events
    pairs: int = 0  # pairs of such events checked in both orders
    refuted: int = 0  # of those, pairs that did not commute (the node then gave all)
    rises: int = 0  # events not visible only because they make a rising goal's atoms rise
    probes: int = 0  # walks taken ahead of the search (`probe`, `walk_on`), kept by restarts
    probe_steps: int = 0  # their steps
    ahead: int = 0  # 1 once the search walked ahead at `PROBE_STATES` worlds (`probe`)
    aside: int = 0  # worlds expanded when the reduction stepped aside (0: it did not)
    prefix: int = 0  # worlds stored unreduced before the reduction started (`late_start`)

    def to_json(self) -> dict[str, int]:
        """The counters as a JSON-ready mapping (all ints: no deep copy)."""
        return dict(vars(self))


@final
class Reduction:
    """Persistent-set expansion of worlds for one `System` and `PropertySet`."""

    def __init__(self, system: System, properties: PropertySet,
                 visibility: Visibility | None = None, reduce_from: int = 0) -> None:
        self.system, self.properties, self.rules = system, properties, system.rules
        #: worlds searched unreduced first (`checker.late_start`); waiting: not there yet
        self.reduce_from, self.waiting = reduce_from, reduce_from > 0
        self._visibility, self._frozen = visibility, False  # (`visibility`)
        self.publications = system.publications
        self.stats = ReductionStatistics()
        self._version = self.publications.version
        self._rising = None if visibility is None else visibility.rising
        # (node, priority) of every KEEP_LAST subscription: once, not per world (`Closure`)
        self._queued = frozenset((n, system.topology.priority(n, m)) for n, m in self.rules.depths)
        self._commuting = bool(system.topology.commuting)
        self.relied: set[str] = set()  # "node.handler" declared commuting, relied on
        system.widen_cache(RESTART_CACHE)
        self._closures = 0  # closures computed, walks and restarts included (`_choose`)
        #: why the reduction stepped aside for the rest of the run (`steps_aside`), or None
        self.aside: str | None = None

    @property
    def visibility(self) -> Visibility:
        """What the properties read, analysed when first asked (a waiting search never asks)."""
        if self._visibility is None:
            self._visibility = Visibility(self.properties, self.system.names)
            self._visibility.frozen, self._rising = self._frozen, self._visibility.rising
        return self._visibility

    def steps_aside(self) -> bool:
        """True, and from now on `aside` says why, once the search expanded `ASIDE_WORLDS`
        worlds and reduced fewer than `ASIDE_SHARE` of them, or `ASIDE_NONE_WORLDS` and
        reduced none: the search then goes on unreduced (sound as any unreduced search;
        the worlds it had are searched again unless none was reduced)."""
        s = self.stats
        expanded = s.reduced + s.full
        if self.aside is None and s.reduced < ASIDE_SHARE * expanded and \
                expanded >= (ASIDE_WORLDS if s.reduced else ASIDE_NONE_WORLDS):
            s.aside = expanded
            self.aside = (f"por stepped aside: {s.reduced:,} of the first {expanded:,} worlds "
                          f"reduced, under {ASIDE_SHARE:.0%}; the search ran unreduced")
        return self.aside is not None

    def begin(self) -> None:
        """Start (or start again) a search: remember the relation and what it assumes."""
        self._version = self.publications.version
        self._rising = None if self._visibility is None else self._visibility.rising

    def statistics(self) -> dict[str, int]:
        """The counters of the search, with the size of the learned relation."""
        self.stats.edges = self.publications.edges()
        self.stats.rises = 0 if self._visibility is None else self._visibility.rises
        return self.stats.to_json()

    def freeze(self) -> None:
        """Learn level by level (`Publications.freeze`): sends, and a rising goal's fall."""
        self.publications.freeze()
        self._frozen = True
        if self._visibility is not None:
            self._visibility.frozen = True

    def learned_state(self) -> tuple[Any, ...]:
        """What this search learned (relation, rising-goal rule; waiting), for `relearn`."""
        return (self.publications.__getstate__(), self.visibility.rising, self.visibility.fell,
                self.waiting)

    def relearn(self, state: tuple[Any, ...]) -> None:
        """Start again from scratch with what `learned_state` gave, frozen, counters at 0."""
        self.publications.__setstate__(state[0])
        self.visibility.rising, self.visibility.fell = state[1], state[2]
        self.waiting = len(state) > 3 and state[3]
        self.visibility.pending_fall, self.visibility.rises = None, 0
        self.freeze()
        self.stats = ReductionStatistics()
        self.begin()

    def learned(self) -> None:
        """Add what the search learned while frozen to the relation, and go on from it: no
        world of the pass was reduced, so none relied on the relation (`Search`)."""
        self.publications.commit()
        if self._visibility is not None:
            self._visibility.commit()
        self.begin()

    def restarted(self) -> None:
        """Count a restart, and add what the search learned while frozen to the relation;
        the other counters start again with the search."""
        self.publications.commit()
        self.visibility.commit()
        s = self.stats
        self.stats = ReductionStatistics(restarts=s.restarts + 1, probes=s.probes,
                                         probe_steps=s.probe_steps, ahead=s.ahead,
                                         prefix=s.prefix)
        self.visibility.rises = 0

    def probe(self, stored: int, max_depth: int | None) -> bool:
        """Walk the reduced graph ahead of a breadth-first search that has stored `stored`
        worlds when a level starts, once per search and only from `PROBE_STATES` worlds
        on; True if it walked. The walks note what they see sent and which goals fall
        (`Publications.observe`, `Visibility.observe`), so that the search restarts for
        them now, while it is small, not when its levels get there.

        Why: a BFS meets a send first at the depth where it happens, and everything it
        searched before is searched again after the restart; in a wide graph that can be
        most of the work (C1a with 0-1 ms of jitter learned its last send at depth 2,119
        of 5,515, after 5.6 M of its 6 M worlds, though every run takes that send).

        One seeded walk (`_walk`) from each of the first `PROBE_WALKS` initial worlds,
        `stored` / `PROBE_SHARE` steps in all. Each step takes a transition of the
        world's persistent set, as the search would (the cycle proviso only adds
        transitions), so what the walks learn the search could learn; a search that
        probes at the same level of the same graph learns the same, in one process or
        on workers. The walks' own counters are not the search's: they are put back."""
        if self.stats.ahead or stored < PROBE_STATES:
            return False
        self.stats.ahead = 1
        starts = [t.world for t in self.system.initial() if t.failure is None]
        self._walks(starts, stored // PROBE_SHARE, max_depth)
        return True

    def walk_on(self, worlds: list[World], stored: int, max_depth: int | None) -> None:
        """At a restart, walk the reduced graph on from the last of the `worlds` the search
        had left to expand (its deepest), as many steps as it had stored worlds (at least
        `WALK_ON_STEPS`, at most `PROBE_STATES`): the sends deeper levels would make are
        learned now, for this restart, instead of a restart each (head-on: 11 restarts, 5
        of them after its first 100 worlds, each searching those again; now 2, as in
        every shipped case, where C1a had 17 and C2c 18). Sound as `probe`: the walks
        take transitions of persistent sets of reachable worlds, and the relation only
        holds sends that reachable transitions made (and their copies for the senders'
        twins, `Publications.peers`, which only make closures larger)."""
        self._walks(worlds[::-1], min(max(stored, WALK_ON_STEPS), PROBE_STATES), max_depth)

    def _walks(self, starts: list[World], budget: int, max_depth: int | None) -> None:
        """One seeded walk (`_walk`) from each of the first `PROBE_WALKS` of `starts`,
        `budget` steps in all; the walks' own counters are put back, and they are counted
        as walks ahead."""
        rng = random.Random(PROBE_SEED)
        left, walks = budget, 0
        with uncounted(self):
            for start in starts[:PROBE_WALKS]:
                walks += 1
                left -= self._walk(start, rng, left if max_depth is None else min(left, max_depth))
        self.stats.probes += max(walks, 1)
        self.stats.probe_steps += budget - left

    def _walk(self, world: World, rng: random.Random, limit: int) -> int:
        """Steps of one walk from `world` until nothing is pending, a world of the walk
        comes back, a safety property is violated (the search goes no further there
        either) or `limit` steps; returns the steps taken."""
        seen = {world.key}
        for steps in range(limit):
            if not world.events:
                return steps
            moves = self._moves(world)
            self.visibility.observe_moves(self.system, world, moves)
            live = [m for m in moves if m[1].failure is None]
            if not live:
                return steps
            world = self.system.apply(world, *rng.choice(live)).world
            if world.key in seen or self.properties.check_world(self.system, world):
                return steps + 1
            seen.add(world.key)
        return limit

    def _moves(self, world: World) -> list[tuple[Action, Variant]]:
        """The (action, variant) of each transition `candidates` would give, in its order,
        none of them applied: a walk builds only the one it takes (head-on: 195 worlds
        built and hashed for its 167 steps before)."""
        enabled = self.rules.enabled(world.events)
        chosen = None if self.disabled else self._choose(world, enabled)
        if chosen is None:
            actions = self.system.actions(world)
        else:
            nodes = {world.events[i].target for i in chosen}
            actions = [*map(RunEvent, chosen), *(Drop(k) for k in self.rules.droppable(
                world.events) if world.events[k].target in nodes)]
        variants = self.system.variants
        return [(a, v) for a in actions for v in variants(world, a)]

    @property
    def stale(self) -> bool:
        """True when the send relation grew, or a rising goal fell, since `begin` (the
        search must restart)."""
        publications = self.publications
        return publications.version != self._version or bool(publications.pending) or \
            publications.pending_unknown is not None or \
            (v := self._visibility) is not None and (v.pending_fall is not None
                                                     or v.rising != self._rising)

    def must_restart(self) -> bool:
        """True when the relation grew (`stale`) and a world of this pass was reduced with
        the old one; a pass that reduced none learns in place (`learned`)."""
        return self.stale and self.stats.reduced > 0

    @property
    def disabled(self) -> str | None:
        """Why the reduction stopped for the run (an unknown event kind), or None."""
        kind = self.publications.unknown
        return None if kind is None else f"event kind {kind} is not covered"

    def successors(self, world: World, find: Callable[[object], int],
                   done: int | None) -> list[Transition]:
        """The transitions a reduced search takes from `world`. For the cycle proviso,
        `find(key)` is a world's id in the store (-1: none) and `done` the largest id of a
        world at most as deep as `world` (BFS: every such world is stored when a level
        starts, whatever order the level is expanded in), else None (DFS: any stored world
        counts)."""
        out, probes = self.candidates(world)
        if probes is None:
            return out
        limit = done if done is not None else _INF
        if any(0 <= find(key) <= limit for key in probes):
            return self.full(world)
        return self.reduced(world, out)

    def candidates(self, world: World) -> tuple[list[Transition], list[object] | None]:
        """The transitions of a persistent set of `world`'s enabled events and the keys of
        those successors that stay at its instant: if one of them is already stored (at
        most as deep as `world`), C3t asks for `full`, else `reduced`. No set smaller than
        everything: every transition, already counted, and None."""
        enabled = self.rules.enabled(world.events)
        if self.waiting:  # every transition, unobserved: the reduced search after the start
            return list(self.system.successors(world, enabled)), None  # sees its own falls
        chosen = None if self.disabled else self._choose(world, enabled)
        if chosen is None:
            self.stats.full += 1
            return self._observed(world, list(self.system.successors(world, enabled))), None
        out: list[Transition] = []
        for i in chosen:
            out += self.system.outcomes(world, RunEvent(i))
        out += _drops(self.system, world, {world.events[i].target for i in chosen})
        t = world.events[0].due
        return out, [tr.world.key for tr in out if tr.failure is None
                     and tr.world.events and tr.world.events[0].due == t]

    def full(self, world: World) -> list[Transition]:
        """Every transition of `world`: the cycle proviso refused its persistent set."""
        self.stats.full += 1
        self.stats.cycle_proviso += 1
        enabled = self.rules.enabled(world.events)
        return self._observed(world, list(self.system.successors(world, enabled)))

    def reduced(self, world: World, out: list[Transition]) -> list[Transition]:
        """The persistent set's transitions `candidates` gave, taken."""
        self.stats.reduced += 1
        return self._observed(world, out)

    def _observed(self, world: World, transitions: list[Transition]) -> list[Transition]:
        """`transitions`, once checked for falling goal atoms (`Visibility.observe`)."""
        self.visibility.observe(self.system, world, transitions)
        return transitions

    def persistent(self, world: World) -> list[int] | None:
        """`_choose` for `world`, nothing expanded (so called within `uncounted`)."""
        return None if self.disabled else self._choose(world, self.rules.enabled(world.events))

    def _choose(self, world: World, enabled: list[int]) -> list[int] | None:
        """A persistent set of the `enabled` event indices smaller than all, or None."""
        if len(enabled) < 2 or self.rules.crashable(world):
            return None
        events = world.events
        first = events[enabled[0]].target
        for i in enabled:
            if events[i].target != first:
                break
        else:  # one node's events: dependent unless it is loose (`checker.commuting`)
            if not self._commuting or not loose_nodes(self.system, world, {first: enabled}):
                return None
        key = None
        if self._closures >= SHAPES_AFTER:
            key = shape(self.system, self.publications, world, enabled)
        if key is not None:
            known = self.publications.derived.get(key, _UNKNOWN)
            if known is None:
                return None
            if known is not _UNKNOWN:
                chosen = [enabled[k] for k in known]
                if self.visibility.silent(self.system, world, chosen):
                    return chosen
                key = None  # a chosen event is visible here: the closure decides
        self._closures += 1
        best = self._closure(world, enabled)
        if key is not None and self.visibility.silent(self.system, world, enabled):
            where = {i: k for k, i in enumerate(enabled)}
            remember(self.publications.derived, key,
                     None if best is None else tuple(where[i] for i in best))
        return best

    def _closure(self, world: World, enabled: list[int]) -> list[int] | None:
        """`_choose` for a world of events of two or more nodes, or of one loose node."""
        closure = Closure(self.system, self.publications, self.visibility, world, enabled,
                          self._queued)
        if (len(closure.by_node) < 2 and not closure.loose) or closure.unknown:
            return None
        best = closure.smallest()
        _count_commuted(self, world, closure, best)
        return best


@contextmanager
def uncounted(reduction: Reduction) -> Iterator[None]:
    """Closures computed inside count nothing: the reduction's counters, the declared
    handlers it relied on and the rising-goal count are put back (walks ahead, the late
    start's sample: no world of the search was expanded)."""
    counted, relied = dataclasses.replace(reduction.stats), set(reduction.relied)
    rises = reduction.visibility.rises
    try:
        yield
    finally:
        reduction.stats, reduction.relied, reduction.visibility.rises = counted, relied, rises


def _drops(system: System, world: World, nodes: set[int]) -> list[Transition]:
    """The KEEP_LAST drops (Rule 6) of the chosen nodes' waiting deliveries: actions of
    those nodes, so a node-granular set takes them with its events. A drop of another
    node's delivery commutes with every chosen event: it only shortens that node's queue,
    which no other node's enabling reads, and a send into the queue (a chosen event's
    effect) leaves an enabled drop enabled."""
    events = world.events
    return [t for k in system.rules.droppable(events) if events[k].target in nodes
            for t in system.outcomes(world, Drop(k))]


def _count_commuted(reduction: Reduction, world: World, closure: Closure,
                    chosen: list[int] | None) -> None:
    """Count `closure`'s pair checks, and the worlds where `chosen` took one event of a
    loose node (naming in `reduction.relied` the declared handlers relied on)."""
    if not closure.pairs:
        return  # no loose node gave one event without its pairs checked
    stats = reduction.stats
    stats.pairs += closure.pairs
    stats.refuted += closure.refuted
    taken = set(chosen or ())
    for x, e in closure.loose.items():
        if e in taken and not taken.issuperset(closure.by_node[x]):
            stats.commuted += 1
            reduction.relied.add(f"{reduction.system.names[x]}.{world.events[e].method}")


def plan(system: System, properties: PropertySet, strategy: str,
         requested: str | None, reduce_from: int = 0) -> tuple[Reduction | None, str]:
    """The reduction a search runs, and its name for summaries: "por", "none", or
    "none (why)" when the default or the request cannot be followed. It starts once the
    search stored `reduce_from` worlds (`checker.late_start`)."""
    asked = requested or default_reduction(system.semantics)
    if asked not in REDUCTIONS:
        raise ValueError(f"unknown reduction {asked!r}; expected {' or '.join(REDUCTIONS)}")
    if asked == NONE:
        return None, NONE if requested else f"none (default under {system.semantics})"
    why = why_off(system.rules, properties, strategy)
    if why is not None:
        return None, f"none ({why})"
    return Reduction(system, properties, reduce_from=reduce_from), POR


def describe(reduction: Reduction | None, name: str, strategy: str = "bfs") -> str:
    """One line for the summary: what ran, and what it did."""
    if reduction is None:
        return name
    if reduction.aside:
        return f"none ({reduction.aside})"
    if reduction.disabled:
        return f"none ({reduction.disabled}; turned off during the search)"
    if reduction.waiting:
        return (f"none (por starts once a search stored {reduction.reduce_from:,} worlds: a "
                "smaller one costs more to reduce than to search; this one stored fewer)")
    s = reduction.stats
    restarts = f", {s.restarts} restart{'s' * (s.restarts != 1)}" if s.restarts else ""
    if s.prefix:
        restarts += f"; started after {s.prefix:,} worlds searched unreduced"
    if reduction.visibility.fell:
        restarts += f"; goals not rising: {reduction.visibility.fell}"
    if s.probes:
        restarts += f"; learned ahead by {s.probes} walk{'s' * (s.probes != 1)} of " \
            f"{s.probe_steps:,} steps"
    return (f"por (persistent sets: {s.reduced:,} worlds reduced, {s.full:,} expanded fully, "
            f"{s.cycle_proviso:,} by the cycle proviso; {reduction.publications.edges()} sends "
            f"learned{restarts}{_commuted(reduction)}"
            + ("; a BFS trace is shortest in the reduced graph)" if strategy == "bfs" else ")"))


def _commuted(reduction: Reduction) -> str:
    """The summary's words on declared same-node commutation, if the search relied on it."""
    s = reduction.stats
    if not s.commuted and not s.pairs:
        return ""
    relied = ", ".join(sorted(reduction.relied)) or "none"
    return (f"; one order of messages declared commutes=True in {s.commuted:,} worlds "
            f"({relied}), {s.pairs:,} pairs checked in both orders, {s.refuted:,} did not "
            "commute")
