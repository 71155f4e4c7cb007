"""A bounded memo for the pure, expensive steps of the robot system (scans, plans).

The checker asks for the same scan or plan again and again on different
interleavings, so the map server memoises them. Results are tuples of cells;
the memo stores each distinct cell once (a 50×50 map has 2,500), which cuts a
cached 40-cell scan from about 2.6 kB to 0.4 kB.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Hashable

from twinfleet.nodes.grid import Cell
from twinfleet.runtime.contract.node import PureMemo


class CellsMemo(PureMemo):  # its content grows, its answers do not change
    """Least-recently-used memo of functions returning a tuple of cells.

    Args:
        maxsize: entries kept; the least recently used is evicted beyond it.
    """

    def __init__(self, maxsize: int = 65536) -> None:
        self._entries: OrderedDict[Hashable, tuple[Cell, ...]] = OrderedDict()
        self._cells: dict[Cell, Cell] = {}
        self.maxsize = maxsize

    def get(self, key: Hashable, compute: Callable[[], tuple[Cell, ...]]) -> tuple[Cell, ...]:
        """The result for `key`, from the memo or else from `compute()` (then remembered)."""
        entries = self._entries
        found = entries.get(key)
        if found is not None:
            entries.move_to_end(key)
            return found
        cells = self._cells
        result = tuple([cells.setdefault(c, c) for c in compute()])
        entries[key] = result
        if len(entries) > self.maxsize:
            entries.popitem(last=False)
        return result

    def __len__(self) -> int:
        return len(self._entries)
