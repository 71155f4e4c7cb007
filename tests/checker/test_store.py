"""The compact store and the speed-ups are invisible: same verdicts, counts and traces.

Every optimisation is compared with the unoptimised search: 64-bit digests vs
`exact_states` (128-bit digests of the full encoding), the transition cache vs
re-running every handler, on every small model (both semantics, faults on and
off) and on C1a in the paper's profile.
"""

from __future__ import annotations

import pickle
import random
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.checker.helpers import node, run, scenario
from twinfleet.checker import PropertySet, Search, System
from twinfleet.checker.driver import load
from twinfleet.checker.paths import find_lasso
from twinfleet.checker.store import DigestTable, EdgeStore, StateStore
from twinfleet.checker.world import World

pytestmark = pytest.mark.timeout(120)

ROOT = Path(__file__).resolve().parents[2]
PP = [node("ping", "Ping", rounds=3), node("pong", "Pong")]
GOAL = "a.stage == 'done' and b.stage == 'done'"
WAITERS = [node("a", "WaiterA", inbox="/go_a", outbox="/go_b", first=True),
           node("b", "WaiterB", inbox="/go_b", outbox="/go_a")]

MODELS: dict[str, tuple[list, dict]] = {
    "ping_pong": (PP, {"properties": [{"name": "b", "kind": "invariant",
                                       "expr": "ping.sent - pong.received <= 1"}]}),
    "sums": ([node("two", "TwoSender"), node("four", "FourSender"), node("sum", "Summer")], {}),
    "door_race": ([node("opener", "Opener"), node("locker", "Locker"), node("door", "Door")], {}),
    "ticks": ([node("a", "TickA"), node("b", "TickB")], {}),
    "waiters": (WAITERS, {"properties": [{"name": "f", "kind": "eventually", "expr": GOAL}]}),
    "deadlock": ([node("a", "WaiterA", inbox="/go_a", outbox="/go_b"),
                  node("b", "WaiterB", inbox="/go_b", outbox="/go_a")],
                 {"properties": [{"name": "f", "kind": "eventually", "expr": GOAL}]}),
    "livelock": ([node("server", "BallServer"), node("returner", "BallReturner")],
                 {"properties": [{"name": "s", "kind": "eventually", "expr": "server.scored"}]}),
    "picker": ([node("p", "Picker", second=[0, 100])], {}),
    "within": ([node("c", "Counter", modulo=0, cap=5)],
               {"properties": [{"name": "w", "kind": "within", "expr": "c.count >= 3",
                                "within_ms": 300}]}),
    "service": ([node("client", "Client"), node("adder", "Adder")], {"latency": [0, 2]}),
    "drop_dup": (PP, {"faults": {"drop": ["/pong"], "duplicate": ["/ping"]}}),
    "crash": (PP, {"faults": {"crash": {"nodes": ["ping", "pong"], "max": 2}},
                   "properties": [{"name": "b", "kind": "invariant",
                                   "expr": "ping.sent - pong.received <= 1"}]}),
    "deadline": (PP, {"latency": {"/ping": [0, 2]}, "deadline_ms": 1}),
}

VARIANTS = [{"exact_states": True}, {"transition_cache": False},
            {"exact_states": True, "transition_cache": False}]


def _summary(result):
    s = result.statistics
    trace = None
    if result.trace is not None:
        trace = (result.trace["initial"]["choices"],
                 [(x["node"], x["handler"], x["choices"], x["digest"])
                  for x in result.trace["steps"]], result.trace["cycle_start"])
    return (result.status, result.violation and result.violation.property, s.states,
            s.transitions, s.depth, s.initial_states, trace)


@pytest.mark.parametrize("model", sorted(MODELS))
@pytest.mark.parametrize("semantics", ["ros", "rebeca"])
@pytest.mark.parametrize("search", ["bfs", "dfs"])
def test_optimisations_match_the_unoptimised_search(tmp_path, model, semantics, search):
    nodes, extra = MODELS[model]
    path = scenario(tmp_path, nodes, semantics=semantics, name=model, **extra)
    expected = _summary(run(path, search=search))
    for options in VARIANTS:
        assert _summary(run(path, search=search, **options)) == expected, options


@pytest.mark.slow
def test_c1a_rebeca_counts_are_the_same_in_both_stores():
    # Without the transition cache the same search takes 5x as long: that it changes nothing
    # is checked on the models above and on generated systems (test_reduction_differential).
    path = ROOT / "twinfleet" / "launch" / "c1a_rebeca.yaml"
    fast = run(path, trace_out=None)
    assert (fast.statistics.states, fast.rmc_transitions) == (18_527, 43_077)  # = RMC's
    exact = run(path, trace_out=None, exact_states=True)
    assert _summary(exact) == _summary(fast)
    assert exact.statistics.digest_bits == 128
    assert fast.statistics.digest_bits == 64
    assert fast.statistics.bytes_per_state < 40 < exact.statistics.bytes_per_state
    assert 0 < fast.statistics.collision_probability < 1e-9


def test_world_key_is_time_shift_invariant_and_content_based():
    a = World(0, (b"x",), ())
    b = World(500, (b"x",), ())
    c = World(0, (b"y",), ())
    assert a.key == b.key != c.key
    assert a.digest == b.digest != c.digest
    assert isinstance(a.key, int) and 0 <= a.key < 2**64


