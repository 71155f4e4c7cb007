"""`twinfleet check --statistical`: how likely a violation is, from independent simulations.

Simulations (`checker.simulate`) run in rounds of `ROUND` indices; each round
is cut into slices for the engine's workers (`checker.parallel`) and its
results come back in index order. After each round the stopping rule reads
the results as a prefix in index order: `--assert-below P` feeds Wald's SPRT
one simulation at a time and stops at the first index where it decides (later
results of the round are dropped); `--precision H` stops once every property's
Clopper–Pearson interval is at most 2H wide; otherwise the run stops after
`--simulations N`. So the answer depends on (scenario, model, seed, options)
and never on the number of workers. A violating simulation is written as a
trace (`twinfleet replay` re-takes its drawn latencies: the model's bounds are
the System's latency ranges and the trace records them), the lowest indices
first, at most `max_traces`.
"""

from __future__ import annotations

import platform
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, final

from twinfleet.checker.driver import load
from twinfleet.checker.estimate import Decision, Sprt, clopper_pearson
from twinfleet.checker.parallel import Engine, engine_for, split
from twinfleet.checker.properties import PropertySet
from twinfleet.checker.simulate import Simulation, Simulator
from twinfleet.checker.system import System
from twinfleet.checker.timing import DEFAULT_MODEL, AssumedTiming, TimingModel, load_timing
from twinfleet.checker.trace import build_trace
from twinfleet.runtime.contract.kinds import (
    EXIT_BAD_INPUT,
    EXIT_FAILED,
    EXIT_INTERRUPTED,
    EXIT_OK,
)
from twinfleet.runtime.contract.tracefile import write_trace
from twinfleet.runtime.scenario.spec import Scenario, resolve_scenario

ROUND = 64  # simulations per round: the stopping rule's granularity, whatever the workers
ANY = "any property"


@final
@dataclass(frozen=True)
class StatisticalOptions:
    """How to estimate (see the module docstring and `twinfleet check --help`)."""

    simulations: int | None = None
    seed: int | None = None
    horizon_ms: int | None = None
    max_steps: int = 1_000_000
    confidence: float = 0.95
    precision: float | None = None
    assert_below: float | None = None
    indifference: float | None = None
    alpha: float = 0.01
    beta: float = 0.01
    workers: int = 1
    cluster: str | None = None  # a Ray cluster address: simulations run as Ray tasks there
    timing: str | None = None
    traces_out: str = "out"
    max_traces: int = 3
    max_time_s: float | None = None
    verify: bool = True
    semantics: str | None = None
    params: tuple[str, ...] = ()  # parameter overrides, as `check` and `launch` take them
    until_decided: bool = False
    progress: Callable[[StatisticalResult], None] | None = field(default=None, compare=False)


@final
@dataclass(frozen=True)
class SimulationJob:
    """What a worker needs to run simulations: picklable, builds its `Simulator` once."""

    scenario: str
    semantics: str | None
    model: TimingModel
    seed: int
    horizon_ms: int
    max_steps: int
    verify: bool = True
    until_decided: bool = False
    params: tuple[str, ...] = ()

    def __call__(self, indices: list[int]) -> list[Simulation]:
        return _simulator(self).batch(indices)


# The simulator of the job this process runs now: built by the job's first batch here and
# reused by its later ones (its kept handler runs are most of a simulation's speed), replaced
# by another job's, and dropped when the statistical check that made it ends (`release`).
_HELD: list[tuple[SimulationJob, Simulator]] = []


def _simulator(job: SimulationJob) -> Simulator:
    if _HELD and (_HELD[0][0] is job or _HELD[0][0] == job):
        return _HELD[0][1]
    _HELD.clear()  # first: the old job's System goes before the new one is built
    scenario = load(job.scenario, semantics=job.semantics, params=job.params)
    system, props = timed_system(scenario, job.model, verify=job.verify)
    sim = Simulator(system, props, job.model, seed=job.seed, horizon_ms=job.horizon_ms,
                    max_steps=job.max_steps, until_decided=job.until_decided)
    _HELD.append((job, sim))
    return sim


def release(job: SimulationJob) -> None:
    """Drop this process's simulator of `job`, if it holds one (the check is over)."""
    if _HELD and _HELD[0][0] == job:
        _HELD.clear()


def timed_system(scenario: Scenario, model: TimingModel, *,
                 verify: bool = True) -> tuple[System, PropertySet]:
    """The scenario's `System` with the model's bounds as its latency ranges and its timer
    lateness (`verify`: the node-contract checks of every handler run, `checker.diagnosis`)."""
    props = PropertySet.from_scenario(scenario)
    probe = System(scenario, properties=props)
    channels = set(probe.topology.subscribers) | set(probe.topology.servers)
    default, per = model.ranges(channels)
    return System(scenario, latency=default, topic_latency=per,
                  timer_lateness=model.timer_lateness.bounds, properties=props,
                  verify=verify, keyed=False), props


@final
@dataclass(frozen=True)
class Estimate:
    """One property's violations in `n` simulations and its interval."""

    name: str
    violations: int
    n: int
    low: float
    high: float

    @property
    def p(self) -> float:
        """The point estimate."""
        return self.violations / self.n if self.n else 0.0


