"""CellsMemo: answers as computed, each cell stored once, least recently used evicted."""

from __future__ import annotations

import pytest

from twinfleet.nodes.memo import CellsMemo

pytestmark = pytest.mark.timeout(10)


def test_memo_answers_from_cache_and_shares_cells():
    memo = CellsMemo(maxsize=10)
    calls = []

    def compute(n: int):
        calls.append(n)
        return tuple((i, int(str(i) * 3)) for i in range(n))  # fresh, equal tuples each time

    a = memo.get("a", lambda: compute(3))
    assert a == ((0, 0), (1, 111), (2, 222))
    assert memo.get("a", lambda: compute(99)) is a and calls == [3]
    b = memo.get("b", lambda: compute(2))
    assert all(x is y for x, y in zip(a[:2], b, strict=True))  # one object per distinct cell


def test_memo_evicts_the_least_recently_used():
    memo = CellsMemo(maxsize=2)
    memo.get(1, lambda: ((1, 1),))
    memo.get(2, lambda: ((2, 2),))
    memo.get(1, lambda: ())  # touch 1: now 2 is the oldest
    memo.get(3, lambda: ((3, 3),))
    assert len(memo) == 2
    assert memo.get(2, lambda: ((9, 9),)) == ((9, 9),)  # recomputed: it was evicted
    assert memo.get(3, lambda: ()) == ((3, 3),)
