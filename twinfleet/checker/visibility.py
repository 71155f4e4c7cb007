"""Which transitions a property can see (the visibility proviso of `checker.reduction`).

A reduced search may postpone the other enabled events only if no property
expression can change its value through an event it takes first (T, the
persistent set, of the nodes N). Expressions are split into *atoms* along
``and``/``or``/``not``; an atom that reads one node's state only is decided
exactly: an event of node A changes it iff the atom differs on A's state
before and after (A's state cannot change while the event waits: A is frozen
in N, so "before" is the same in every world where it might run instead). An
atom that reads several nodes (or ``nodes``) makes every state change of
those nodes visible. If no atom changes, no boolean combination of them can.

Guards. An event that does change an atom of ``c1 and c2 and ...`` is still
invisible if some conjunct is false at the world, reads only nodes of N and
is not changed by the event: no world where the event may run (N frozen)
can make the conjunction true (dually a true disjunct of an ``or``). So the
reduction may add a guard's nodes to N (`Visibility.needs`): at an instant
where robots arrive, two arrivals guard each other.

Evaluating the whole expression before and after would not be sound: with
``r2.done and not r1.done`` an r1 step that keeps it false here may make it
true in a world where r2 arrived first.

Rising goals. An `eventually` expression that is a conjunction of one-node
atoms (``r1.done and r2.done``) is *rising* while no transition has made one
of its atoms fall (true to false). Then an event that only makes its atoms
rise is not visible to it, provided no zero-time cycle can run beside the set
(`Closure.acyclic`). Why: a run that never reaches the goal must take the
postponed event e (time cannot pass before it, and no zero-time cycle can
postpone it for ever); moved to the front, e's rise is there earlier, and if
the goal held at some world of the moved run, it would hold at the world of
the original run right after e, since atoms that rose stay up. So the moved
run avoids the goal too, and the reduced graph keeps every counterexample.
Robots arriving at one instant (each arrival a rise of `all_arrive`) then
cost one world each instead of every subset of arrivals. Whether atoms fall
is checked on every transition the search takes (`observe`); the first fall
turns the relaxation off and the search restarts, as for the learned send
relation (`checker.publications`: a reduced search that never met a falling
transition has none among the reachable ones, by the same first-violation
argument, since a fall depends only on its node's state and event).
"""

from __future__ import annotations

import ast
import builtins
from collections.abc import Callable, Iterable, Sequence
from typing import TYPE_CHECKING, Any, final

from twinfleet.checker.transition import Crash, Drop, RunEvent

if TYPE_CHECKING:
    from types import CodeType

    from twinfleet.checker.properties import PropertySet
    from twinfleet.checker.system import System
    from twinfleet.checker.transition import Action, Transition, Variant
    from twinfleet.checker.world import World

_CACHE_LIMIT = 4_096  # values kept per part (by the node states it reads)


@final
class Part:
    """A subexpression over a fixed set of nodes, evaluated on their states (cached)."""

    __slots__ = ("_cache", "_tree", "code", "names", "reads")

    def __init__(self, tree: ast.expr, index: dict[str, int]) -> None:
        used = sorted({n.id for n in ast.walk(tree) if isinstance(n, ast.Name)})
        self.names = tuple(n for n in used if n in index)
        self.reads = tuple(index[n] for n in self.names)
        # compiled when first evaluated: in a small check many parts never are
        self._tree: ast.expr | None = tree
        self.code: CodeType | None = None
        self._cache: dict[tuple[bytes, ...], Any] = {}

    def value(self, system: System, states: Sequence[bytes]) -> Any:
        """The part on node states (in scenario order); an exception is its own value."""
        key = tuple(states[i] for i in self.reads)
        found = self._cache.get(key)
        if found is None:
            env: dict[str, Any] = {"__builtins__": builtins}
            for i, name in zip(self.reads, self.names, strict=True):
                env[name] = system.decode(i, states[i])
            if self.code is None:
                assert self._tree is not None
                self.code = compile(ast.Expression(self._tree), "<property part>", "eval")
                self._tree = None
            try:
                found = bool(eval(self.code, env))
            except Exception as exc:  # the search reports it where it evaluates the property
                found = type(exc).__name__
            if len(self._cache) >= _CACHE_LIMIT:
                self._cache.clear()
            self._cache[key] = found
        return found

    def changed(self, system: System, states: Sequence[bytes], node: int,
                afters: Sequence[bytes]) -> bool:
        """True if replacing `node`'s state by one of `afters` changes the part."""
        if node not in self.reads:
            return False
        before = self.value(system, states)
        for after in afters:
            if self.value(system, (*states[:node], after, *states[node + 1:])) != before:
                return True
        return False


