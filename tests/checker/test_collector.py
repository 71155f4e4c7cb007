"""A search runs with the cyclic garbage collector's seldom thresholds, and gives the
caller's back; a cluster worker holds them (and its switch interval) until released."""

from __future__ import annotations

import gc
import sys
from pathlib import Path
from typing import Any

import pytest

from twinfleet.checker import CheckOptions, check
from twinfleet.checker.collector import (
    SEARCH_THRESHOLDS,
    Held,
    quick_switches,
    seldom_collections,
)
from twinfleet.checker.outcome import Outcome
from twinfleet.checker.search import Search

STATION = Path(__file__).resolve().parents[1] / "data" / "station" / "station.yaml"


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


def test_the_switch_interval_comes_back_even_after_an_error() -> None:
    before, inside = sys.getswitchinterval(), []

    def failing() -> None:
        with quick_switches(0.00005):
            inside.append(sys.getswitchinterval())
            raise RuntimeError

    with pytest.raises(RuntimeError):
        failing()
    assert inside == [pytest.approx(0.00005)]
    assert sys.getswitchinterval() == before


def test_what_an_object_holds_comes_back_when_it_is_released() -> None:
    before = (gc.get_threshold(), sys.getswitchinterval())
    worker = Held()
    worker.hold(seldom_collections())
    worker.hold(quick_switches(0.00005))
    assert (gc.get_threshold(), sys.getswitchinterval()) == (SEARCH_THRESHOLDS,
                                                            pytest.approx(0.00005))
    assert worker.release() == 0
    assert (gc.get_threshold(), sys.getswitchinterval()) == before
    assert worker.release() == 0 and Held().release() == 0  # again, or never held: nothing
    assert (gc.get_threshold(), sys.getswitchinterval()) == before


def test_a_cluster_worker_holds_the_thresholds_from_its_build_until_released() -> None:
    from twinfleet.checker.cluster import engine
    from twinfleet.checker.cluster.spec import SystemSpec, fingerprint

    spec = SystemSpec(str(STATION), None, (), ())
    expected = fingerprint(spec.build()[0])
    before, worker = gc.get_threshold(), Held()
    engine._built(spec, expected, worker)
    assert gc.get_threshold() == SEARCH_THRESHOLDS
    worker.release()
    assert gc.get_threshold() == before
