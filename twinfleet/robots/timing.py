"""Logical arrival times from the checker, and how far live runs drift from them.

`predicted_arrivals` walks one path of the checker's `System` (seeded random
choices among the enabled events and `ctx.choose` options, exactly what
`checker.search`'s random walks do) until every robot's state says `done`,
and returns each robot's logical arrival time. In the checker every node
starts at t = 0; live, each robot starts when its process has seen every peer,
so a live run is compared per robot from its own start (`LiveRunResult.durations_ms`).
"""

from __future__ import annotations

import random
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, final

from twinfleet.checker.choices import RandomChooser
from twinfleet.checker.driver import load
from twinfleet.checker.system import System
from twinfleet.nodes.map_server import MapServerParams
from twinfleet.nodes.robot import RobotParams
from twinfleet.runtime.scenario.spec import Scenario


def robot_names(scenario: Scenario) -> tuple[str, ...]:
    """The robots the map server tracks (its `robots` parameter), else ()."""
    server = map_server(scenario)
    return () if server is None else tuple(server.robots)


def map_server(scenario: Scenario) -> MapServerParams | None:
    """The parameters of the scenario's map server, if it has one."""
    return next((cfg.params for cfg in scenario.nodes
                 if isinstance(cfg.params, MapServerParams)), None)


def robot_profile(scenario: Scenario) -> str:
    """The behaviour profile of the scenario's robots (the first robot's; "" without one)."""
    return next((cfg.params.profile for cfg in scenario.nodes
                 if isinstance(cfg.params, RobotParams)), "")


@final
@dataclass(frozen=True, slots=True)
class Prediction:
    """One checker path: per robot its logical arrival time (None: not within the walk)."""

    seed: int
    steps: int
    arrival_ms: Mapping[str, int | None]


def predicted_arrivals(path: str | Path, *, seed: int = 0, semantics: str | None = None,
                       params: Sequence[str] = (), max_steps: int = 200_000,
                       horizon_ms: int = 180_000) -> Prediction:
    """Arrival times on one seeded random path of the checker's transition relation.

    Args:
        path: scenario file.
        seed: seed of the walk's choices.
        semantics: an override of the scenario's; params: parameter overrides
            (``profile=rebeca``).
        max_steps: give up after this many transitions,
        horizon_ms: or once logical time passes this (robots that never arrive keep the
            scan loop going for ever).
    """
    scenario = load(path, semantics=semantics, params=params)
    system = System(scenario)
    robots = {system.index[name]: name for name in robot_names(scenario)}
    rng = random.Random(seed)
    world = rng.choice(system.initial()).world
    arrival: dict[str, int | None] = dict.fromkeys(robots.values())
    steps = 0
    while (world.events and steps < max_steps and world.now <= horizon_ms
           and None in arrival.values()):
        t = system.step(world, rng.choice(system.actions(world)), RandomChooser(rng))
        world, steps = t.world, steps + 1
        i = t.event.target
        name = robots.get(i)
        if (name is not None and arrival[name] is None
                and getattr(system.decode(i, world.states[i]), "done", False)):
            arrival[name] = world.now
    return Prediction(seed, steps, arrival)


def arrival_errors(durations_ms: Mapping[str, int | None],
                   predicted: Mapping[str, int | None]) -> dict[str, int]:
    """Per robot live duration minus predicted arrival, for robots known in both."""
    return {name: d - p for name, d in durations_ms.items()
            if d is not None and (p := predicted.get(name)) is not None}


@final
@dataclass(frozen=True, slots=True)
class DriftSummary:
    """|Δ arrival| statistics over several runs."""

    runs: int
    samples: int
    mean_abs_ms: float
    max_abs_ms: int
    mean_signed_ms: float


def summarise(errors: Iterable[Mapping[str, int]], runs: int) -> DriftSummary:
    """Mean and max of |Δ| over every robot of every run (and the mean signed Δ)."""
    values = [v for per_run in errors for v in per_run.values()]
    if not values:
        return DriftSummary(runs, 0, float("nan"), 0, float("nan"))
    return DriftSummary(runs, len(values), sum(abs(v) for v in values) / len(values),
                        max(abs(v) for v in values), sum(values) / len(values))


def describe(prediction: Prediction) -> dict[str, Any]:
    """A JSON-ready view of a prediction."""
    return {"seed": prediction.seed, "steps": prediction.steps,
            "arrival_ms": dict(prediction.arrival_ms)}
