"""A search runs with the cyclic garbage collector's seldom thresholds, and gives the
caller's back."""

from __future__ import annotations

import gc
from typing import Any

import pytest

from twinfleet.checker import CheckOptions, check
from twinfleet.checker.collector import SEARCH_THRESHOLDS, seldom_collections
from twinfleet.checker.outcome import Outcome
from twinfleet.checker.search import Search


def test_the_thresholds_come_back_even_after_an_error() -> None:
    before, inside = gc.get_threshold(), []

    def failing() -> None:
        with seldom_collections():
            inside.append(gc.get_threshold())
            raise RuntimeError

    with pytest.raises(RuntimeError):
        failing()
    assert inside == [SEARCH_THRESHOLDS]
    assert gc.get_threshold() == before


@pytest.mark.slow
def test_a_check_searches_with_them(monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[tuple[int, ...]] = []
    run = Search.run

    def recorded(self: Search, *args: Any, **kwargs: Any) -> Outcome:
        seen.append(gc.get_threshold())
        return run(self, *args, **kwargs)

    monkeypatch.setattr(Search, "run", recorded)
    before = gc.get_threshold()
    assert check("c1a", CheckOptions()).status.value == "holds"
    assert seen == [SEARCH_THRESHOLDS]
    assert gc.get_threshold() == before
