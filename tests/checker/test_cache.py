"""The bounded outcome cache keeps what is used, drops what is not, and forgets by time."""

from __future__ import annotations

import pytest

from twinfleet.checker.cache import GenerationCache


def test_keeps_at_most_two_generations():
    cache: GenerationCache[str] = GenerationCache(2)
    for t in range(5):
        cache.put(("k", t), f"v{t}")
    assert len(cache) <= 4
    assert cache.get(("k", 0)) is None
    assert cache.get(("k", 4)) == "v4"


def test_a_hit_in_the_old_generation_survives_the_next_turn():
    cache: GenerationCache[int] = GenerationCache(2)
    cache.put(("a", 0), 1)
    cache.put(("b", 0), 2)
    cache.put(("c", 0), 3)  # a, b are now old
    assert cache.get(("a", 0)) == 1  # moved back to the young generation
    cache.put(("d", 0), 4)  # young {c, a} turns over; b is dropped
    cache.put(("e", 0), 5)
    assert cache.get(("a", 0)) == 1
    assert cache.get(("b", 0)) is None


def test_forget_before_drops_by_the_time_at_the_end_of_the_key():
    cache: GenerationCache[int] = GenerationCache(2)
    for t in (10, 20, 30, 40):
        cache.put(("x", t), t)
    assert cache.forget_before(25) == 2
    assert [cache.get(("x", t)) for t in (10, 20, 30, 40)] == [None, None, 30, 40]


def test_limit_must_be_positive():
    with pytest.raises(ValueError, match="positive"):
        GenerationCache(0)
