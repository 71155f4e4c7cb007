"""Checks and fleets inside pytest: `twinfleet.testing`.

Build a system from node classes and properties in Python (no YAML), check it,
and run it live over Zenoh, from a test::

    from twinfleet import testing

    def test_no_two_robots_in_the_cell():
        system = testing.system({"keeper": Keeper, "r1": (Walker, {"cell": 1}),
                                 "r2": (Walker, {"cell": 1})},
                                [testing.invariant("one_inside", "keeper.inside <= 1")])
        result = testing.check(system)
        assert result.holds, result.explain()

`check` returns a `CheckReport`: the verdict (`holds`, `violated`, `breach`),
the counts, and on a violation the trace, which `save_trace` writes so that
`twinfleet replay FILE` re-executes it (a system built in Python is written
beside it as a scenario file, so its node classes must be importable by module
path: defined at the top level of a module, not inside a test function).

`live_fleet` (an async context manager) and `run_live` (its synchronous
wrapper, for plain pytest) start the real fleet: an embedded Zenoh router on
``tcp/127.0.0.1:<free port>``, multicast scouting off, one OS process per
node. The test gets a `LiveFleet` to wait for messages and publish; the
processes are stopped when the test ends, whether it passes or fails.

This module sits on top of every layer, beside the command line.
"""

from __future__ import annotations

import asyncio
import builtins
import json
from collections.abc import AsyncIterator, Awaitable, Callable, Mapping, Sequence
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO, final

from twinfleet.checker.diagnosis import ContractBreachError
from twinfleet.checker.driver import CheckOptions, CheckResult
from twinfleet.checker.driver import check as _check
from twinfleet.robots import EXAMPLES
from twinfleet.runtime.contract.kinds import Status
from twinfleet.runtime.contract.messages import DecodeError, decode, encode
from twinfleet.runtime.contract.node import QOS_DEFAULT, Node
from twinfleet.runtime.contract.tracefile import write_trace
from twinfleet.runtime.fleet.launcher import FleetResult, LaunchOptions, run_fleet
from twinfleet.runtime.host.keys import topic_key
from twinfleet.runtime.scenario.examples import add_examples
from twinfleet.runtime.scenario.scenario_file import write_scenario
from twinfleet.runtime.scenario.spec import NodeEntry, PropertyConfig, Scenario

__all__ = ["CheckReport", "LiveFleet", "check", "eventually", "invariant", "live_fleet",
           "no_failure", "run_live", "system", "within"]

# ------------------------------------------------------------------ building


add_examples(EXAMPLES)  # the robots' scenarios, by name here as on the command line


def invariant(name: str, expr: str) -> PropertyConfig:
    """A property that holds in every reachable world (`expr` over node states by name)."""
    return PropertyConfig(name, "invariant", expr)


def eventually(name: str, expr: str) -> PropertyConfig:
    """A liveness property: every run reaches a world where `expr` holds."""
    return PropertyConfig(name, "eventually", expr)


def within(name: str, expr: str, ms: int) -> PropertyConfig:
    """`expr` holds within `ms` logical milliseconds on every run."""
    return PropertyConfig(name, "within", expr, ms)


def no_failure(name: str = "no_failure") -> PropertyConfig:
    """No handler calls `ctx.fail` or raises (always checked; name it to report it so)."""
    return PropertyConfig(name, "no_failure")


NodeSpecs = Mapping[str, type[Node] | tuple[type[Node], Any]] | Sequence[NodeEntry]


def system(nodes: NodeSpecs, properties: Sequence[PropertyConfig | Mapping[str, Any]] = (), *,
           name: str = "system", **settings: Any) -> Scenario:
    """A scenario from Python values.

    Args:
        nodes: ``{name: NodeClass}`` or ``{name: (NodeClass, params)}`` (params a mapping or
            a ``NodeClass.Params`` instance), in start order; or `NodeEntry` values (for a
            namespace or a node priority).
        properties: `invariant(...)`, `eventually(...)`, ... or YAML-shaped mappings.
        name: the scenario's (and the live fleet's) name.
        settings: the other keywords of `Scenario.build` (``check={"latency": ...}``,
            ``semantics="rebeca"``, ``live={"timeout_s": 10}``, ``params={...}``, ...).
    """
    if isinstance(nodes, Mapping):
        entries = [NodeEntry(n, *(spec if isinstance(spec, tuple) else (spec,)))
                   for n, spec in nodes.items()]
    else:
        entries = list(nodes)
    return Scenario.build(name, entries, properties=list(properties), **settings)


# ------------------------------------------------------------------ checking


