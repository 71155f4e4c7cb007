"""The visited-state store: digests numbered in discovery order, parents, and edges.

Each distinct world digest gets an integer id; per id the store keeps the
parent id (for shortest/first-found paths) and, when liveness properties are
checked, the ids of its successors and one bit per `eventually` property
("its expression holds here"). Steps are not stored: a path of ids is turned
back into steps by re-running the successors of each world on it and picking
the one that reaches the next digest (`steps_along`), which keeps the store at
a few tens of bytes per state plus 4 bytes per edge.

`find_lasso` is the liveness check on the recorded graph: a depth-first search
restricted to states where the property's expression is false, colouring
states on the stack grey, so a back edge closes a reachable cycle on which the
expression never holds (a lasso) and a state with nothing pending ends a
finite counterexample.
"""

from __future__ import annotations

from array import array
from typing import final

from checker.system import Step, System, Transition
from checker.world import World

_GREY, _BLACK = 1, 2


@final
class StateGraph:
    """Visited states; `edges` is None unless `record_edges`."""

    def __init__(self, *, record_edges: bool = False, flags: tuple[str, ...] = ()) -> None:
        self.ids: dict[bytes, int] = {}
        self.parent = array("i")
        self.roots: dict[int, tuple[int, ...]] = {}
        self.edges: list[array] | None = [] if record_edges else None
        self.terminal = bytearray()
        self.holds: dict[str, bytearray] = {name: bytearray() for name in flags}

    def __len__(self) -> int:
        return len(self.ids)

    def add(self, digest: bytes, parent: int, *, terminal: bool = False) -> tuple[int, bool]:
        """The id of `digest`, and whether it is new (then `parent` is recorded; -1 = root)."""
        known = self.ids.get(digest)
        if known is not None:
            return known, False
        sid = len(self.ids)
        self.ids[digest] = sid
        self.parent.append(parent)
        self.terminal.append(terminal)
        if self.edges is not None:
            self.edges.append(array("i"))
        return sid, True

    def path_ids(self, sid: int) -> list[int]:
        """Ids from a root to `sid` along first-discovery parents."""
        ids = [sid]
        while self.parent[ids[-1]] >= 0:
            ids.append(self.parent[ids[-1]])
        return ids[::-1]


def steps_along(system: System, graph: StateGraph, ids: list[int]) -> tuple[tuple[int, ...],
                                                                             list[Step]]:
    """The initial choices and steps that follow the path of state ids `ids`."""
    digests = list(graph.ids)
    initial = graph.roots[ids[0]]
    world = system.initial_world(initial).world
    steps = []
    for nxt in ids[1:]:
        t = _successor_to(system, world, digests[nxt])
        steps.append(t.step)
        world = t.world
    return initial, steps


def _successor_to(system: System, world: World, digest: bytes) -> Transition:
    for t in system.successors(world):
        if t.failure is None and t.world.digest == digest:
            return t
    raise RuntimeError("a recorded edge cannot be re-executed: the model is nondeterministic "
                       "(rerun with --debug-state)")


def find_lasso(graph: StateGraph, prop: str) -> tuple[list[int], int | None] | None:
    """A path of ids on which `prop` never holds, ending in a cycle or a terminal state.

    Returns (ids, cycle_start) where `ids[-1] == ids[cycle_start]` for a lasso and
    cycle_start is None for a path ending in a terminal state; None if there is none.
    """
    assert graph.edges is not None, "find_lasso needs a graph recorded with edges"
    holds, edges, terminal = graph.holds[prop], graph.edges, graph.terminal
    colour = bytearray(len(graph))
    for root in graph.roots:
        if holds[root] or colour[root]:
            continue
        colour[root] = _GREY
        if terminal[root]:
            return [root], None
        stack = [root]
        cursor = [0]
        while stack:
            v = stack[-1]
            out = edges[v]
            k = cursor[-1]
            if k == len(out):
                colour[v] = _BLACK
                stack.pop()
                cursor.pop()
                continue
            cursor[-1] = k + 1
            w = out[k]
            if holds[w] or colour[w] == _BLACK:
                continue
            if colour[w] == _GREY:
                return [*stack, w], stack.index(w)
            colour[w] = _GREY
            stack.append(w)
            cursor.append(0)
            if terminal[w]:
                return list(stack), None
    return None
