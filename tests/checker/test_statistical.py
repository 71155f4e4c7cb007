"""Statistical checking: estimators on systems with known probabilities, SPRT error rates,
the same answers with 1 or 2 workers, and c2a's violating simulations replayed."""

from __future__ import annotations

import random
import subprocess
import sys
from pathlib import Path

import pytest

from tests.checker.smc_systems import Coin4, Nested, Receiver, Sender
from tests.checker.tpc import tpc_scenario
from twinfleet import testing
from twinfleet.checker.estimate import Decision, Sprt, clopper_pearson
from twinfleet.checker.properties import PropertySet
from twinfleet.checker.simulate import Simulation, Simulator
from twinfleet.checker.statistical import StatisticalOptions, check_statistical
from twinfleet.checker.system import System
from twinfleet.checker.timing import Histogram, TimingModel
from twinfleet.cli import main

COIN = TimingModel(Histogram((0, 1), (0.5, 0.5)))  # two latencies, equally likely


def _systems() -> list[tuple[str, System, PropertySet, float]]:
    cases = [("coin4", {"c": Coin4}, "c.pick != 3", 0.25),
             ("nested", {"c": Nested}, "c.pick != 0", 1 / 6),
             ("latency", {"a": Sender, "b": Sender, "r": Receiver}, "r.times != [1, 1]", 0.25)]
    out = []
    for name, nodes, expr, p in cases:
        scenario = testing.system(nodes, [testing.invariant("ok", expr)], name=name)
        props = PropertySet.from_scenario(scenario)
        latency = (0, 1) if name == "latency" else None
        out.append((name, System(scenario, properties=props, latency=latency), props, p))
    return out


@pytest.mark.parametrize("case", range(3), ids=["coin4", "nested", "latency"])
def test_the_interval_covers_the_true_probability_at_its_nominal_rate(case: int) -> None:
    name, system, props, p = _systems()[case]
    seeds, n = range(20), 80  # fixed: a derandomized test
    covered = 0
    for seed in seeds:
        sim = Simulator(system, props, COIN, seed=seed, horizon_ms=100, max_steps=100)
        k = sum(1 for i in range(n) if sim.run(i).violated)
        low, high = clopper_pearson(k, n, 0.95)
        covered += low <= p <= high
    assert covered / len(seeds) >= 0.95, (name, covered)


def test_a_known_probability_is_estimated_closely() -> None:
    _, system, props, p = _systems()[2]
    sim = Simulator(system, props, COIN, seed=5, horizon_ms=100, max_steps=100)
    k = sum(1 for i in range(2000) if sim.run(i).violated)
    low, high = clopper_pearson(k, 2000, 0.99)
    assert low <= p <= high and high - low < 0.06


def _sprt_errors(p: float, accept_is_error: bool, runs: int = 1000) -> tuple[int, int]:
    errors = 0
    for seed in range(runs):
        rng, test = random.Random(seed), Sprt(0.1, 0.05, alpha=0.05, beta=0.05)
        while test.add(rng.random() < p) is Decision.UNDECIDED:
            pass
        errors += (test.decision is Decision.BELOW) == accept_is_error
    return errors, runs


def test_sprt_error_rates_are_within_alpha_and_beta() -> None:
    # An error rate above nominal would put the 99 % interval of the observed rate above it.
    for p, accept_is_error in ((0.10, True), (0.05, False)):  # alpha: wrong sign-off; beta
        errors, runs = _sprt_errors(p, accept_is_error)
        assert clopper_pearson(errors, runs, 0.99)[0] <= 0.05, (p, errors, runs)
        assert errors / runs <= 0.05 / (1 - 0.05) + 0.02  # Wald's bound, with sampling slack


SCENARIO = """\
name: coin
nodes:
  - {name: a, class: "smc_systems:Sender"}
  - {name: b, class: "smc_systems:Sender"}
  - {name: r, class: "smc_systems:Receiver"}
  - {name: c, class: "smc_systems:Coin4"}
properties:
  - {name: late_pair, kind: invariant, expr: "r.times != [1, 1]"}
  - {name: three, kind: invariant, expr: "c.pick != 3"}
"""


def _scenario(tmp_path: Path) -> Path:
    (tmp_path / "smc_systems.py").write_text(
        (Path(__file__).parent / "smc_systems.py").read_text())
    (tmp_path / "coin.yaml").write_text(SCENARIO)
    (tmp_path / "timing.yaml").write_text(
        "format: twinfleet-timing/1\nlatency:\n  default: {values: [0, 1], weights: [0.5, 0.5]}\n")
    return tmp_path / "coin.yaml"


