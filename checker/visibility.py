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
"""

from __future__ import annotations

import ast
import builtins
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Any, final

from twinfleet.checker.transition import RunEvent

if TYPE_CHECKING:
    from twinfleet.checker.properties import PropertySet
    from twinfleet.checker.system import System
    from twinfleet.checker.transition import Variant
    from twinfleet.checker.world import World

_CACHE_LIMIT = 4_096  # values kept per part (by the node states it reads)


@final
class Part:
    """A subexpression over a fixed set of nodes, evaluated on their states (cached)."""

    __slots__ = ("_cache", "code", "names", "reads", "source")

    def __init__(self, tree: ast.expr, index: dict[str, int]) -> None:
        self.source = ast.unparse(tree)
        used = sorted({n.id for n in ast.walk(tree) if isinstance(n, ast.Name)})
        self.names = tuple(n for n in used if n in index)
        self.reads = tuple(index[n] for n in self.names)
        self.code = compile(self.source, "<property part>", "eval")
        self._cache: dict[tuple[bytes, ...], Any] = {}

    def value(self, system: System, states: Sequence[bytes]) -> Any:
        """The part on node states (in scenario order); an exception is its own value."""
        key = tuple(states[i] for i in self.reads)
        found = self._cache.get(key)
        if found is None:
            env: dict[str, Any] = {"__builtins__": builtins}
            for i, name in zip(self.reads, self.names, strict=True):
                env[name] = system.decode(i, states[i])
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

    def __init__(self, source: str, index: dict[str, int]) -> None:
        tree = ast.parse(source.strip(), mode="eval").body
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
        #: for `and`, the conjuncts (a false one guards); for `or`, the disjuncts
        self.guard_value = isinstance(tree, ast.BoolOp) and isinstance(tree.op, ast.Or)
        self.guards = ([Part(v, index) for v in tree.values] if isinstance(tree, ast.BoolOp)
                       and "nodes" not in {n.id for n in ast.walk(tree)
                                           if isinstance(n, ast.Name)} else [])

    def reads(self, node: int) -> bool:
        """True if the expression reads `node`'s state."""
        return node in self.whole or node in self.atoms

    def changes(self, system: System, states: Sequence[bytes], node: int,
                afters: Sequence[bytes]) -> bool:
        """True if some atom over `node` changes (any change if a multi-node atom reads it)."""
        if node in self.whole:
            return True
        return any(a.changed(system, states, node, afters) for a in self.atoms.get(node, ()))

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
        self.expressions = [Expression(p.expr.source, index)
                            for p in (*properties.invariants, *properties.within,
                                      *properties.eventually) if p.expr is not None]
        self.uses_now = any(e.uses_now for e in self.expressions)
        self._of: list[list[Expression]] = [[e for e in self.expressions if e.reads(i)]
                                            for i in range(len(names))]
        # per variant list (System keeps one per node state, event and time): the list,
        # its new states and the expressions they change (`needs`)
        self._changes: dict[int, tuple[list[Variant], list[bytes], list[Expression]]] = {}

    def needs(self, system: System, world: World, chosen: Sequence[int],
              frozen: set[int]) -> set[int] | None:
        """None if no event of `chosen` (indices into `world.events`, of the nodes
        `frozen`) is visible; else the nodes whose addition to `frozen` might guard the
        first visible one (empty: none can)."""
        states = world.states
        for i in chosen:
            node = world.events[i].target
            exprs = self._of[node]
            if not exprs:
                continue
            variants = system.variants(world, RunEvent(i))
            # Whether an expression changes reads only the node's state before (fixed by
            # the list) and after, so it is decided once per list; a guard reads the world.
            cached = self._changes.get(id(variants))
            if cached is None or cached[0] is not variants:
                before = states[node]
                afters = [v.state for v in variants if v.state != before]
                changing = [e for e in exprs if e.changes(system, states, node, afters)] \
                    if afters else []
                if len(self._changes) >= _CACHE_LIMIT:
                    self._changes.clear()
                cached = self._changes[id(variants)] = (variants, afters, changing)
            afters, changing = cached[1], cached[2]
            for expr in changing:
                guard = expr.guard(system, states, node, afters, frozen)
                if guard is not None:
                    return guard
        return None
