"""Invariants are checked once per tuple of node states when none reads `now`."""

from __future__ import annotations

from typing import Any

import pytest

from twinfleet.checker.properties import Expr, Property, PropertySet
from twinfleet.checker.world import Event, World
from twinfleet.runtime.contract.kinds import EventKind


class _Reader:
    names = ("a", "b")

    def decode(self, i: int, data: bytes) -> Any:
        return {"n": int(data)}


def _world(now: int, a: bytes, b: bytes, due: int) -> World:
    return World(now, (a, b), (Event(due, EventKind.TIMER, 0, "t", 0, (), 0),))


def _counting(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    calls: list[str] = []
    holds = Expr.holds

    def counted(self: Expr, *args: Any) -> bool:
        calls.append(self.source)
        return holds(self, *args)

    monkeypatch.setattr(Expr, "holds", counted)
    return calls


def test_one_look_up_per_tuple_of_node_states(monkeypatch):
    names = ["a", "b"]
    props = PropertySet([Property("small", "invariant", Expr("a['n'] < 5", names, "t")),
                         Property("sum", "invariant", Expr("a['n'] + b['n'] < 9", names, "t"))])
    calls = _counting(monkeypatch)
    ok, bad = (b"1", b"2"), (b"7", b"2")
    assert props.check_world(_Reader(), _world(0, *ok, 5)) is None
    assert len(calls) == 2
    assert props.check_world(_Reader(), _world(30, *ok, 40)) is None  # other events, time
    assert len(calls) == 2
    violation = props.check_world(_Reader(), _world(0, *bad, 5))
    assert violation is not None and violation.property == "small"
    again = props.check_world(_Reader(), _world(10, *bad, 10))  # never kept as holding
    assert again is not None and again.property == "small"


def test_an_invariant_that_reads_now_is_checked_in_every_world(monkeypatch):
    names = ["a", "b"]
    props = PropertySet([Property("early", "invariant", Expr("now < 20", names, "t"))])
    calls = _counting(monkeypatch)
    assert props.check_world(_Reader(), _world(0, b"1", b"2", 5)) is None
    violation = props.check_world(_Reader(), _world(30, b"1", b"2", 40))
    assert violation is not None and violation.property == "early"
    assert len(calls) == 2
