"""RMC's exploration order gives RMC's partial counts of the violating cases exactly."""

from __future__ import annotations

import pytest

from tests.rmc.rmc_order import Heap, count_case

pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]

#: What `std::priority_queue<N, vector<N>, greater<N>>` (g++ 12, libstdc++, this machine)
#: pops for the push/pop sequence of `_drive` below, comparing the key only: equal keys
#: come out in heap order, not in insertion order.
LIBSTDCXX_POPS = (
    "0 2 1 7 8 3 5 9 11 14 12 4 16 17 19 15 13 28 6 26 30 27 33 34 35 36 10 22 21 23 37 38 42 "
    "20 40 46 25 18 39 24 31 32 29 43 48 49 59 54 44 57 41 56 66 47 50 45 52 71 63 61 62 60 73 "
    "58 65 51 68 55 72 53 64 69 67 70"
)


def _drive(heap: Heap) -> list[int]:
    # The same linear congruential sequence as the C++ reference program.
    s, ident, out = 12345, 0, []
    for rnd in range(60):
        s = (s * 1103515245 + 12345) % 2**32
        for _ in range((s >> 16) % 4):
            s = (s * 1103515245 + 12345) % 2**32
            heap.push((s >> 16) % 3 + rnd // 10, ident)
            ident += 1
        if len(heap):
            out.append(heap.pop())
    while len(heap):
        out.append(heap.pop())
    return out


def test_heap_pops_like_libstdcxx_priority_queue():
    assert _drive(Heap()) == [int(v) for v in LIBSTDCXX_POPS.split()]


@pytest.mark.parametrize(
    ("case", "states", "transitions"),
    [
        ("c2a", 2_901, 6_429),
        ("c2b", 6_541, 15_018),
        ("c2c", 1_634, 3_621),  # our breadth-first search stops at 1,636 / 3,645
    ],
)
def test_rmc_order_reaches_rmcs_counts_at_the_collision(case, states, transitions):
    counts = count_case(case)
    assert counts.violated
    assert (counts.states, counts.transitions) == (states, transitions)