def _leaves(tree: ast.expr) -> Iterable[ast.expr]:
    """The non-boolean subexpressions of `tree` joined by and/or/not."""
    if isinstance(tree, ast.BoolOp):
        for value in tree.values:
            yield from _leaves(value)
    elif isinstance(tree, ast.UnaryOp) and isinstance(tree.op, ast.Not):
        yield from _leaves(tree.operand)
    else:
        yield tree


@final
class Expression:
    """One property expression: its atoms by node, and its top-level guards."""

    def __init__(self, source: str, index: dict[str, int], goal: bool = False) -> None:
        tree = ast.parse(source.strip(), mode="eval").body
        self.source = source
        self.uses_now = False
        self.atoms: dict[int, list[Part]] = {}
        self.whole: set[int] = set()
        for leaf in _leaves(tree):
            used = {n.id for n in ast.walk(leaf) if isinstance(n, ast.Name)}
            self.uses_now |= "now" in used
            part = Part(leaf, index)
            if "nodes" in used:
                self.whole.update(index.values())
            elif len(part.reads) == 1:
                self.atoms.setdefault(part.reads[0], []).append(part)
            else:
                self.whole.update(part.reads)
        #: an `eventually` conjunction of one-node atoms (module docstring: rising goals)
        conjuncts = tree.values if isinstance(tree, ast.BoolOp) and isinstance(
            tree.op, ast.And) else [tree]
        self.rising = goal and not self.whole and not any(
            isinstance(c, ast.BoolOp) or isinstance(c, ast.UnaryOp) and isinstance(
                c.op, ast.Not) for c in conjuncts)
        #: for `and`, the conjuncts (a false one guards); for `or`, the disjuncts
        self.guard_value = isinstance(tree, ast.BoolOp) and isinstance(tree.op, ast.Or)
        self.guards = ([Part(v, index) for v in tree.values] if isinstance(tree, ast.BoolOp)
                       and "nodes" not in {n.id for n in ast.walk(tree)
                                           if isinstance(n, ast.Name)} else [])

    def reads(self, node: int) -> bool:
        """True if the expression reads `node`'s state."""
        return node in self.whole or node in self.atoms

    def changes(self, system: System, states: Sequence[bytes], node: int,
                afters: Sequence[bytes], rises: bool = False) -> bool:
        """True if some atom over `node` changes (any change if a multi-node atom reads it);
        with `rises`, a change from false to true does not count."""
        if node in self.whole:
            return True
        if rises:
            return any(self._falls_or_varies(system, states, node, afters))
        return any(a.changed(system, states, node, afters) for a in self.atoms.get(node, ()))

    def _falls_or_varies(self, system: System, states: Sequence[bytes], node: int,
                         afters: Sequence[bytes]) -> Iterable[bool]:
        for a in self.atoms.get(node, ()):
            before = a.value(system, states)
            for after in afters:
                value = a.value(system, (*states[:node], after, *states[node + 1:]))
                yield value != before and not (before is False and value is True)

    def falls(self, system: System, before: Sequence[bytes], after: Sequence[bytes],
              node: int) -> bool:
        """True if an atom over `node` is true in `before` and not in `after`."""
        return any(a.value(system, before) is True and a.value(system, after) is not True
                   for a in self.atoms.get(node, ()))

    def guard(self, system: System, states: Sequence[bytes], node: int,
              afters: Sequence[bytes], frozen: set[int]) -> set[int] | None:
        """None if a guard over `frozen` nodes holds the expression; else the nodes of the
        smallest guard that would (empty: none)."""
        best: set[int] = set()
        for part in self.guards:
            if part.value(system, states) is not self.guard_value:
                continue
            if part.changed(system, states, node, afters):
                continue
            reads = set(part.reads)
            if reads <= frozen:
                return None
            if not best or len(reads) < len(best):
                best = reads
        return best