@final
@dataclass
class StatisticalResult:
    """What a statistical check found (and, while running, has found so far)."""

    scenario: str
    model: str
    horizon_ms: int
    confidence: float
    workers: int
    simulations: list[Simulation] = field(default_factory=list)
    names: list[str] = field(default_factory=list)
    sprt: Sprt | None = None
    elapsed_s: float = 0.0
    traces: list[str] = field(default_factory=list)
    stopped: str = ""
    timing: AssumedTiming | None = None
    replaced: str = ""  # said first: the model that replaced the scenario's timing, and why
    params: tuple[str, ...] = ()
    interrupted: bool = False

    def estimates(self) -> list[Estimate]:
        """Per property (then any property) its count and Clopper-Pearson interval."""
        n = len(self.simulations)
        names = [*self.names, *sorted({v for s in self.simulations for v in s.violated}
                                      - set(self.names)), ANY]
        out = []
        for name in names:
            k = sum(1 for s in self.simulations if s.violated and (
                name == ANY or name in s.violated))
            out.append(Estimate(name, k, n, *clopper_pearson(k, n, self.confidence)))
        return out

    @property
    def decision(self) -> Decision | None:
        """The SPRT's decision, if one was asked for."""
        return None if self.sprt is None else self.sprt.decision

    @property
    def exit_code(self) -> int:
        """0: below / no violation seen; 1: not below / a violation seen; 2: undecided;
        130: interrupted (the estimate so far is still reported)."""
        if self.interrupted:
            return EXIT_INTERRUPTED
        if self.sprt is not None:
            return {Decision.BELOW: EXIT_OK, Decision.NOT_BELOW: EXIT_FAILED}.get(
                self.sprt.decision, EXIT_BAD_INPUT)
        return EXIT_FAILED if any(s.violated for s in self.simulations) else EXIT_OK

    def summary(self) -> str:
        """The report `twinfleet check --statistical` prints."""
        n = len(self.simulations)
        rate = n / self.elapsed_s if self.elapsed_s else 0.0
        with_ = f" with {' '.join(self.params)}" if self.params else ""
        lines = [f"timing: {self.replaced}"] if self.replaced else []
        lines += [f"statistical check of {self.scenario}{with_}: {n:,} simulations to "
                  f"{self.horizon_ms / 1000:g} s of fleet time, {self.elapsed_s:.1f} s on "
                  f"{self.workers} worker(s) ({rate:,.1f} simulations/s; {self.stopped})",
                  f"timing: {self.model}",
                  *([f"  assumed: {self.timing.line()}"] if self.timing is not None else []),
                 f"P(violation within the horizon), {self.confidence:.0%} Clopper-Pearson:"]
        for e in self.estimates():
            lines.append(f"  {e.name:<24} {e.violations:>6} / {n:<6} {e.p:.4f} "
                         f"[{e.low:.4f}, {e.high:.4f}]")
        if self.sprt is not None:
            s = self.sprt
            lines.append(f"SPRT P(violation) < {s.bound:g} (indifference {s.indifference:g}, "
                         f"alpha {s.alpha:g}, beta {s.beta:g}): {s.decision.value} after "
                         f"{s.n:,} simulations ({s.k} violating)")
        for path in self.traces:
            lines.append(f"violating simulation: twinfleet replay {path}")
        return "\n".join(lines)

    def to_json(self) -> dict[str, Any]:
        """The result as JSON-ready data."""
        return {"scenario": self.scenario, "model": self.model, "horizon_ms": self.horizon_ms,
                "simulations": len(self.simulations), "elapsed_s": self.elapsed_s,
                "workers": self.workers, "confidence": self.confidence,
                "estimates": [{"property": e.name, "violations": e.violations, "n": e.n,
                               "p": e.p, "low": e.low, "high": e.high}
                              for e in self.estimates()],
                "sprt": None if self.sprt is None else {
                    "bound": self.sprt.bound, "decision": self.sprt.decision.value,
                    "n": self.sprt.n, "violations": self.sprt.k},
                "traces": self.traces, "stopped": self.stopped,
                "timing": None if self.timing is None else self.timing.to_json(),
                "timing_replaced": self.replaced or None, "params": list(self.params),
                "interrupted": self.interrupted}