def test_same_seed_one_or_two_workers_give_identical_estimates(tmp_path: Path) -> None:
    path = _scenario(tmp_path)
    runs = [check_statistical(path, StatisticalOptions(
        simulations=300, seed=11, workers=w, timing=str(tmp_path / "timing.yaml"),
        traces_out=str(tmp_path / f"out{w}"))) for w in (1, 2)]
    assert runs[0].estimates() == runs[1].estimates()
    assert [s.violated for s in runs[0].simulations] == [s.violated for s in runs[1].simulations]
    sprt = [check_statistical(path, StatisticalOptions(
        seed=3, workers=w, assert_below=0.3, indifference=0.2, alpha=0.05, beta=0.05,
        timing=str(tmp_path / "timing.yaml"), traces_out=str(tmp_path / "sprt")))
        for w in (1, 2)]
    assert sprt[0].sprt is not None and sprt[1].sprt is not None
    assert (sprt[0].sprt.n, sprt[0].decision) == (sprt[1].sprt.n, sprt[1].decision)
    assert sprt[0].decision is Decision.NOT_BELOW  # P(some violation) = 1 - 3/4 * 3/4


def test_violating_simulations_replay(tmp_path: Path) -> None:
    path = _scenario(tmp_path)
    result = check_statistical(path, StatisticalOptions(
        simulations=50, seed=1, timing=str(tmp_path / "timing.yaml"),
        traces_out=str(tmp_path / "out"), max_traces=2))
    assert result.exit_code == 1 and len(result.traces) == 2
    for trace in result.traces:
        done = subprocess.run([sys.executable, "-m", "twinfleet", "replay", trace],
                              capture_output=True, text=True, timeout=60, cwd=tmp_path)
        assert done.returncode == 1, done.stdout + done.stderr


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_c2a_statistical_gives_an_interval_and_traces_that_replay(tmp_path: Path) -> None:
    run = subprocess.run([sys.executable, "-m", "twinfleet", "check", "c2a", "--statistical",
                          "--simulations", "3", "--horizon-ms", "20000", "--quiet",
                          "--traces-out", str(tmp_path), "--max-traces", "1"],
                         capture_output=True, text=True, timeout=280, cwd=tmp_path)
    assert run.returncode == 1, run.stdout + run.stderr
    assert "no_collision" in run.stdout and "Clopper-Pearson" in run.stdout
    (trace,) = tmp_path.glob("c2a.sim*.trace.json")
    done = subprocess.run([sys.executable, "-m", "twinfleet", "replay", str(trace)],
                          capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert done.returncode == 1 and "replay confirmed: no_collision" in done.stdout


def _key(s: Simulation) -> tuple[object, ...]:
    return (s.violated, s.steps, s.end_ms, s.ended, s.first)


@pytest.mark.parametrize("case", range(3), ids=["coin4", "nested", "latency"])
def test_kept_handler_runs_give_the_same_simulations(case: int) -> None:
    _, system, props, _ = _systems()[case]
    runs = [[Simulator(system, props, COIN, seed=9, horizon_ms=100, max_steps=100,
                       reuse=reuse).run(i) for i in range(60)] for reuse in (False, True)]
    assert [_key(s) for s in runs[0]] == [_key(s) for s in runs[1]]


def test_kept_handler_runs_on_a_robot_fleet_are_reused_and_give_the_same_simulations() -> None:
    from twinfleet.checker.driver import load
    from twinfleet.checker.statistical import timed_system
    from twinfleet.checker.timing import default_timing

    spec = load(Path(__file__).resolve().parents[2] / "twinfleet" / "launch" / "headon.yaml")
    out, handler_runs = [], []
    for reuse in (False, True):
        system, props = timed_system(spec, default_timing(), verify=True)
        sim = Simulator(system, props, default_timing(), seed=4, horizon_ms=6000,
                        max_steps=10_000, reuse=reuse)
        out.append([_key(sim.run(i)) for i in range(3)])
        handler_runs.append(system.runner.handler_runs)
    assert out[0] == out[1]
    assert handler_runs[1] < handler_runs[0] / 2  # most steps reuse a kept run


def test_the_progress_line_shows_the_final_tables_interval(tmp_path, capsys):
    path = tpc_scenario(tmp_path, decision_timeout_ms=3, latency=(0, 2))
    main(["check", str(path), "--statistical", "--simulations", "200", "--seed", "3",
          "--max-traces", "0"])
    captured = capsys.readouterr()
    last = [ln for ln in captured.err.splitlines() if ln.startswith("[check]")][-1]
    interval = last.split(" P ")[1].split("]")[0].split(" ", 1)[1] + "]"
    table = [ln for ln in captured.out.splitlines() if ln.strip().startswith("any property")]
    assert table and interval in table[0], (last, table)