@given(st.lists(st.integers(min_value=0, max_value=2**64 - 1), max_size=400))
@settings(max_examples=60, deadline=None)
def test_digest_table_behaves_like_a_dict(keys):
    table = DigestTable(capacity=8)
    ref: dict[int, int] = {}
    for k in keys:
        expected = ref.setdefault(k, len(ref))
        assert table.setdefault(k) == expected
    assert len(table) == len(ref)
    for k, sid in ref.items():
        assert table.get(k) == sid
    assert table.capacity * 0.75 >= len(ref)
    assert list(table.keys()) == list(ref)
    again = pickle.loads(pickle.dumps(table))
    assert all(again.get(k) == sid for k, sid in ref.items())
    assert again.setdefault(12345678901) == ref.get(12345678901, len(ref))


@given(st.lists(st.integers(min_value=0, max_value=2**64 - 1), unique=True, max_size=400),
       st.lists(st.integers(min_value=0, max_value=2**64 - 1), max_size=50))
@settings(max_examples=60, deadline=None)
def test_a_loaded_table_finds_all_keys_at_once_as_get_finds_each(keys, others):
    table = DigestTable(capacity=8)
    table.load(np.array(keys, dtype=np.uint64))
    probe = keys[::2] + others
    assert table.find_all(np.array(probe, dtype=np.uint64)).tolist() == \
        [keys.index(k) if k in keys else -1 for k in probe]
    assert [table.get(k) for k in keys] == list(range(len(keys)))
    assert table.setdefault(2**64 - 7) == (keys.index(2**64 - 7) if 2**64 - 7 in keys
                                           else len(keys))


@given(st.lists(st.lists(st.integers(min_value=0, max_value=9), max_size=6), max_size=10))
@settings(max_examples=60, deadline=None)
def test_edge_rows_built_at_once_equal_rows_set_one_by_one(rows):
    states = 10
    expanded = list(range(states - 1, states - 1 - len(rows), -1))  # any order of ids
    one_by_one = EdgeStore()
    for _ in range(states):
        one_by_one.new_state()
    for sid, children in zip(expanded, rows, strict=True):
        one_by_one.set(sid, children)
    at_once = EdgeStore.from_rows(states, np.array(expanded, dtype=np.int64),
                                  np.array([len(r) for r in rows], dtype=np.int64),
                                  np.array([c for r in rows for c in r], dtype=np.int64))
    for sid in range(states):
        assert [at_once.targets[k] for k in at_once.out(sid)] == \
            [one_by_one.targets[k] for k in one_by_one.out(sid)]
        assert (at_once.start[sid] < 0) == (one_by_one.start[sid] < 0)


def test_digest_table_reads_the_older_checkpoint_layout():
    keys = np.zeros(8, dtype=np.uint64)
    ids = np.zeros(8, dtype=np.int32)
    for sid, (slot, key) in enumerate([(3, 11), (1, 9), (6, 14)]):
        keys[slot], ids[slot] = key, sid
    table = DigestTable.__new__(DigestTable)
    table.__setstate__({"keys": keys, "ids": ids, "n": 3})
    assert [table.get(k) for k in (11, 9, 14, 5)] == [0, 1, 2, -1]
    assert table.setdefault(5) == 3


def test_digest_table_grows_and_stays_compact():
    rng = random.Random(5)
    table = DigestTable()
    keys = [rng.getrandbits(64) for _ in range(100_000)]
    for sid, k in enumerate(keys):
        assert table.setdefault(k) == sid
    assert [table.get(k) for k in keys[:1000]] == list(range(1000))
    assert table.get(rng.getrandbits(64)) == -1
    # 8 B per key (in 64 KiB blocks) + 4 B per slot at a load factor between 0.375 and 0.75
    assert table.nbytes() / len(table) < 8 * 1.1 + 4 / 0.37


def test_edge_store_deduplicates_and_lasso_search_uses_it():
    store = StateStore(record_edges=True, flags=("p",))
    for key in range(4):
        store.add(key + 10, key - 1)
        store.holds["p"].append(False)
    store.roots[0] = ()
    edges = store.edges
    assert isinstance(edges, EdgeStore)
    edges.set(0, [1, 1, 2])
    edges.set(1, [3])
    edges.set(2, [])
    edges.set(3, [1, 1])
    assert [edges.targets[k] for k in edges.out(0)] == [1, 2]
    assert find_lasso(store, "p") == ([0, 1, 3, 1], 1)


@pytest.mark.slow
def test_store_holds_far_fewer_bytes_per_state_than_the_exact_store(tmp_path):
    path = scenario(tmp_path, [node("c", "Counter", modulo=0)], name="big")
    scen = load(path)
    props = PropertySet.from_scenario(scen)
    stats = {}
    for exact in (False, True):
        search = Search(System(scen, properties=props, exact_states=exact), props)
        search.limits = type(search.limits)(max_states=20_000)
        stats[exact] = search.run("bfs").statistics
    assert stats[False].states == stats[True].states == 20_000
    # 8 B keys + 32,768 int32 slots (load 0.61) + parent, flags and roots.
    assert stats[False].bytes_per_state < 30
    assert stats[True].bytes_per_state > 2 * stats[False].bytes_per_state