@final
@dataclass
class CheckReport:
    """What `check` found.

    Attributes:
        verdict: a `Status` (a string enum): "holds", "violated", "unknown" (a limit
            stopped the search) or "contract breach" (a node breaks the node contract:
            no verdict).
        property: the violated property's name (None unless violated).
        message: what was violated, or the breach's one-line diagnosis.
        states, transitions: distinct worlds and steps explored.
        elapsed_s: search time.
        trace: the counterexample (`twinfleet-trace/1`), or None.
        warnings: load-time lint warnings (`runtime.scenario.lint`).
        result: the checker's full `CheckResult` (None for a breach found at load).
    """

    verdict: Status
    property: str | None
    message: str
    states: int = 0
    transitions: int = 0
    elapsed_s: float = 0.0
    trace: dict[str, Any] | None = None
    warnings: list[str] = field(default_factory=list)
    result: CheckResult | None = None
    scenario: Scenario | None = None

    @builtins.property  # the class has a field named `property`
    def holds(self) -> bool:
        """True when every property holds (exhaustively)."""
        return self.verdict is Status.HOLDS

    @builtins.property
    def violated(self) -> bool:
        """True when a property is violated (then `trace` shows how)."""
        return self.verdict is Status.VIOLATED

    @builtins.property
    def breach(self) -> bool:
        """True when a node breaks the node contract (`message` says where and how)."""
        return self.verdict is Status.BREACH

    def explain(self) -> str:
        """The verdict, the counts and, on a violation, every step of the trace."""
        head = (f"{self.verdict}: {self.message} ({self.states:,} states, "
                f"{self.transitions:,} transitions, {self.elapsed_s:.3f} s)")
        lines = [head, *self.warnings]
        if self.trace is not None:
            lines += ["trace:", *_steps(self.trace)]
        return "\n".join(lines)

    def save_trace(self, path: str | Path) -> Path:
        """Write the trace where `twinfleet replay` re-executes it; return its path.

        A system built in Python is written beside it first (``<path>.scenario.yaml``)."""
        if self.trace is None:
            raise ValueError(f"no trace to save: the verdict is {self.verdict}")
        trace, path = dict(self.trace), Path(path)
        if trace.get("scenario") is None:
            assert self.scenario is not None
            written = write_scenario(self.scenario, path.with_name(path.name + ".scenario.yaml"))
            trace["scenario"] = str(Path(str(written.path)).resolve())
        write_trace(trace, str(path))
        return path


def _steps(trace: Mapping[str, Any]) -> list[str]:
    out = [f"  0  t=0  initial: {json.dumps(trace['initial']['states'])}"]
    for s in trace["steps"]:
        changed = f"  -> {json.dumps(s['changed'])}" if s["changed"] else ""
        out.append(f"  {s['index']}  t={s['time']}  {s['node']}.{s['handler']} ({s['kind']} "
                   f"from {s['sender']}{', ' + s['args'] if s['args'] else ''}){changed}")
    return out


def check(scenario: Scenario | str | Path, **options: Any) -> CheckReport:
    """Check a system (or a scenario file): every interleaving, every choice.

    `options` are `twinfleet.checker.CheckOptions` fields (``search="dfs"``,
    ``max_states=...``, ``semantics=...``, ``verify=False``, ...; ``params=["r1.speed:=0.4"]``
    overrides parameters as `twinfleet launch` does); no trace file is written (use
    `CheckReport.save_trace`)."""
    options.setdefault("trace_out", None)
    options["params"] = tuple(options.get("params", ()))
    built = scenario if isinstance(scenario, Scenario) else None
    try:
        result = _check(scenario, CheckOptions(**options))
    except ContractBreachError as exc:  # an initial state that cannot be encoded
        return CheckReport(Status.BREACH, None, str(exc), scenario=built)
    s = result.statistics
    violation = result.violation
    message = (result.breach or (violation.message if violation else "") or
               ("every property holds" if result.status is Status.HOLDS else result.reason))
    return CheckReport(result.status, violation.property if violation else None, message,
                       s.states, s.transitions, s.elapsed_s, result.trace, result.warnings,
                       result, built)


# ------------------------------------------------------------------ live


