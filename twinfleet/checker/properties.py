"""Properties named in a scenario, and how each is checked on worlds.

Expressions are in the small, safe language of `runtime.scenario.property_eval` (the
live driver evaluates the same), with every node name bound to that node's
decoded state object, `nodes` bound to a dict name → state and `now` to the
world's logical time (e.g. ``map_server.collisions == 0``). Under a time
limit an evaluation still running when it expires raises
`runtime.scenario.property_eval.Overtime`, which the search reports as its stop. Kinds (`runtime.scenario.spec.PROPERTY_KINDS`):

- `invariant`: `expr` holds in every reachable world.
- `no_failure`: no handler calls `ctx.fail` or raises. Always checked; naming
  it only gives the check a name.
- `deadlock`: no reachable world has no pending event while the goal `expr`
  is false. Without `expr` no goal can be met, so every world with nothing
  pending is a deadlock (the same check as `quiescence`, under this name).
- `quiescence`: no reachable world has no pending event at all (what RMC calls
  deadlock, R11).
- `eventually`: on every path `expr` holds at some point; violated by a lasso
  (a reachable cycle) or a path to a world with nothing pending, on which
  `expr` never holds. Checked by `checker.paths.find_lasso`. No fairness is
  assumed by default, but the time rule (semantics Rule 1) already prevents
  starvation across time; with `check.fairness: weak` (`--fairness weak`) a
  cycle counts only if every message dropped on it is also handled on it
  (`checker.fairness`).
- `within`: on every path `expr` holds at some world whose time is at most
  `within_ms`. Each world carries the names of the `within` properties not yet
  met on its path (`World.obligations`); it is violated in a world where one is
  still pending and the next event is later than `within_ms` (or none is).

Besides the named properties, a search always reports handler failures, and
the optional checks of `checker.faults` under fixed names: `queue_bound`
(kind "queue overflow", from `check.queue_bound`), `deadline` (kind "deadline
miss", from `check.deadline_ms`) and `determinism` (kind "nondeterminism",
from `check --check-determinism`).

Expressions are evaluated once per combination of the node states they read
(and `now`, if they read it) and the result cached: they must be pure. The
cache starts afresh at 2,048 entries per expression: a breadth-first search
meets the same combinations close together, so (on C1a) that re-evaluates
nothing and keeps the cache from growing with the number of worlds. When no
invariant reads `now`, the tuples of node states on which all of them hold are
kept too (as many, afresh as often): one look-up checks them all in a world.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol, final

from twinfleet.checker.faults import parse_deadlines, parse_queue_bounds
from twinfleet.runtime.contract.kinds import FailureKind
from twinfleet.runtime.scenario.config import Fairness
from twinfleet.runtime.scenario.property_eval import ExpressionError, Overtime, parse_expression
from twinfleet.runtime.scenario.spec import Scenario

if TYPE_CHECKING:
    from twinfleet.checker.transition import Failure
    from twinfleet.checker.world import Event, World

_CACHE_LIMIT = 2_048  # entries per expression cache (see the module docstring)

QUEUE_BOUND = "queue_bound"
QUEUE_OVERFLOW = "queue overflow"


#: The property a failed transition violates, by failure kind (HANDLER: the scenario's
#: `no_failure` property, whatever its name; a choice that the run does not offer is
#: reported like a handler failure).
FAILURE_PROPERTIES: dict[FailureKind, str] = {
    FailureKind.HANDLER: "no_failure",
    FailureKind.CHOICE_MISMATCH: "no_failure",
    FailureKind.STATE_OUTSIDE: "debug_state",
    FailureKind.DEADLINE: "deadline",
    FailureKind.NONDETERMINISM: "determinism",
    FailureKind.CONTRACT: "node_contract",
}


class PropertyError(ValueError):
    """A property expression could not be evaluated (a name error, a type error...)."""


class States(Protocol):
    """What expressions read node states through (a `checker.system.System`)."""

    names: tuple[str, ...]

    def decode(self, i: int, data: bytes) -> Any:
        """The state object of node `i` encoded as `data` (read-only)."""
        ...


@final
class Expr:
    """A compiled property expression over node states."""

    __slots__ = ("_cache", "expression", "needed", "reads", "source", "uses_all", "uses_now",
                 "where")

    def __init__(self, source: str, names: Sequence[str], where: str) -> None:
        self.source = source
        self.where = where
        try:  # checked against the safe language (runtime.scenario.property_eval)
            self.expression = parse_expression(source, names, where)
        except ExpressionError as exc:
            raise PropertyError(f"{where}: {exc}") from None
        used = self.expression.names
        self.uses_all = "nodes" in used
        self.uses_now = "now" in used
        self.needed = tuple((i, n) for i, n in enumerate(names) if n in used)
        #: indices of the nodes whose state the expression reads
        self.reads = tuple(range(len(names))) if self.uses_all else tuple(i for i, _ in self.needed)
        self._cache: dict[tuple[Any, ...], bool] = {}

    def holds(self, system: States, states: Sequence[bytes], now: int) -> bool:
        """Evaluate on node states (snapshot bytes, in scenario order) at time `now`."""
        key: tuple[Any, ...] = tuple([states[i] for i in self.reads])
        if self.uses_now:
            key = (*key, now)
        cache = self._cache
        found = cache.get(key)
        if found is None:
            if len(cache) >= _CACHE_LIMIT:
                cache.clear()
            found = cache[key] = self._evaluate(system, states, now)
        return found

    def _evaluate(self, system: States, states: Sequence[bytes], now: int) -> bool:
        env: dict[str, Any] = {"now": now}
        for i, name in self.needed:
            env[name] = system.decode(i, states[i])
        if self.uses_all:
            env["nodes"] = {n: system.decode(i, states[i]) for i, n in enumerate(system.names)}
        try:
            return self.expression.evaluate(env)
        except Overtime:
            raise
        except Exception as exc:
            raise PropertyError(f"{self.where}: {self.source!r} raised "
                                f"{type(exc).__name__}: {exc}") from None


@final
@dataclass(frozen=True, slots=True)
class Property:
    """One property to check."""

    name: str
    kind: str
    expr: Expr | None = None
    within_ms: int | None = None
    fairness: Fairness = Fairness.NONE  # what an `eventually` counterexample may assume

    def describe(self) -> str:
        """A one-line description: name, kind, expression (and fairness, if assumed)."""
        text = f"{self.name} ({self.kind}"
        if self.expr is not None:
            text += f": {self.expr.source}"
        if self.within_ms is not None:
            text += f" within {self.within_ms} ms"
        if self.kind == "eventually":
            text += f", fairness {self.fairness}"
        return text + ")"


@final
@dataclass(frozen=True, slots=True)
class PropertyViolation:
    """A property found violated; `shape` says what kind of trace shows it."""

    property: str
    kind: str
    message: str
    shape: str = "path"  # "path", "terminal" or "lasso"
    failure: Failure | None = None


@final
class PropertySet:
    """The properties of a scenario, compiled against its node names."""

    def __init__(self, properties: Sequence[Property], *,
                 queue_bounds: Sequence[int | None] = (), node_names: Sequence[str] = (),
                 deadlines: str = "") -> None:
        self.all = tuple(properties)
        self.queue_bounds = tuple(queue_bounds) if any(b is not None for b in queue_bounds) else ()
        self.node_names = tuple(node_names)
        self.deadlines = deadlines
        self._failure_name = next((p.name for p in self.all if p.kind == "no_failure"),
                                  "no_failure")
        self.invariants = [p for p in self.all if p.kind == "invariant"]
        self.terminal = [p for p in self.all if p.kind in ("deadlock", "quiescence")]
        self.eventually = [p for p in self.all if p.kind == "eventually"]
        self.within = [p for p in self.all if p.kind == "within"]
        self._within_by_name = {p.name: p for p in self.within}
        # Tuples of node states every invariant holds on, when none reads `now`: a search
        # meets the same node states in many worlds (c1a_rebeca: 996 tuples in 18,527
        # worlds), and one look-up answers for all the invariants.
        self._holding: set[tuple[bytes, ...]] | None = (
            None if any(p.expr is None or p.expr.uses_now for p in self.invariants) else set())

    @classmethod
    def from_scenario(cls, scenario: Scenario) -> PropertySet:
        """Compile the scenario's `properties:` list."""
        names = [n.name for n in scenario.nodes]
        props = []
        for i, cfg in enumerate(scenario.properties):
            where = f"{scenario.path}:properties[{i}] ({cfg.name})"
            expr = Expr(cfg.expr, names, where) if cfg.expr is not None else None
            props.append(Property(cfg.name, cfg.kind, expr, cfg.within_ms,
                                  scenario.check.fairness))
        default, per = parse_deadlines(scenario, None)
        deadlines = ", ".join([*([f"{default} ms"] if default is not None else []),
                               *(f"{k} {v} ms" for k, v in sorted(per.items()))])
        return cls(props, queue_bounds=parse_queue_bounds(scenario), node_names=names,
                   deadlines=deadlines)

    def eventually_named(self, name: str) -> Property:
        """The `eventually` property called `name`."""
        return next(p for p in self.eventually if p.name == name)

    def names(self) -> list[str]:
        """Every property checked, including the implicit handler-failure check."""
        named = [p.describe() for p in self.all]
        if self.queue_bounds:
            bounds = ", ".join(f"{n} {b}" for n, b in zip(self.node_names, self.queue_bounds,
                                                           strict=True) if b is not None)
            named.append(f"{QUEUE_BOUND} ({QUEUE_OVERFLOW}: at most {bounds} pending events)")
        if self.deadlines:
            named.append(f"deadline (deadline miss: messages handled within {self.deadlines})")
        if not any(p.kind == "no_failure" for p in self.all):
            named.append("no_failure (implicit: ctx.fail and handler exceptions)")
        return named

    def update(self, system: States, parent: World | None, now: int,
               states: tuple[bytes, ...], events: tuple[Event, ...]) -> tuple[str, ...]:
        """The `within` obligations still pending in a new world (those whose expr is still false)."""
        pending = parent.obligations if parent is not None else tuple(p.name for p in self.within)
        if not pending:
            return ()
        keep = []
        for name in pending:
            prop = self._within_by_name[name]
            assert prop.expr is not None
            if not prop.expr.holds(system, states, now):
                keep.append(name)
        return tuple(keep)

    def check_world(self, system: States, world: World) -> PropertyViolation | None:
        """The first safety property violated in `world`, or None."""
        if self.queue_bounds:
            violation = self._check_queues(world)
            if violation is not None:
                return violation
        holding = self._holding
        if holding is None or world.states not in holding:
            violation = self._check_invariants(system, world)
            if violation is not None:
                return violation
            if holding is not None:
                if len(holding) >= _CACHE_LIMIT:
                    holding.clear()
                holding.add(world.states)
        for name in world.obligations:
            prop = self._within_by_name[name]
            nxt = world.next_time
            if nxt is None or prop.within_ms is None or nxt > prop.within_ms:
                return PropertyViolation(prop.name, prop.kind,
                                 f"{prop.expr.source if prop.expr else ''!r} did not hold within "
                                 f"{prop.within_ms} ms (false at t={world.now} ms, next event "
                                 f"{'never' if nxt is None else f'at {nxt} ms'})")
        if world.terminal:
            return self._check_terminal(system, world)
        return None

    def _check_invariants(self, system: States, world: World) -> PropertyViolation | None:
        for prop in self.invariants:
            assert prop.expr is not None
            if not prop.expr.holds(system, world.states, world.now):
                return PropertyViolation(prop.name, prop.kind,
                                 f"invariant {prop.expr.source!r} is false at t={world.now} ms")
        return None

    def _check_queues(self, world: World) -> PropertyViolation | None:
        counts = [0] * len(self.queue_bounds)
        for ev in world.events:
            counts[ev.target] += 1
        for i, (n, bound) in enumerate(zip(counts, self.queue_bounds, strict=True)):
            if bound is not None and n > bound:
                return PropertyViolation(QUEUE_BOUND, QUEUE_OVERFLOW,
                                 f"queue overflow: {self.node_names[i]} has {n} pending events "
                                 f"at t={world.now} ms (bound {bound})")
        return None

    def _check_terminal(self, system: States, world: World) -> PropertyViolation | None:
        for prop in self.terminal:
            if prop.kind == "quiescence":
                return PropertyViolation(prop.name, prop.kind,
                                 f"quiescent: no event pending at t={world.now} ms", "terminal")
            if prop.expr is None or not prop.expr.holds(system, world.states, world.now):
                goal = f" while {prop.expr.source!r} is false" if prop.expr else ""
                return PropertyViolation(prop.name, prop.kind,
                                 f"deadlock: no event pending at t={world.now} ms{goal}",
                                 "terminal")
        return None

    def check_failure(self, failure: Failure) -> PropertyViolation:
        """The violation a failed transition stands for (`FAILURE_PROPERTIES`)."""
        name = FAILURE_PROPERTIES[failure.kind]
        if name == "no_failure":
            name = self._failure_name
        return PropertyViolation(name, failure.kind, str(failure), "path", failure)

    def reads(self) -> tuple[frozenset[int], bool]:
        """(indices of the nodes whose state some property expression reads, whether some
        reads `now`): what a step must change to be visible to the properties."""
        exprs = [p.expr for p in self.all if p.expr is not None]
        nodes = frozenset(i for e in exprs for i in e.reads)
        return nodes, any(e.uses_now for e in exprs)
