"""Which transitions a property can see (the visibility proviso of `checker.reduction`).

A reduced search may postpone a transition only if no property expression
can change its value through it. Expressions are split into *atoms* along
``and``/``or``/``not``; an atom that reads the state of one node only is
decided exactly: a transition of node A changes it iff the atom differs on
A's state before and after (A's state cannot change while the transition is
postponed: A is frozen in the reduction's node set, so "before" is the same
in every world where the transition might run instead). An atom that reads
several nodes (or ``nodes``) makes every state change of those nodes
visible. If no atom changes, no boolean combination of them can.

Evaluating the whole expression before and after would not be sound: with
``r2.done and not r1.done`` an r1 step that keeps it false here may make it
true in a world where r2 arrived first.
"""

from __future__ import annotations

import ast
import builtins
from collections.abc import Iterable, Sequence
from types import CodeType
from typing import TYPE_CHECKING, Any, final

if TYPE_CHECKING:
    from twinfleet.checker.properties import PropertySet, States
    from twinfleet.checker.transition import Variant

_CACHE_LIMIT = 4_096  # atom values kept per atom (by node state)


@final
class Atom:
    """A boolean leaf of a property expression that reads one node's state."""

    __slots__ = ("_cache", "code", "name", "node", "source")

    def __init__(self, source: str, node: int, name: str) -> None:
        self.source = source
        self.node = node
        self.name = name
        self.code: CodeType = compile(source, "<atom>", "eval")
        self._cache: dict[bytes, Any] = {}

    def value(self, system: States, data: bytes) -> Any:
        """The atom on node state `data` (an exception counts as its own value)."""
        found = self._cache.get(data)
        if found is None:
            env = {"__builtins__": builtins, self.name: system.decode(self.node, data)}
            try:
                found = bool(eval(self.code, env))
            except Exception as exc:  # the search reports it where it evaluates the property
                found = type(exc).__name__
            if len(self._cache) >= _CACHE_LIMIT:
                self._cache.clear()
            self._cache[data] = found
        return found


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
class Visibility:
    """What the properties of a `PropertySet` read, split into per-node atoms.

    Args:
        properties: the properties whose value along a path must be kept
            (invariants, `within`, `eventually`; terminal checks need no proviso).
        names: node names in scenario order.

    Attributes:
        uses_now: some expression reads `now` (the reduction is then off).
        whole: nodes any of whose state changes is visible.
    """

    def __init__(self, properties: PropertySet, names: Sequence[str]) -> None:
        index = {n: i for i, n in enumerate(names)}
        self.atoms: list[list[Atom]] = [[] for _ in names]
        self.whole: set[int] = set()
        self.uses_now = False
        for prop in (*properties.invariants, *properties.within, *properties.eventually):
            if prop.expr is not None:
                self._split(prop.expr.source, index)

    def _split(self, source: str, index: dict[str, int]) -> None:
        for leaf in _leaves(ast.parse(source.strip(), mode="eval").body):
            used = {n.id for n in ast.walk(leaf) if isinstance(n, ast.Name)}
            self.uses_now |= "now" in used
            if "nodes" in used:
                self.whole.update(index.values())
                continue
            read = [index[n] for n in used if n in index]
            if len(read) == 1:
                name = next(n for n in used if n in index)
                self.atoms[read[0]].append(Atom(ast.unparse(leaf), read[0], name))
            else:
                self.whole.update(read)

    @property
    def reads(self) -> set[int]:
        """Nodes some atom reads."""
        return self.whole | {i for i, atoms in enumerate(self.atoms) if atoms}

    def visible(self, system: States, node: int, before: bytes,
                variants: Sequence[Variant]) -> bool:
        """True if some variant of a transition of `node` (state `before`) changes an atom."""
        atoms = self.atoms[node]
        whole = node in self.whole
        if not atoms and not whole:
            return False
        for v in variants:
            after = v.state
            if after is before or after == before:
                continue
            if whole:
                return True
            for atom in atoms:
                if atom.value(system, before) != atom.value(system, after):
                    return True
        return False