@final
class LiveFleet:
    """A running fleet, as a test sees it (from `live_fleet` / `run_live`).

    Attributes:
        name: the fleet's name (its Zenoh key prefix is ``twinfleet/<name>``).
        endpoint: the router's endpoint (``tcp/127.0.0.1:<port>``).
        result: how the run ended (`FleetResult`), once the `live_fleet` block is left.
    """

    def __init__(self, fleet: Any) -> None:
        self._fleet = fleet
        self.name: str = fleet.scenario.fleet
        self.endpoint: str = fleet.endpoint
        self.result: FleetResult | None = None
        self._heard: dict[str, list[Any]] = {}
        self._waiters: dict[str, list[tuple[Callable[[Any], bool], asyncio.Future[Any]]]] = {}

    @property
    def pids(self) -> dict[str, int]:
        """The process id of every running node, by node name."""
        return {name: p.proc.pid for name, p in self._fleet.processes.items()
                if p.proc is not None}

    def watch(self, topic: str) -> list[Any]:
        """Start collecting the messages published on `topic` (absolute name); the list
        fills as they arrive."""
        if topic not in self._heard:
            self._heard[topic] = []
            self._waiters[topic] = []
            self._fleet.transport.subscribe(topic_key(self.name, topic), self._deliver(topic),
                                            QOS_DEFAULT)
        return self._heard[topic]

    def _deliver(self, topic: str) -> Callable[[str, bytes], None]:
        def deliver(_key: str, payload: bytes) -> None:
            try:
                msg = decode(payload).msg
            except DecodeError:
                return
            self._heard[topic].append(msg)
            waiting = self._waiters[topic]
            for item in [w for w in waiting if not w[1].done() and w[0](msg)]:
                item[1].set_result(msg)
                waiting.remove(item)
        return deliver

    async def message(self, topic: str, where: Callable[[Any], bool] = lambda m: True, *,
                      timeout_s: float = 10.0) -> Any:
        """The first message on `topic` satisfying `where`, among those already collected
        (`watch`) and those to come; TimeoutError after `timeout_s` wall seconds, and
        RuntimeError if the fleet ends first."""
        for msg in self.watch(topic):
            if where(msg):
                return msg
        found: asyncio.Future[Any] = asyncio.get_running_loop().create_future()
        self._waiters[topic].append((where, found))
        ended = asyncio.ensure_future(asyncio.shield(self._fleet.ended))
        done, _ = await asyncio.wait({found, ended}, timeout=timeout_s,
                                     return_when=asyncio.FIRST_COMPLETED)
        ended.cancel()
        if found in done:
            return found.result()
        found.cancel()
        if ended in done:
            raise RuntimeError(f"fleet {self.name} ended ({ended.result().detail}) before a message "
                               f"on {topic} came")
        raise TimeoutError(f"no matching message on {topic} within {timeout_s:g} s "
                           f"({len(self._heard[topic])} others arrived)")

    async def ended(self) -> str:
        """Wait until the run ends by itself; why it ended, in words."""
        return (await asyncio.shield(self._fleet.ended)).detail

    def publish(self, topic: str, msg: Any) -> None:
        """Publish `msg` on `topic` (absolute name) into the fleet, as node "test"."""
        self._fleet.transport.put(topic_key(self.name, topic), encode(msg, sender="test"),
                                  QOS_DEFAULT)


@asynccontextmanager
async def live_fleet(scenario: Scenario | str | Path, *, time_scale: float = 1.0,
                     timeout_s: float = 60.0, seed: int | None = None,
                     out: TextIO | None = None,
                     params: Sequence[str] = ()) -> AsyncIterator[LiveFleet]:
    """Run the fleet of `scenario` while the block runs; stop it when the block ends
    (normally or by an exception: the processes are stopped either way).

    `timeout_s` bounds the whole run (wall seconds); lines of the launcher go to `out`
    (default: stdout, which pytest captures and shows on failure); `params` are parameter
    overrides of a scenario file, as `twinfleet launch` takes them (``"r1.speed:=0.4"``)."""
    from twinfleet.runtime.scenario.property_fields import check_property_fields

    if not isinstance(scenario, Scenario):
        from twinfleet.runtime.scenario.overrides import load_with_params

        scenario = load_with_params(scenario, params)
    elif params:
        raise ValueError("params override a scenario file; a system built in Python takes "
                         "its parameters when it is built")
    check_property_fields(scenario)  # a misspelt field fails before any process starts
    loop = asyncio.get_running_loop()
    ready: asyncio.Future[LiveFleet] = loop.create_future()
    finished = asyncio.Event()

    async def driver(fleet: Any) -> str:
        await _every_node_alive(fleet, timeout_s)
        ready.set_result(LiveFleet(fleet))
        await finished.wait()
        return "the test finished"

    options = LaunchOptions(time_scale=time_scale, timeout_s=timeout_s, seed=seed,
                            handle_signals=False, params=tuple(params))
    output = {} if out is None else {"out": out}  # else run_fleet's own default
    runner = asyncio.create_task(run_fleet(scenario, options, driver=driver, **output))
    waited: set[asyncio.Future[Any]] = {ready, runner}
    await asyncio.wait(waited, return_when=asyncio.FIRST_COMPLETED)
    if not ready.done():
        result = await runner  # re-raises a launcher error
        raise RuntimeError(f"fleet {scenario.fleet} ended before the test began: {result.reason}")
    handle = ready.result()
    try:
        yield handle
    finally:
        finished.set()
        handle.result = await runner


async def _every_node_alive(fleet: Any, timeout_s: float) -> None:
    """Wait until every node's liveliness token is up (its handlers are declared: the
    launcher's `Fleet.all_alive`), so that a test starts with the whole fleet running;
    RuntimeError naming the missing."""
    try:
        await asyncio.wait_for(fleet.all_alive.wait(), timeout_s)
    except TimeoutError:
        raise RuntimeError(f"nodes {', '.join(sorted(fleet.unseen))} did not start within "
                           f"{timeout_s:g} s") from None


def run_live(scenario: Scenario | str | Path,
             test: Callable[[LiveFleet], Awaitable[None]] | None = None,
             **options: Any) -> FleetResult:
    """Run the fleet, await ``test(fleet)`` (if given; else until the run ends by itself:
    its timeout, a shutdown request or a failed node), stop it, and return how it ended.
    `options` are those of `live_fleet`."""
    async def main() -> FleetResult:
        async with live_fleet(scenario, **options) as fleet:
            if test is not None:
                await test(fleet)
            else:
                await fleet.ended()
        assert fleet.result is not None
        return fleet.result

    return asyncio.run(main())