def check_statistical(scenario: str | Path, options: StatisticalOptions) -> StatisticalResult:
    """Estimate (or test) the probability of a violation of `scenario` (module docstring)."""
    path = resolve_scenario(scenario)
    spec = load(path, semantics=options.semantics, params=options.params)
    model, source, replaced = statistical_timing(spec, options.timing)
    horizon = options.horizon_ms or int(1000 * (spec.live.horizon_s or 60))
    seed = options.seed if options.seed is not None else spec.seed
    job = SimulationJob(str(path.resolve()), options.semantics, model, seed,
                        horizon, options.max_steps, options.verify, options.until_decided,
                        options.params)
    sim = _simulator(job)  # here too: it writes the traces, and a bad scenario fails early
    result = StatisticalResult(spec.source, model.describe(), horizon, options.confidence,
                               options.workers, names=_names(sim.properties),
                               timing=model.assumed(source), replaced=replaced,
                               params=options.params)
    if options.assert_below is not None:
        result.sprt = Sprt(options.assert_below,
                           options.indifference or options.assert_below / 2,
                           options.alpha, options.beta)
    limit = options.simulations or (1000 if result.sprt is None and options.precision is None
                                    else 10_000_000)
    engine = engine_for(options.workers, options.cluster)
    try:
        _rounds(engine, job, result, options, limit)
    except KeyboardInterrupt:  # Ctrl-C, or SIGTERM (twinfleet.cli): keep the estimate so far
        result.interrupted = True
        result.stopped = "interrupted"
    finally:
        engine.close()
        release(job)  # this process's; `sim` itself stays for the traces
    result.stopped = result.stopped or f"{limit:,} simulations"
    result.traces = _write_traces(sim, result, path, options)
    return result


def _rounds(engine: Engine, job: SimulationJob, result: StatisticalResult,
            options: StatisticalOptions, limit: int) -> None:
    """Run rounds on `engine` into `result` until the stopping rule or `limit` says stop.
    With several workers and only `limit` to stop the run, the next round is sent before
    the current one's results are read (a second thread waits for it): a worker done with
    its part of a round starts on the next instead of waiting for the others; any other
    stopping rule may end the run at any round, so rounds go one at a time there."""
    start = time.perf_counter()
    ahead = engine.workers > 1 and result.sprt is None and options.precision is None \
        and options.max_time_s is None

    def send(first: int) -> Callable[[], list[list[Simulation]]]:
        """The round from index `first`: its results when called (sent now if ahead)."""
        batches = split(range(first, min(first + ROUND, limit)), engine.workers)
        if waiting is None:
            return lambda: engine.map(job, batches)
        return waiting.submit(engine.map, job, batches).result

    waiting = ThreadPoolExecutor(2) if ahead else None
    try:
        pending = send(0)
        while True:
            first = len(result.simulations) + ROUND
            following = send(first) if ahead and first < limit else None
            _take(result, [s for b in pending() for s in b], options)
            result.elapsed_s = time.perf_counter() - start
            if options.max_time_s is not None and result.elapsed_s >= options.max_time_s:
                result.stopped = result.stopped or f"--max-time {options.max_time_s:g} s"
            if options.progress is not None:
                options.progress(result)
            if len(result.simulations) >= limit or result.stopped:
                return
            pending = following or send(len(result.simulations))
    finally:  # not waiting: on Ctrl-C a round still running ends with the engine's close
        if waiting is not None:
            waiting.shutdown(wait=False, cancel_futures=True)


def statistical_timing(scenario: Scenario, timing: str | None) -> tuple[TimingModel, str, str]:
    """The model simulations draw from, where it comes from, and (said first) what replaced
    the scenario's timing: `timing` if given; else the scenario's `check.latency`, each
    value of a range equally likely, as the exhaustive check branches on every value;
    else (no latency at all would make every delivery a tie) the loopback model."""
    if timing is not None:
        return load_timing(timing), f"--timing {timing}", ""
    latency = scenario.check.latency
    if latency:
        origin = "the scenario's check.latency"
        return (TimingModel.from_ranges(latency.default, latency.names, origin), origin, "")
    source = f"the loopback model shipped with twinfleet ({DEFAULT_MODEL})"
    return (load_timing(None), source, f"{source} replaces the scenario's timing (it sets no "
            "check.latency, so the exhaustive check delivers every message when sent); "
            "give --timing FILE or check.latency to choose")


def _names(props: PropertySet) -> list[str]:
    names = [p.name for p in props.all]
    return names if any(p.kind == "no_failure" for p in props.all) else [*names, "no_failure"]


def _take(result: StatisticalResult, done: list[Simulation], options: StatisticalOptions) -> None:
    """Append a round's results (index order) and apply the stopping rule to the prefix."""
    sprt = result.sprt
    if sprt is not None:
        for k, s in enumerate(done):
            if sprt.add(bool(s.violated)) is not Decision.UNDECIDED:
                result.simulations += done[:k + 1]
                result.stopped = f"SPRT decided: {sprt.decision.value}"
                return
        result.simulations += done
        return
    result.simulations += done
    if options.precision is not None and all(
            (e.high - e.low) / 2 <= options.precision for e in result.estimates()):
        result.stopped = f"every interval within +-{options.precision:g}"


def _write_traces(sim: Simulator, result: StatisticalResult, path: Path,
                  options: StatisticalOptions) -> list[str]:
    out: list[str] = []
    for s in result.simulations:
        if len(out) >= options.max_traces:
            break
        if s.first is None or not s.replayable:
            continue
        violation, cex = s.first
        trace = build_trace(sim.system, violation, cex, scenario_path=str(path.resolve()),
                            search="statistical", params=list(options.params))
        trace["simulation"] = {"index": s.index, "seed": sim.seed,
                               "machine": platform.machine()}
        where = str(Path(options.traces_out) / f"{path.stem}.sim{s.index}.trace.json")
        write_trace(trace, where)
        out.append(where)
    return out
