"""A shard's visited table answers as a dict of key -> parent key does, batch by batch."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from twinfleet.checker.cluster import visited as visited_module
from twinfleet.checker.cluster.level import ShardCore, owner, pack_pairs, visited_from
from twinfleet.checker.cluster.visited import ROOT, VisitedTable

KEYS = st.one_of(st.integers(min_value=0, max_value=40),  # repeats, and the key 0
                 st.integers(min_value=0, max_value=2**64 - 1))
BATCHES = st.lists(st.lists(st.tuples(KEYS, st.integers(min_value=1, max_value=2**64 - 1)),
                            max_size=60), max_size=8)


@settings(max_examples=80, deadline=None)
@given(batches=BATCHES, roots=st.lists(KEYS, max_size=3))
def test_batches_of_claims_are_answered_as_a_dict_answers_them_one_by_one(
        batches: list[list[tuple[int, int]]], roots: list[int]) -> None:
    for few in (0, visited_module.FEW):  # numpy's probing rounds, then key by key
        default, visited_module.FEW = visited_module.FEW, few
        try:
            _answers_as_a_dict(batches, roots)
        finally:
            visited_module.FEW = default


def _answers_as_a_dict(batches: list[list[tuple[int, int]]], roots: list[int]) -> None:
    table, ref = VisitedTable(capacity=4), {}
    for key in roots:
        table.put(key, ROOT)
        ref.setdefault(key, ROOT)
    for batch in batches:
        keys = np.array([k for k, _ in batch], dtype=np.uint64)
        before = table.contains(keys).tolist()
        assert before == [k in ref for k, _ in batch]
        stored = table.add(keys, np.array([p for _, p in batch], dtype=np.uint64))
        expected = []
        for key, parent in batch:
            expected.append(key not in ref)
            ref.setdefault(key, parent)
        assert stored.tolist() == expected
    assert len(table) == len(ref)
    assert all(table.get(k) == p for k, p in ref.items())
    assert table.get(2**64 - 3) == ref.get(2**64 - 3)
    keys, parents = table.arrays()
    assert dict(zip(keys.tolist(), [ROOT if p == 0 else p for p in parents.tolist()],
                    strict=True)) == ref
    again = visited_from([ShardCore(table).dump()], roots)
    assert all(again.get(k) == p for k, p in ref.items()) and len(again) == len(ref)


def test_a_shard_answers_the_first_worker_that_claims_a_key() -> None:
    shard = ShardCore()
    first, second = shard.claim([pack_pairs([5, 6, 7], [1, 1, 1]), pack_pairs([7, 8], [2, 2])])
    assert np.frombuffer(first, dtype=np.bool_).tolist() == [True, True, True]
    assert np.frombuffer(second, dtype=np.bool_).tolist() == [False, True]
    assert shard.parent(7) == 1 and shard.parent(8) == 2
    stored = shard.stored([np.array([5, 9], dtype=np.uint64).tobytes()])[0]
    assert np.frombuffer(stored, dtype=np.bool_).tolist() == [True, False]


@settings(max_examples=60, deadline=None)
@given(length=st.integers(1, 40), shards=st.integers(1, 3), seed=st.integers(0, 2**16))
def test_a_path_walked_by_lineages_is_the_path_walked_parent_by_parent(
        length: int, shards: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    path = [int(k) for k in rng.integers(1, 2**63, size=length, dtype=np.uint64)]
    parts = [ShardCore() for _ in range(shards)]
    for parent, key in zip([0, *path], path, strict=False):  # 0: the first is initial
        parts[owner(key, shards)].add(np.array([key], dtype=np.uint64),
                                      np.array([parent], dtype=np.uint64))
    walked, calls = [path[-1]], 0
    while walked[-1] != ROOT:
        index = owner(walked[-1], shards)
        found = parts[index].lineage(walked[-1], index, shards)
        assert all(owner(k, shards) == index for k in found[:-1])  # one partition's run
        walked += found
        calls += 1
    assert walked[:-1] == path[::-1]
    assert calls == 1 + sum(owner(a, shards) != owner(b, shards)
                            for a, b in zip(path, path[1:], strict=False))


def test_the_table_grows_and_stays_compact() -> None:
    rng = np.random.default_rng(3)
    table = VisitedTable()
    keys = rng.integers(1, 2**63, size=200_000, dtype=np.uint64)
    for chunk in np.array_split(keys, 50):
        table.add(chunk, chunk + np.uint64(1))
    assert len(table) == len(np.unique(keys))
    assert table.contains(keys).all()
    assert table.nbytes() / len(table) <= 16 / 0.375
