"""runtime.contract.snapshot: canonical bytes, exact types back, both dataclass paths."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from twinfleet.runtime.contract.snapshot import _canonical, _flat, _pack, restore, snapshot

Cell = tuple[int, int]


@dataclass
class Flat:
    cell: Cell = (0, 0)
    moves: tuple[Cell, ...] = ()
    name: str = ""
    ratio: float = 0.5
    done: bool = False
    maybe: int | None = None


@dataclass
class General:
    cells: list[Cell] = field(default_factory=list)
    table: dict[str, int] = field(default_factory=dict)
    seen: set[Cell] = field(default_factory=set)
    grid: np.ndarray = field(default_factory=lambda: np.zeros((2, 2), dtype=np.int16))
    inner: Flat = field(default_factory=Flat)


def test_flat_dataclass_round_trips_with_tuples():
    value = Flat((3, 4), ((1, 2), (2, 3)), "r1", 1.5, True, None)
    back = restore(snapshot(value))
    assert back == value
    assert type(back.moves) is tuple
    assert type(back.moves[0]) is tuple
    assert snapshot(back) == snapshot(value)


def test_general_dataclass_keeps_lists_dicts_sets_arrays():
    value = General([(1, 2)], {"b": 2, "a": 1}, {(1, 1), (0, 2)}, np.arange(4, dtype=np.int16).reshape(2, 2))
    back = restore(snapshot(value))
    assert type(back.cells) is list
    assert type(back.cells[0]) is tuple
    assert back.table == value.table
    assert back.seen == value.seen
    assert back.grid.dtype == np.int16
    assert (back.grid == value.grid).all()
    assert snapshot(back) == snapshot(value)


def test_equal_values_of_different_types_encode_differently():
    assert snapshot((1, 2)) != snapshot((1.0, 2.0))
    assert snapshot(Flat(maybe=1)) != snapshot(Flat(maybe=True))
    assert snapshot([1]) != snapshot((1,))


def test_dict_order_does_not_matter():
    assert snapshot({"a": 1, "b": 2}) == snapshot({"b": 2, "a": 1})


plain = st.recursive(
    st.one_of(st.integers(-10**12, 10**12), st.booleans(), st.text(max_size=5), st.none(),
              st.floats(allow_nan=False)),
    lambda inner: st.one_of(st.tuples(inner, inner), st.lists(inner, max_size=3)),
    max_leaves=12,
)


@given(plain)
def test_any_plain_value_round_trips_canonically(value):
    back = restore(snapshot(value))
    assert snapshot(back) == snapshot(value)
    assert back == value


@dataclass
class One:
    only: int = 7


def test_flat_dataclasses_take_the_fast_path_with_the_general_paths_bytes():
    # A flat dataclass (a node state, a message) is encoded without the general dispatch,
    # answered once per type; its bytes are those the general path gives (`_pack` with the
    # `_default` hook), at the top, inside a tuple (an event's args) and with one field.
    assert _flat(Flat) is not None and _flat(One) is not None
    assert _flat(General) is None and _flat(tuple) is None
    for value in (Flat((3, 4), ((1, 2),), "r1", 1.5, True, 2), One(), (Flat(), One(3)),
                  (One(), 1, "a", None, 2.5, True, b"x"), (), (One(), (1, 2)), (1, [2])):
        assert snapshot(value) == _pack(_canonical(value))
        assert restore(snapshot(value)) == value


def test_a_call_error_in_a_state_keeps_its_failure_enum():
    from twinfleet import CallError, CallFailure

    error = CallError("/plan", CallFailure.TIMEOUT, "timeout")
    back = restore(snapshot({"last": error}))["last"]
    assert back == error and back.failure is CallFailure.TIMEOUT
    assert snapshot(error) != snapshot(CallError("/plan", CallFailure.NO_SERVER, "timeout"))


def test_a_call_error_decoded_from_the_wire_carries_the_enum():
    from twinfleet import CallError, CallFailure
    from twinfleet.runtime.contract.messages import decode, encode

    error = decode(encode(CallError("/plan", CallFailure.SERVER_ERROR, "server error: x"))).msg
    assert error.failure is CallFailure.SERVER_ERROR and error.reason == "server error: x"
