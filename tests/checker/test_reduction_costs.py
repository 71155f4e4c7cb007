"""What a reduced search spends besides its worlds (docs/reduction.md §5, §6): persistent
sets looked up by shape, walks that build only the worlds they step to, restarts that
start from the initial transitions built once, and no restart for a pass that reduced
nothing. Each must leave the search's choices, what it learns and its counts as they
were."""

from __future__ import annotations

import random
from pathlib import Path
from typing import Any

import pytest

from twinfleet.checker import reduction as reduction_module
from twinfleet.checker.driver import CheckOptions, check, load
from twinfleet.checker.properties import PropertySet
from twinfleet.checker.reduction import Reduction
from twinfleet.checker.search import Search
from twinfleet.checker.system import System
from twinfleet.checker.world import World

pytestmark = pytest.mark.timeout(60)

LAUNCH = Path(__file__).resolve().parents[2] / "twinfleet" / "launch"
STATION = Path(__file__).resolve().parents[1] / "data" / "station" / "station.yaml"


def searched(path: Path) -> tuple[System, Reduction, Any]:
    """A fresh reduced BFS of `path`: its system, reduction and outcome."""
    scenario_ = load(str(path))
    props = PropertySet.from_scenario(scenario_)
    system = System(scenario_, properties=props)
    reduction = Reduction(system, props)
    outcome = Search(system, props, handle_sigint=False, reduction=reduction).run("bfs")
    return system, reduction, outcome


def choices(monkeypatch: pytest.MonkeyPatch, path: Path) -> tuple[dict[Any, Any], int, Any]:
    """Per world key, the persistent set the last pass chose (None: all); the closures
    computed in the whole run; the outcome."""
    chosen: dict[Any, Any] = {}
    closures = [0]
    choose, closure = Reduction._choose, Reduction._closure

    def recording(self: Reduction, world: World, enabled: list[int]) -> list[int] | None:
        found = choose(self, world, enabled)
        chosen[(self.stats.restarts, world.key)] = None if found is None else tuple(found)
        return found

    def counting(self: Reduction, world: World, enabled: list[int]) -> list[int] | None:
        closures[0] += 1
        return closure(self, world, enabled)

    monkeypatch.setattr(Reduction, "_choose", recording)
    monkeypatch.setattr(Reduction, "_closure", counting)
    _, _, outcome = searched(path)
    return chosen, closures[0], outcome


@pytest.mark.parametrize("name", ["headon", "c2c"])
def test_persistent_sets_by_shape_are_the_sets_the_closure_chooses(monkeypatch, name):
    # Head-on has 55 shapes in its 242 closures: looked up by shape, the same set in every
    # world, the same graph, from about a quarter of the closures.
    path = LAUNCH / f"{name}.yaml"
    by_shape, computed, outcome = choices(monkeypatch, path)
    monkeypatch.setattr(reduction_module, "SHAPES_AFTER", 1 << 40)  # every world's closure
    by_closure, every, plain = choices(monkeypatch, path)
    assert by_shape == by_closure
    assert outcome.statistics.states == plain.statistics.states
    assert outcome.status == plain.status
    assert computed < every / 2


def walk_by_transitions(self: Reduction, world: World, rng: random.Random, limit: int) -> int:
    """A walk that builds every transition of each world's persistent set and picks one:
    what `Reduction._walk` did before it picked among (action, variant) pairs."""
    seen = {world.key}
    for steps in range(limit):
        live = [t for t in self.reduced(world, self.candidates(world)[0])
                if t.failure is None] if world.events else []
        if not live:
            return steps
        world = rng.choice(live).world
        if world.key in seen or self.properties.check_world(self.system, world):
            return steps + 1
        seen.add(world.key)
    return limit


@pytest.mark.parametrize(("path", "fewer"), [(LAUNCH / "headon.yaml", True), (STATION, False)])
def test_a_walk_builds_only_the_worlds_it_steps_to(monkeypatch, path, fewer):
    # Head-on's walk at its restart: 167 steps, 171 worlds built (one per step, 4 by a
    # pair check of the map server's commuting handler) against 199 when every transition
    # of a step was; the same steps, the same relation learned, the same search. The
    # station's walk has one transition per step either way.
    built = [0]
    walking = [False]
    walk_on = Reduction.walk_on

    def counting(build: Any) -> Any:  # each way a step builds its world
        def counted(self: System, *args: Any) -> Any:
            built[0] += walking[0]
            return build(self, *args)
        return counted

    def watched(self: Reduction, *args: Any) -> None:
        walking[0] = True
        walk_on(self, *args)
        walking[0] = False

    for name in ("_apply_run", "_apply_crash", "_apply_drop"):
        monkeypatch.setattr(System, name, counting(getattr(System, name)))
    monkeypatch.setattr(Reduction, "walk_on", watched)
    _, lean, outcome = searched(path)
    lean_built = built[0]
    built[0] = 0
    monkeypatch.setattr(Reduction, "_walk", walk_by_transitions)
    _, full, before = searched(path)
    assert lean.stats.probe_steps == full.stats.probe_steps > 0
    assert lean.learned_state() == full.learned_state()
    assert outcome.statistics.states == before.statistics.states
    assert lean.stats.probe_steps <= lean_built <= built[0]
    assert (lean_built < built[0]) is fewer


def test_a_restart_starts_from_the_initial_transitions_built_once(monkeypatch):
    # The station restarts once (its first level reduced a world); building its initial
    # transitions runs every start handler, once per search.
    built = [0]
    initial = System.initial

    def counted(self: System) -> Any:
        built[0] += 1
        return initial(self)

    monkeypatch.setattr(System, "initial", counted)
    _, reduction, _ = searched(STATION)
    assert reduction.stats.restarts == 1
    assert built[0] == 1


@pytest.mark.parametrize(("name", "restarts"), [("headon", 0), ("c2c", 1)])
def test_a_pass_that_reduced_nothing_learns_in_place(monkeypatch, name, restarts):
    # Every search's first level learns sends and, with nothing reduced yet (its initial
    # world has one event), restarted from scratch: now it learns in place, walks on from
    # the same worlds and goes on, to the same graph and trace, one restart fewer.
    path = LAUNCH / f"{name}.yaml"
    options = CheckOptions(reduction="por", reduce_from=0)
    in_place = check(path, options)
    monkeypatch.setattr(Reduction, "must_restart", lambda self: self.stale)  # as it was
    restarting = check(path, options)
    assert in_place.reduction_statistics is not None
    assert restarting.reduction_statistics is not None
    assert in_place.reduction_statistics["restarts"] == restarts
    assert restarting.reduction_statistics["restarts"] == restarts + 1
    assert in_place.statistics.states == restarting.statistics.states
    assert in_place.statistics.transitions == restarting.statistics.transitions
    assert in_place.status == restarting.status
    assert in_place.trace == restarting.trace
