"""`System`: a scenario compiled into initial worlds and a successor function.

The system owns one node object per scenario node, built by the scenario's
own `NodeConfig.instantiate()`. To run an event it sets the node's `state`
from the world's snapshot bytes, runs the handler through
`runtime.dispatch.run_handler` with a `Context` whose chooser is the
checker's, snapshots the state again and turns the recorded effects into
pending events (`Publish` → one delivery per subscriber, `Call` → a request to
the server or a "no server" `CallError` after the timeout, `After` → a timer,
a service's return value → a reply). Node code is never special-cased.

Initial worlds: every node's `initial_state()`, the first firing of each
`@every` timer at phase + period, then every `@on_start` handler run at t=0 in
scenario order, like Rebeca constructors: they are not transitions (R10) and
their effects are the initial pending events. If start handlers call
`ctx.choose`, each combination is a separate initial world.
"""

from __future__ import annotations

import pickle
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, final

from checker.choices import ChoiceMismatch, PrefixChooser
from checker.semantics import Semantics
from checker.world import (
    DELIVERY,
    PERIODIC,
    REPLY,
    REQUEST,
    START,
    TIMER,
    Event,
    World,
    sort_events,
)
from runtime.context import After, Call, Chooser, Context, Fail, Log, Publish
from runtime.dispatch import run_handler
from runtime.messages import CallError
from runtime.node import Node
from runtime.scenario import Scenario, ScenarioError
from runtime.snapshot import SnapshotError, restore, snapshot

if TYPE_CHECKING:
    from checker.properties import PropertySet

FAILURE = "handler failure"
DEBUG_STATE = "state outside self.state"


@final
@dataclass(frozen=True, slots=True)
class Failure:
    """A handler that failed: `ctx.fail`, an exception, or (debug) a stray mutation."""

    kind: str  # FAILURE or DEBUG_STATE
    node: str
    handler: str
    message: str
    traceback: str = ""

    def __str__(self) -> str:
        return f"{self.kind}: {self.node}.{self.handler}: {self.message}"


@final
@dataclass(frozen=True, slots=True)
class Step:
    """One transition's identity: the event index in the parent world and its choices."""

    event: int
    choices: tuple[int, ...] = ()
    options: tuple[int, ...] = ()


@final
@dataclass(slots=True)
class Transition:
    """The result of running one event variant (or the start handlers, for initial worlds)."""

    step: Step
    world: World
    event: Event
    failure: Failure | None = None
    logs: tuple[Log, ...] = ()