@final
class Visibility:
    """What the properties of a `PropertySet` read (see the module docstring).

    Args:
        properties: their invariants, `within` and `eventually` expressions must keep their
            value along paths (terminal checks need no proviso).
        names: node names in scenario order.
    """

    def __init__(self, properties: PropertySet, names: Sequence[str]) -> None:
        index = {n: i for i, n in enumerate(names)}
        self.expressions = [Expression(p.expr.source, index, p.kind == "eventually")
                            for p in (*properties.invariants, *properties.within,
                                      *properties.eventually) if p.expr is not None]
        self.uses_now = any(e.uses_now for e in self.expressions)
        self._of: list[list[Expression]] = [[e for e in self.expressions if e.reads(i)]
                                            for i in range(len(names))]
        # per variant list (System keeps one per node state, event and time): the list,
        # its new states and the expressions they change, each with whether the change is
        # only a rise (`_changing`)
        self._changes: dict[int, tuple[list[Variant], list[bytes],
                                       list[tuple[Expression, bool]]]] = {}
        self._rising: list[list[Expression]] = [[e for e in of if e.rising] for of in self._of]
        #: the rising-goal relaxation holds (no falling transition seen); why not, if not
        self.rising = any(self._rising)
        self.fell: str | None = None
        #: a BFS learns level by level (`Publications.freeze`): a fall seen while frozen
        #: waits here, the relaxation still on, until the search restarts (`commit`)
        self.frozen = False
        self.pending_fall: str | None = None
        self.rises = 0  # events a rising goal let through (for the statistics)
        self._rose: set[tuple[int, bytes, bytes]] = set()  # (node, before, after) seen not to fall

    @property
    def watching(self) -> bool:
        """True while `observe` reads transitions: a rising goal has not fallen yet."""
        return self.rising and self.pending_fall is None

    def observe(self, system: System, world: World, transitions: Iterable[Transition]) -> None:
        """Check that no transition makes an atom of a rising goal fall; the first that does
        turns the relaxation off (`rising`; the search must restart), or, frozen, is noted
        (`pending_fall`)."""
        if self.watching:
            self._falls(system, world.states, ((node, tr.event.method, tr.world.states)
                                               for tr in transitions for node in tr.changed))

    def observe_moves(self, system: System, world: World,
                      moves: Iterable[tuple[Action, Variant]]) -> None:
        """`observe` for the transitions of `moves` (`System.apply` of each), not built."""
        if not self.watching:
            return
        before, events = world.states, world.events
        changes = []
        for action, v in moves:
            if type(action) is Drop:
                continue  # nothing runs
            if type(action) is Crash:
                node, method = action.node, ""
            else:
                ev = events[action.index]
                node, method = ev.target, ev.method
            if v.state is not before[node]:
                changes.append((node, method, (*before[:node], v.state, *before[node + 1:])))
        self._falls(system, before, changes)

    def _falls(self, system: System, before: tuple[bytes, ...],
               changes: Iterable[tuple[int, str, tuple[bytes, ...]]]) -> None:
        """`observe` on (node changed, the handler that ran, the states after) triples."""
        rising, seen = self._rising, self._rose
        for node, method, after in changes:
            if not rising[node]:
                continue
            # a fall reads the node's state before and after only: once per pair
            key = (node, before[node], after[node])
            if key in seen:
                continue
            for expr in rising[node]:
                if expr.falls(system, before, after, node):
                    fell = (f"{system.names[node]}.{method} makes an atom of "
                            f"`{expr.source}` false")
                    if self.frozen:
                        self.pending_fall = fell
                    else:
                        self.rising, self.fell = False, fell
                    return
            if len(seen) >= _CACHE_LIMIT:
                seen.clear()
            seen.add(key)

    def commit(self, fell: str | None = None) -> None:
        """Turn the relaxation off if a fall was noted here, or `fell` (noted by another
        worker), when the search restarts."""
        fell = self.pending_fall or fell
        if fell is not None and self.rising:
            self.rising, self.fell = False, fell
        self.pending_fall = None

    def needs(self, system: System, world: World, chosen: Sequence[int],
              frozen: set[int], acyclic: Callable[[], bool] | None = None) -> set[int] | None:
        """None if no event of `chosen` (indices into `world.events`, of the nodes
        `frozen`) is visible; else the nodes whose addition to `frozen` might guard the
        first visible one (empty: none can). `acyclic()` says whether no zero-time cycle
        can run beside the set (then rising goals may rise unseen)."""
        unseen: bool | None = None  # whether rises go unseen here, asked on the first one
        for i in chosen:
            node = world.events[i].target
            if not self._of[node]:
                continue
            afters, changing = self._changing(system, world, i)
            for expr, only_rises in changing:
                if only_rises:
                    if unseen is None:
                        unseen = self._rises_unseen(acyclic)
                    if unseen:
                        self.rises += 1
                        continue
                guard = expr.guard(system, world.states, node, afters, frozen)
                if guard is not None:
                    return guard
        return None

    def changed(self, system: System, world: World, index: int,
                acyclic: Callable[[], bool] | None = None) -> bool:
        """True if pending event `index` of `world` changes an atom of some expression
        there (no guard considered; a rise of a rising goal counts as in `needs`)."""
        if not self._of[world.events[index].target]:
            return False
        return any(not (only_rises and self._rises_unseen(acyclic))
                   for _, only_rises in self._changing(system, world, index)[1])

    def silent(self, system: System, world: World, indices: Iterable[int]) -> bool:
        """True if no pending event of `indices` of `world` changes an atom of any
        expression: a persistent set of them needs no proviso (`needs`), whatever the
        rest of the world."""
        of = self._of
        return not any(of[world.events[i].target] and self._changing(system, world, i)[1]
                       for i in indices)

    def _rises_unseen(self, acyclic: Callable[[], bool] | None) -> bool:
        """The rising-goal rule (module docstring): a change that only makes atoms of a
        rising goal rise is not visible while the goals rise and no zero-time cycle can run
        beside the set (`acyclic()`)."""
        return self.rising and acyclic is not None and acyclic()

    def _changing(self, system: System, world: World, index: int,
                  ) -> tuple[list[bytes], list[tuple[Expression, bool]]]:
        """The states pending event `index` leaves its node in (where it changes it), and
        the expressions that change, each with whether the change is only a rise. It reads
        only the node's state before (fixed by the variant list) and after, so it is
        decided once per list; a guard reads the world."""
        node = world.events[index].target
        variants = system.variants(world, RunEvent(index))
        cached = self._changes.get(id(variants))
        if cached is None or cached[0] is not variants:
            states = world.states
            afters = self._afters(states[node], variants)
            changing = [(e, e.rising and not e.changes(system, states, node, afters, True))
                        for e in self._of[node]
                        if afters and e.changes(system, states, node, afters)]
            if len(self._changes) >= _CACHE_LIMIT:
                self._changes.clear()
            cached = self._changes[id(variants)] = (variants, afters, changing)
        return cached[1], cached[2]

    @staticmethod
    def _afters(before: bytes, variants: Sequence[Variant]) -> list[bytes]:
        """The states an event's variants leave its node in, where they change it."""
        return [v.state for v in variants if v.state != before]
