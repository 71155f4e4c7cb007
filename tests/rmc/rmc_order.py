"""Our `rebeca` system searched in RMC's own exploration order, for partial counts.

A search that stops at the first violation counts what it has seen so far, so
its numbers depend on the order in which states are expanded. RMC's order
(org.rebecalang.rmc `TimedModelCheckerCPPTemplate.vm`, `FTTSPatchTemplate.vm`,
`AbstractTimedRebecaAnalyzerCPPTemplate.vm`):

- open states sit in a `std::priority_queue` ordered by their next-event time
  with `std::greater` only, so equal times come out in the order libstdc++'s
  binary heap (`push_heap`/`pop_heap`) happens to leave them (`Heap` below
  transcribes those two algorithms);
- a state's successors: the enabled rebec(s) of least instance priority, each
  queue alternative in RMC's queue order (equal-time scans come as
  r5, r4, r2, r3, r1, as every trace prints them; path requests by sender,
  r1 first), each `?()` variant with the last `?()` varying fastest (our
  back-off options are listed rank-major, steps fastest: the same order);
- every executed step counts one transition, the initial state counts one
  more, and the assertions are checked in every reached state.

`python3 -m tests.rmc.rmc_order c2c` prints the counts at the first collision.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from tests.rmc import adapter
from tests.rmc.follower import MAP_NODE, scenario_path

#: RMC's queue order of the five equal-time `scanObstacles` (by their parameter bytes).
SCAN_ORDER = ("r5", "r4", "r2", "r3", "r1")


class Heap:
    """libstdc++'s `std::priority_queue<T, vector<T>, greater<T>>` on a key, tie order included."""

    def __init__(self) -> None:
        self.items: list[tuple[int, Any]] = []

    def __len__(self) -> int:
        return len(self.items)

    @staticmethod
    def _after(a: tuple[int, Any], b: tuple[int, Any]) -> bool:
        return a[0] > b[0]  # std::greater on the key only

    def _sift_up(self, hole: int, top: int, value: tuple[int, Any]) -> None:
        items = self.items
        parent = (hole - 1) // 2
        while hole > top and self._after(items[parent], value):
            items[hole] = items[parent]
            hole = parent
            parent = (hole - 1) // 2
        items[hole] = value

    def push(self, key: int, item: Any) -> None:
        """`push_back` then `std::push_heap`."""
        self.items.append((key, item))
        self._sift_up(len(self.items) - 1, 0, self.items[-1])

    def pop(self) -> Any:
        """`top()`, then `std::pop_heap` (`__adjust_heap`) and `pop_back`."""
        items = self.items
        top = items[0]
        n = len(items) - 1
        if n > 0:
            value = items[-1]
            items[-1] = items[0]
            hole, child = 0, 0
            while child < (n - 1) // 2:
                child = 2 * (child + 1)
                if self._after(items[child], items[child - 1]):
                    child -= 1
                items[hole] = items[child]
                hole = child
            if n % 2 == 0 and child == (n - 2) // 2:
                child = 2 * (child + 1)
                items[hole] = items[child - 1]
                hole = child - 1
            self._sift_up(hole, 0, value)
        items.pop()
        return top[1]


def rmc_rank(step: adapter.Step) -> tuple[int, ...]:
    """Where RMC's queue puts this step's message among equal-time alternatives."""
    if step.handler == "scan_robot":
        return (SCAN_ORDER.index(step.args[0]),)
    if step.handler == "generate_path":
        return (int(step.args[0].robot[1:]),)
    return ()


@dataclass(frozen=True)
class Counts:
    """States and transitions (RMC's way) when the search stopped, and why."""

    states: int
    transitions: int
    violated: bool


def search(system: Any, world: Any, violated: Callable[[Any, Any], bool]) -> Counts:
    """Explore in RMC's order from `world` until `violated(system, world)` or the end."""
    seen = {world.key}
    states, transitions = 1, 1  # RMC counts storing the initial state as a transition
    heap = Heap()
    heap.push(world.events[0].due, world)
    while heap:
        current = heap.pop()
        steps = adapter.enabled_steps(system, current)
        steps.sort(key=rmc_rank)  # stable: variants keep their order
        for step in steps:
            after = adapter.take(step)
            transitions += 1
            new = after.key not in seen
            if new:
                seen.add(after.key)
                states += 1
            if violated(system, after):
                return Counts(states, transitions, True)
            if new and after.events:
                heap.push(after.events[0].due, after)
    return Counts(states, transitions, False)


def collision_or_livelock(system: Any, world: Any) -> bool:
    """The model's two assertions: `collisionFree` and `liveLockFree` (failures ≤ 2)."""
    states = adapter.node_states(system, world)
    robots = [s for name, s in states.items() if name != MAP_NODE]
    return states[MAP_NODE].collisions > 0 or any(r.failures > 2 for r in robots)


def count_case(case: str) -> Counts:
    """RMC-order counts of `launch/<case>_rebeca.yaml` at its first violation."""
    system, world = adapter.build(scenario_path(case))
    return search(system, world, collision_or_livelock)


if __name__ == "__main__":
    for name in sys.argv[1:]:
        c = count_case(name)
        print(f"{name}: {'violated' if c.violated else 'holds'} {c.states} states, "
              f"{c.transitions} transitions")