@final
class System:
    """Initial worlds and successors of a scenario under one set of message rules.

    Args:
        scenario: the parsed scenario.
        semantics: "ros" or "rebeca"; default the scenario's `semantics`.
        latency: (min, max) delivery delay branches; default `check.latency`.
        global_priority: rebeca's `@globalPriority`; default `check.global_priority`.
        debug_state: detect handlers that change node attributes other than `state`.
        monitors: property monitors (`checker.properties.PropertySet`) kept in worlds.
    """

    def __init__(self, scenario: Scenario, *, semantics: str | None = None,
                 latency: tuple[int, int] | None = None, global_priority: bool | None = None,
                 debug_state: bool = False, monitors: PropertySet | None = None) -> None:
        self.scenario = scenario
        self.nodes: tuple[Node, ...] = tuple(cfg.instantiate() for cfg in scenario.nodes)
        self.names: tuple[str, ...] = tuple(cfg.name for cfg in scenario.nodes)
        self.index = {name: i for i, name in enumerate(self.names)}
        check = scenario.check
        if latency is None:
            latency = _latency(scenario)
        if global_priority is None:
            global_priority = check.get("global_priority", False)
        try:
            self.semantics = Semantics(semantics or scenario.semantics,
                                       tuple(cfg.priority for cfg in scenario.nodes),
                                       bool(global_priority), latency)
        except ValueError as exc:
            raise ScenarioError(f"{scenario.path}: check: {exc}") from None
        self.debug_state = debug_state
        self.monitors = monitors
        self._current: list[bytes | None] = [None] * len(self.nodes)
        self._decoded: dict[bytes, Any] = {}
        self._compile_graph()

    def _compile_graph(self) -> None:
        self._subscribers: dict[str, list[tuple[int, str, int]]] = {}
        self._servers: dict[str, tuple[int, str, int]] = {}
        self._priorities: list[dict[str, int]] = []
        self._periods: dict[tuple[int, str], int] = {}
        self._initial_states = tuple(snapshot(node.initial_state()) for node in self.nodes)
        for i, node in enumerate(self.nodes):
            spec = node.spec()
            self._priorities.append({h.method: h.priority for h in spec.handlers})
            for h in spec.of_kind("subscribe"):
                topic = node.resolve(h.name or "")
                self._subscribers.setdefault(topic, []).append((i, h.method, h.priority))
            for h in spec.of_kind("service"):
                name = node.resolve(h.name or "")
                if name in self._servers:
                    other = self.names[self._servers[name][0]]
                    raise ScenarioError(f"{self.scenario.path}: nodes: service {name} is served "
                                        f"by both {other} and {self.names[i]}")
                self._servers[name] = (i, h.method, h.priority)
            for h in spec.of_kind("every"):
                self._periods[(i, h.method)] = node.period_ms(h)

    # ----------------------------------------------------------------- worlds

    def initial(self) -> list[Transition]:
        """Every initial world (one per combination of choices made by start handlers)."""
        result = []
        prefix: tuple[int, ...] | None = ()
        while prefix is not None:
            chooser = PrefixChooser(prefix)
            result.append(self._start(chooser))
            prefix = chooser.next_prefix()
        return result

    def initial_world(self, choices: Sequence[int] = ()) -> Transition:
        """Rebuild the initial world reached with the start-handler `choices`."""
        return self._start(PrefixChooser(choices))

    def _start(self, chooser: PrefixChooser) -> Transition:
        states = list(self._initial_states)
        pending: list[Event] = []
        for i, node in enumerate(self.nodes):
            for h in node.spec().of_kind("every"):
                period = self._periods[(i, h.method)]
                self.semantics.add(pending, Event(h.phase_ms + period, PERIODIC, i, h.method, i,
                                                  (), h.priority))
        failure, logs, event = None, [], Event(0, START, 0, "", -1, (), 0)
        for i, node in enumerate(self.nodes):
            for h in node.spec().of_kind("start"):
                event = Event(0, START, i, h.method, i, (), h.priority)
                failure = self._fire(states, pending, event, chooser, logs)
                if failure is not None:
                    break
            if failure is not None:
                break
        step = Step(-1, tuple(chooser.indices), tuple(chooser.options))
        world = self.make_world(0, tuple(states), pending, None)
        return Transition(step, world, event, failure, tuple(logs))

    def make_world(self, now: int, states: tuple[bytes, ...], pending: list[Event],
                   parent: World | None) -> World:
        """Build a world, updating the property monitors it carries."""
        events = sort_events(pending)
        monitors: tuple[str, ...] = ()
        if self.monitors is not None:
            monitors = self.monitors.update(self, parent, now, states, events)
        return World(now, states, events, monitors)

    def successors(self, world: World) -> Iterator[Transition]:
        """Every transition from `world`: each enabled event times each choice variant."""
        for index in self.semantics.enabled(world.events):
            prefix: tuple[int, ...] | None = ()
            while prefix is not None:
                chooser = PrefixChooser(prefix)
                yield self.run(world, index, chooser)
                prefix = chooser.next_prefix()

    def execute(self, world: World, step: Step) -> Transition:
        """Re-run one recorded step deterministically (used by traces and replay)."""
        return self.run(world, step.event, PrefixChooser(step.choices))

    def run(self, world: World, index: int, chooser: Chooser) -> Transition:
        """Run event `world.events[index]` with `chooser` answering its choice points."""
        ev = world.events[index]
        states = list(world.states)
        pending = self.semantics.remove(world.events, index)
        logs: list[Log] = []
        failure = self._fire(states, pending, ev, chooser, logs)
        step = Step(index, tuple(getattr(chooser, "indices", ())),
                    tuple(getattr(chooser, "options", ())))
        new = self.make_world(ev.due, tuple(states), pending, world)
        return Transition(step, new, ev, failure, tuple(logs))

    # ------------------------------------------------------------- handlers

    def _load(self, i: int, data: bytes) -> Node:
        node = self.nodes[i]
        current = self._current[i]
        if current is not data and current != data:
            node.state = restore(data)
            self._current[i] = data
        return node

    def _fire(self, states: list[bytes], pending: list[Event], ev: Event, chooser: Chooser,
              logs: list[Log]) -> Failure | None:
        """Run `ev`'s handler on `states`, adding its effects to `pending` (in place)."""
        i = ev.target
        old = states[i]
        node = self._load(i, old)
        before = _fingerprint(node) if self.debug_state else None
        ctx = Context(node, ev.due, chooser)
        self._current[i] = None  # the state object is about to change
        try:
            outcome = run_handler(node, ev.method, ctx, ev.args, expects_reply=ev.kind == REQUEST)
        except ChoiceMismatch as exc:
            return Failure(FAILURE, node.name, ev.method, f"nondeterministic choices: {exc}")
        if outcome.error is not None:
            return Failure(FAILURE, node.name, ev.method, outcome.error.message,
                           outcome.error.traceback)
        if before is not None:
            stray = _changed(before, _fingerprint(node))
            if stray:
                return Failure(DEBUG_STATE, node.name, ev.method,
                               f"handler changed attribute(s) {', '.join(stray)} outside self.state")
        try:
            new = snapshot(node.state)
        except SnapshotError as exc:
            return Failure(FAILURE, node.name, ev.method, f"state cannot be snapshot: {exc}")
        if new == old:
            new = old
        self._current[i] = new
        states[i] = new
        return self._apply(pending, ev, outcome.effects, outcome.reply, chooser, logs)

    def _apply(self, pending: list[Event], ev: Event, effects: Sequence[Any], reply: Any,
               chooser: Chooser, logs: list[Log]) -> Failure | None:
        i, now, add = ev.target, ev.due, self.semantics.add
        if ev.kind == PERIODIC:
            period = self._periods[(i, ev.method)]
            add(pending, Event(now + period, PERIODIC, i, ev.method, i, (), ev.priority))
        failure = None
        for eff in effects:
            match eff:
                case Publish(topic=topic, msg=msg):
                    for j, method, prio in self._subscribers.get(topic, ()):
                        due = self._message_due(now, chooser)
                        add(pending, Event(due, DELIVERY, j, method, i, (msg,), prio))
                case Call(service=service, request=req, reply_to=reply_to, timeout_ms=timeout):
                    server = self._servers.get(service)
                    if server is None:
                        err = CallError(service, "no server")
                        add(pending, Event(now + timeout, TIMER, i, reply_to, i, (err,),
                                           self.priority(i, reply_to)))
                    else:
                        j, method, prio = server
                        add(pending, Event(self._message_due(now, chooser), REQUEST, j, method, i,
                                           (req,), prio, reply_to))
                case After(delay_ms=delay, handler=method, args=args):
                    add(pending, Event(now + delay, TIMER, i, method, i, args,
                                       self.priority(i, method)))
                case Fail(reason=reason):
                    failure = failure or Failure(FAILURE, self.names[i], ev.method,
                                                 f"ctx.fail: {reason}")
                case Log():
                    logs.append(eff)
        if ev.kind == REQUEST:
            add(pending, Event(self._message_due(now, chooser), REPLY, ev.sender, ev.reply_to, i,
                               (reply,), self.priority(ev.sender, ev.reply_to)))
        return failure

    def _message_due(self, now: int, chooser: Chooser) -> int:
        n = self.semantics.latency_options
        return self.semantics.message_due(now, chooser.choose(n) if n > 1 else 0)

    def priority(self, node: int, method: str) -> int:
        """Handler priority of `method` on node index `node` (0 if undeclared)."""
        return self._priorities[node].get(method, 0)

    # -------------------------------------------------------------- reading

    def decode(self, i: int, data: bytes) -> Any:
        """The state object of node `i` encoded as `data` (cached; treat it as read-only)."""
        value = self._decoded.get(data)
        if value is None:
            if len(self._decoded) > 50_000:
                self._decoded.clear()
            value = self._decoded[data] = restore(data)
        return value

    def states_of(self, world: World) -> dict[str, Any]:
        """Fresh decoded state objects of every node, by name."""
        return {name: restore(data) for name, data in zip(self.names, world.states, strict=True)}


def _latency(scenario: Scenario) -> tuple[int, int] | None:
    raw = scenario.check.get("latency")
    if raw is None:
        return None
    if (not isinstance(raw, list | tuple) or len(raw) != 2
            or not all(isinstance(v, int) and not isinstance(v, bool) for v in raw)):
        raise ScenarioError(f"{scenario.path}: check.latency: expected [min, max] in ms, got {raw!r}")
    return None if tuple(raw) == (0, 0) else (raw[0], raw[1])


def _fingerprint(node: Node) -> dict[str, bytes]:
    out = {}
    for attr, value in vars(node).items():
        if attr == "state" or getattr(value, "pure_memo", False):
            continue  # a declared memo of a pure function may fill up: that is not state
        try:
            out[attr] = snapshot(value)
        except (SnapshotError, TypeError, ValueError):
            try:
                out[attr] = pickle.dumps(value)
            except Exception:  # unpicklable configuration: compare by repr
                out[attr] = repr(value).encode()
    return out


def _changed(before: dict[str, bytes], after: dict[str, bytes]) -> list[str]:
    return sorted(k for k in before.keys() | after.keys() if before.get(k) != after.get(k))
