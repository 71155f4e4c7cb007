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

Speed. A handler's outcome depends only on the node's state, the event and
the time (that is the node contract, which replay relies on too), so the
system runs each (node state, event, time) once and keeps every choice
variant's outcome — new node state and new events — in a cache: the
interleavings of independent nodes repeat the same local steps many times
(C1a: 128,800 transitions, 5,595 distinct handler runs). Entries are keyed by
absolute time, so the search drops those older than its frontier's earliest
t* (`forget_before`), which no world left to expand can use; and whatever
the search order it keeps at most two generations of 1,024 outcomes
(`checker.cache.GenerationCache`): a breadth-first frontier can span a wide
range of times, and outcomes not used for a generation are rarely used again. Equal node states
are interned to one bytes object, hashed once (`World.key`). The cache is off
under `debug_state` and `check_determinism`, which must really run every
transition; `transition_cache=False` turns it off for comparison.

Faults, deadlines and latency follow `checker.faults`; crash transitions are
listed after the event transitions of a world.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterator, Sequence
from typing import TYPE_CHECKING, Any, final

from twinfleet.checker.cache import GenerationCache
from twinfleet.checker.choices import ChoiceMismatch, Chooser, PrefixChooser
from twinfleet.checker.faults import DROP, DUPLICATE, parse_settings
from twinfleet.checker.semantics import Semantics
from twinfleet.checker.transition import (
    CAUSES,
    DEADLINE,
    DEBUG_STATE,
    FAILURE,
    NONDETERMINISM,
    Failure,
    Step,
    Transition,
    Variant,
    changed_attributes,
    difference,
    fingerprint,
)
from twinfleet.checker.world import (
    CRASH,
    DELIVERY,
    ENVIRONMENT,
    PERIODIC,
    REPLY,
    REQUEST,
    START,
    TIMER,
    Event,
    World,
    fast_key,
    sort_events,
    world_digest,
)
from twinfleet.runtime.context import After, Call, Context, Fail, Log, Publish
from twinfleet.runtime.dispatch import run_handler
from twinfleet.runtime.messages import CallError
from twinfleet.runtime.node import Node
from twinfleet.runtime.scenario import Scenario, ScenarioError
from twinfleet.runtime.snapshot import SnapshotError, restore, snapshot

__all__ = ["DEADLINE", "DEBUG_STATE", "FAILURE", "NONDETERMINISM", "Failure", "Step",
           "System", "Transition", "Variant"]

_CACHE_LIMIT = 100_000  # interned node states / content hashes kept before starting afresh
_MEMO_LIMIT = 1_024  # handler outcomes per cache generation (two kept; ~0.55 KB each on C1b)
_DECODED_LIMIT = 64  # decoded states kept for property expressions (~2.5 KB each on C1a)

if TYPE_CHECKING:
    from twinfleet.checker.properties import PropertySet


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
        exact_states: key worlds by their 128-bit digest (`World.digest`).
        check_determinism: run every transition twice and report a difference.
        transition_cache: reuse handler outcomes (see the module docstring).
    """

    def __init__(self, scenario: Scenario, *, semantics: str | None = None,
                 latency: tuple[int, int] | None = None, global_priority: bool | None = None,
                 debug_state: bool = False, monitors: PropertySet | None = None,
                 exact_states: bool = False, check_determinism: bool = False,
                 transition_cache: bool = True) -> None:
        self.scenario = scenario
        self.nodes: tuple[Node, ...] = tuple(cfg.instantiate() for cfg in scenario.nodes)
        self.names: tuple[str, ...] = tuple(cfg.name for cfg in scenario.nodes)
        self.index = {name: i for i, name in enumerate(self.names)}
        self._compile_graph()
        self.settings = parse_settings(scenario, set(self._subscribers), set(self._servers),
                                       latency=() if latency is None else latency)
        if global_priority is None:
            global_priority = scenario.check.global_priority
        try:
            self.semantics = Semantics(semantics or scenario.semantics,
                                       tuple(cfg.priority for cfg in scenario.nodes),
                                       bool(global_priority), self.settings.latency,
                                       self.settings.topic_latency)
        except ValueError as exc:
            raise ScenarioError(f"{scenario.source}: check: {exc}") from None
        self.crash = self.settings.crash
        self.debug_state = debug_state
        self.check_determinism = check_determinism
        self.exact_states = exact_states
        self.monitors = monitors
        self._memo: GenerationCache[list[Variant]] | None = (
            GenerationCache(_MEMO_LIMIT)
            if transition_cache and not debug_state and not check_determinism else None)
        self._current: list[bytes | None] = [None] * len(self.nodes)
        self._decoded: dict[bytes, Any] = {}
        self._canon: dict[bytes, bytes] = {}
        self._hashes: dict[bytes, bytes] = {}
        self.hashed = 0  # content hashes computed (node states, events): for the collision bound
        self.handler_runs = 0  # handlers actually run (the rest came from the cache)

    def _compile_graph(self) -> None:
        self._subscribers: dict[str, list[tuple[int, str, int]]] = {}
        self._servers: dict[str, tuple[int, str, int]] = {}
        self._service_of: dict[tuple[int, str], str] = {}
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
                self._service_of[(i, h.method)] = name
            for h in spec.of_kind("every"):
                self._periods[(i, h.method)] = node.period_ms(h)

    # ----------------------------------------------------------------- worlds

    def initial(self) -> list[Transition]:
        """Every initial world (one per combination of choices made by start handlers)."""
        result = []
        prefix: tuple[int, ...] | None = ()
        while prefix is not None:
            chooser = PrefixChooser(prefix)
            t = self._start(chooser)
            if self.check_determinism and t.failure is None:
                t = self._recheck_start(t)
            result.append(t)
            prefix = chooser.next_prefix()
        return result

    def initial_world(self, choices: Sequence[int] = (), *,
                      chooser: Chooser | None = None) -> Transition:
        """Rebuild the initial world reached with the start-handler `choices` (or `chooser`)."""
        return self._start(chooser if chooser is not None else PrefixChooser(choices))

    def _start(self, chooser: Chooser) -> Transition:
        states = list(self._initial_states)
        pending: list[Event] = []
        for i in range(len(self.nodes)):
            for ev in self._periodic(i, 0):
                self.semantics.add(pending, ev)
        failure, logs, faults, branches = None, [], [], []
        event = Event(0, START, 0, "", -1, (), 0)
        for i, node in enumerate(self.nodes):
            for h in node.spec().of_kind("start"):
                event = Event(0, START, i, h.method, i, (), h.priority)
                v = self._exec(i, states[i], event, chooser)
                states[i] = v.state
                logs += v.logs
                faults += v.faults
                branches += v.branches  # positions in the shared chooser
                for ev in v.events:
                    self.semantics.add(pending, ev)
                failure = v.failure
                if failure is not None:
                    break
            if failure is not None:
                break
        step = Step(-1, tuple(chooser.indices), tuple(chooser.options))
        world = self.make_world(0, tuple(states), pending, None)
        return Transition(step, world, event, failure, tuple(logs), tuple(faults), tuple(branches))

    def _recheck_start(self, t: Transition) -> Transition:
        self._current = [None] * len(self.nodes)
        again = self._start(PrefixChooser(t.step.choices))
        if again.world.digest == t.world.digest and again.step == t.step:
            return t
        failure = Failure(NONDETERMINISM, "", "on_start", "running the start handlers twice "
                          "gave different initial worlds" + CAUSES)
        return Transition(t.step, t.world, t.event, failure, t.logs, t.faults)

    def _periodic(self, i: int, now: int) -> Iterator[Event]:
        for h in self.nodes[i].spec().of_kind("every"):
            yield Event(now + h.phase_ms + self._periods[(i, h.method)], PERIODIC, i, h.method,
                        i, (), h.priority)

    def make_world(self, now: int, states: tuple[bytes, ...], pending: list[Event],
                   parent: World | None, crashes: int = 0) -> World:
        """Build a world, updating the property monitors it carries."""
        events = sort_events(pending)
        monitors: tuple[str, ...] = ()
        if self.monitors is not None:
            monitors = self.monitors.update(self, parent, now, states, events)
        if self.exact_states:
            digest = world_digest(states, events, monitors, crashes)
            return World(now, states, events, monitors, crashes=crashes, key=digest,
                         digest=digest)
        hashes = self._hashes
        parts = []
        for s in states:
            h = hashes.get(s)
            parts.append(h if h is not None else self._hash_state(s))
        return World(now, states, events, monitors, crashes=crashes,
                     key=fast_key(parts, events, monitors, crashes))

    def _hash_state(self, data: bytes) -> bytes:
        if len(self._hashes) >= _CACHE_LIMIT:
            self._hashes.clear()
        h = self._hashes[data] = hashlib.blake2b(data, digest_size=8).digest()
        self.hashed += 1
        return h

    def _intern(self, data: bytes) -> bytes:
        """The one bytes object kept for this node-state encoding."""
        canon = self._canon.get(data)
        if canon is None:
            if len(self._canon) >= _CACHE_LIMIT:
                self._canon.clear()
            canon = self._canon[data] = data
        return canon

    # ------------------------------------------------------------ successors

    def successors(self, world: World) -> Iterator[Transition]:
        """Every transition from `world`: each enabled event times each choice variant,
        then each crash fault."""
        events = world.events
        states = world.states
        for index in self.semantics.enabled(events):
            ev = events[index]
            if ev.sk[3]:
                yield self._deadline_miss(world, index)
                continue
            for v in self._variants(states[ev.target], ev):
                yield self._build(world, index, v)
        crash = self.crash
        if crash is not None and events and world.crashes < crash.max:
            for j in crash.nodes:
                for v in self._crash_variants(world, j):
                    yield self._build_crash(world, j, v)

    def actions(self, world: World) -> list[int | tuple[str, int]]:
        """What may happen next: enabled event indices, then ("crash", node) faults."""
        acts: list[int | tuple[str, int]] = list(self.semantics.enabled(world.events))
        crash = self.crash
        if crash is not None and world.events and world.crashes < crash.max:
            acts += [(CRASH, j) for j in crash.nodes]
        return acts

    def take(self, world: World, action: int | tuple[str, int], chooser: Chooser) -> Transition:
        """Run one action of `actions(world)` with `chooser` answering its choice points."""
        if isinstance(action, tuple):
            return self._build_crash(world, action[1], self._restart(world, action[1], chooser))
        return self.run(world, action, chooser)

    def execute(self, world: World, step: Step) -> Transition:
        """Re-run one recorded step deterministically (used by traces and replay)."""
        if step.crash:
            variants = [self._restart(world, step.event, PrefixChooser(step.choices))]
            if self.check_determinism:
                variants = self._checked_restarts(world, step.event, variants)
            return self._build_crash(world, step.event, variants[0])
        return self.run(world, step.event, PrefixChooser(step.choices))

    def run(self, world: World, index: int, chooser: Chooser) -> Transition:
        """Run event `world.events[index]` with `chooser` answering its choice points."""
        ev = world.events[index]
        if ev.sk[3]:
            return self._deadline_miss(world, index)
        data = world.states[ev.target]
        v = self._exec(ev.target, data, ev, chooser)
        if self.check_determinism:
            v = self._recheck(data, ev, v)
        return self._build(world, index, v)

    def _variants(self, data: bytes, ev: Event) -> list[Variant]:
        """Every choice variant of running `ev` on node state `data` (cached)."""
        memo = self._memo
        mk = (data, ev.key, ev.due)  # time last (see forget_before)
        if memo is not None:
            found = memo.get(mk)
            if found is not None:
                return found
        variants = []
        prefix: tuple[int, ...] | None = ()
        while prefix is not None:
            chooser = PrefixChooser(prefix)
            v = self._exec(ev.target, data, ev, chooser)
            if self.check_determinism:
                v = self._recheck(data, ev, v)
            variants.append(v)
            prefix = chooser.next_prefix()
        if memo is not None:
            memo.put(mk, variants)
        return variants

    def _build(self, world: World, index: int, v: Variant) -> Transition:
        ev = world.events[index]
        pending = self.semantics.remove(world.events, index)
        add = self.semantics.add
        for e in v.events:
            add(pending, e)
        states = world.states
        i = ev.target
        if v.state is not states[i]:
            states = (*states[:i], v.state, *states[i + 1:])
        new = self.make_world(ev.due, states, pending, world, world.crashes)
        return Transition(Step(index, v.choices, v.options), new, ev, v.failure, v.logs, v.faults,
                          v.branches)

    def _deadline_miss(self, world: World, index: int) -> Transition:
        ev = world.events[index]
        sender = "environment" if ev.sender == ENVIRONMENT else self.names[ev.sender]
        message = (f"{ev.kind} from {sender} to {self.names[ev.target]}.{ev.method} is handled "
                   f"at t={ev.due} ms, {ev.due - (ev.deadline or 0)} ms after its deadline "
                   f"t={ev.deadline} ms")
        failure = Failure(DEADLINE, self.names[ev.target], ev.method, message)
        return self._build(world, index, Variant((), (), world.states[ev.target], (), failure))

    # ---------------------------------------------------------------- crashes

    def _crash_variants(self, world: World, j: int) -> list[Variant]:
        now = world.events[0].due
        durable = j in self.crash.durable if self.crash else False
        data = world.states[j] if durable else self._initial_states[j]
        memo = self._memo
        mk = (CRASH, j, data, now)  # time last, like event entries (see forget_before)
        found = None if memo is None else memo.get(mk)
        if found is not None:
            return found
        variants = []
        prefix: tuple[int, ...] | None = ()
        while prefix is not None:
            chooser = PrefixChooser(prefix)
            variants.append(self._restart(world, j, chooser))
            prefix = chooser.next_prefix()
        if self.check_determinism:
            variants = self._checked_restarts(world, j, variants)
        if memo is not None:
            memo.put(mk, variants)
        return variants

    def _checked_restarts(self, world: World, j: int, variants: list[Variant]) -> list[Variant]:
        checked = []
        for v in variants:
            self._current[j] = None
            diff = difference(v, self._restart(world, j, PrefixChooser(v.choices)))
            if diff is not None:
                failure = Failure(NONDETERMINISM, self.names[j], "on_start",
                                  f"restarting it twice gave different results: {diff}" + CAUSES)
                v = Variant(v.choices, v.options, v.state, (), failure, v.logs, v.faults)
            checked.append(v)
        return checked

    def _restart(self, world: World, j: int, chooser: Chooser) -> Variant:
        """Node `j` after a crash at t*: reset (unless durable), timers re-armed, started."""
        assert self.crash is not None
        now = world.events[0].due
        data = world.states[j] if j in self.crash.durable else self._initial_states[j]
        events = list(self._periodic(j, now))
        failure, logs, faults = None, [], []
        for h in self.nodes[j].spec().of_kind("start"):
            v = self._exec(j, data, Event(now, START, j, h.method, j, (), h.priority), chooser)
            data, failure = v.state, v.failure
            events += v.events
            logs += v.logs
            faults += v.faults
            if failure is not None:
                break
        return Variant(tuple(getattr(chooser, "indices", ())), tuple(getattr(chooser, "options", ())),
                       data, tuple(events), failure, tuple(logs), tuple(faults))

    def _build_crash(self, world: World, j: int, v: Variant) -> Transition:
        now = world.events[0].due
        pending = [e for e in world.events if e.target != j]
        for e in v.events:
            self.semantics.add(pending, e)
        states = (*world.states[:j], v.state, *world.states[j + 1:])
        new = self.make_world(now, states, pending, world, world.crashes + 1)
        assert self.crash is not None
        kept = "state kept (durable)" if j in self.crash.durable else "state reset"
        note = f"{self.names[j]} crashed and restarted: pending events lost, {kept}"
        label = Event(now, CRASH, j, "", ENVIRONMENT, (), 0)
        return Transition(Step(j, v.choices, v.options, crash=True), new, label, v.failure,
                          v.logs, (note, *v.faults))

    # ------------------------------------------------------------- handlers

    def _load(self, i: int, data: bytes) -> Node:
        node = self.nodes[i]
        current = self._current[i]
        if current is not data and current != data:
            node.state = restore(data)
            self._current[i] = data
        return node

    def _exec(self, i: int, data: bytes, ev: Event, chooser: Chooser) -> Variant:
        """Run `ev`'s handler on node state `data`: its new state, new events and failure."""
        node = self._load(i, data)
        self.handler_runs += 1
        before = fingerprint(node) if self.debug_state else None
        ctx = Context(node, ev.due, chooser)
        self._current[i] = None  # the state object is about to change
        try:
            outcome = run_handler(node, ev.method, ctx, ev.args, expects_reply=ev.kind == REQUEST)
        except ChoiceMismatch as exc:
            return self._failed(chooser, data, FAILURE, node.name, ev.method,
                                f"nondeterministic choices: {exc}")
        if outcome.error is not None:
            return self._failed(chooser, data, FAILURE, node.name, ev.method,
                                outcome.error.message, outcome.error.traceback)
        if before is not None:
            stray = changed_attributes(before, fingerprint(node))
            if stray:
                return self._failed(chooser, data, DEBUG_STATE, node.name, ev.method,
                                    f"handler changed attribute(s) {', '.join(stray)} outside "
                                    "self.state")
        try:
            new = snapshot(node.state)
        except SnapshotError as exc:
            return self._failed(chooser, data, FAILURE, node.name, ev.method,
                                f"state cannot be snapshot: {exc}")
        new = data if new == data else self._intern(new)
        self._current[i] = new
        handler_end = len(getattr(chooser, "indices", ()))
        events, failure, logs, faults = self._effects(ev, outcome.effects, outcome.reply, chooser)
        indices = tuple(getattr(chooser, "indices", ()))
        return Variant(indices, tuple(getattr(chooser, "options", ())), new, tuple(events),
                       failure, tuple(logs), tuple(faults), tuple(range(handler_end, len(indices))))

    @staticmethod
    def _failed(chooser: Chooser, data: bytes, kind: str, node: str, method: str, message: str,
                traceback: str = "") -> Variant:
        return Variant(tuple(getattr(chooser, "indices", ())), tuple(getattr(chooser, "options", ())),
                       data, (), Failure(kind, node, method, message, traceback))

    def _effects(self, ev: Event, effects: Sequence[Any], reply: Any, chooser: Chooser
                 ) -> tuple[list[Event], Failure | None, list[Log], list[str]]:
        """The events a handler's effects create, in order (the rules of one transition)."""
        i, now = ev.target, ev.due
        out: list[Event] = []
        faults: list[str] = []
        logs: list[Log] = []
        if ev.kind == PERIODIC:
            out.append(Event(now + self._periods[(i, ev.method)], PERIODIC, i, ev.method, i, (),
                             ev.priority))
        failure = None
        for eff in effects:
            match eff:
                case Publish(topic=topic, msg=msg):
                    for j, method, prio in self._subscribers.get(topic, ()):
                        copies = self._copies(topic, j, chooser, faults)
                        for _ in range(copies):
                            out.append(self._message(now, topic, DELIVERY, j, method, i, (msg,),
                                                     prio, "", chooser))
                case Call(service=service, request=req, reply_to=reply_to, timeout_ms=timeout):
                    server = self._servers.get(service)
                    lost = server is not None and self._copies(service, server[0], chooser,
                                                               faults) == 0
                    if server is None or lost:
                        err = CallError(service, "timeout" if lost else "no server")
                        out.append(Event(now + timeout, TIMER, i, reply_to, i, (err,),
                                         self.priority(i, reply_to)))
                    else:
                        j, method, prio = server
                        out.append(self._message(now, service, REQUEST, j, method, i, (req,),
                                                 prio, reply_to, chooser))
                case After(delay_ms=delay, handler=method, args=args):
                    out.append(Event(now + delay, TIMER, i, method, i, args,
                                     self.priority(i, method)))
                case Fail(reason=reason):
                    failure = failure or Failure(FAILURE, self.names[i], ev.method,
                                                 f"ctx.fail: {reason}")
                case Log():
                    logs.append(eff)
        if ev.kind == REQUEST:
            service = self._service_of.get((i, ev.method), "")
            out.append(self._message(now, service, REPLY, ev.sender, ev.reply_to, i, (reply,),
                                     self.priority(ev.sender, ev.reply_to), "", chooser))
        self.hashed += len(out)
        return out, failure, logs, faults

    def _copies(self, name: str, j: int, chooser: Chooser, faults: list[str]) -> int:
        """How many copies of one message on `name` to node `j` arrive (fault branches)."""
        options = self.settings.delivery_options(name)
        if len(options) == 1:
            return 1
        pick = options[chooser.branch(len(options))]
        if pick == DROP:
            faults.append(f"{name} to {self.names[j]}: dropped")
            return 0
        if pick == DUPLICATE:
            faults.append(f"{name} to {self.names[j]}: duplicated")
            return 2
        return 1

    def _message(self, now: int, name: str, kind: str, target: int, method: str, sender: int,
                 args: tuple[Any, ...], priority: int, reply_to: str, chooser: Chooser) -> Event:
        """A message on topic/service `name`, with its latency branch and deadline."""
        due = now
        span = self.semantics.latency_range(name)
        if span is not None:
            low, high = span
            due = now + low + (chooser.branch(high - low + 1) if high > low else 0)
        limit = self.settings.deadline_for(name) if self.settings.has_deadlines else None
        return Event(due, kind, target, method, sender, args, priority, reply_to,
                     deadline=None if limit is None else now + limit)

    def _recheck(self, data: bytes, ev: Event, first: Variant) -> Variant:
        """`first` if running `ev` again from `data` with the same choices agrees, else a failure."""
        self._current[ev.target] = None  # restore the node state from the bytes again
        second = self._exec(ev.target, data, ev, PrefixChooser(first.choices))
        diff = difference(first, second)
        if diff is None:
            return first
        failure = Failure(NONDETERMINISM, self.names[ev.target], ev.method,
                          f"running it twice from the same state gave different results: {diff}"
                          + CAUSES)
        return Variant(first.choices, first.options, data, (), failure, first.logs, first.faults)

    def priority(self, node: int, method: str) -> int:
        """Handler priority of `method` on node index `node` (0 if undeclared)."""
        return self._priorities[node].get(method, 0)

    # -------------------------------------------------------------- reading

    def decode(self, i: int, data: bytes) -> Any:
        """The state object of node `i` encoded as `data` (cached; treat it as read-only)."""
        value = self._decoded.get(data)
        if value is None:
            # Small on purpose: property results are cached by state (checker.properties),
            # so decoding happens once per new combination; decoded states are large.
            if len(self._decoded) >= _DECODED_LIMIT:
                self._decoded.clear()
            value = self._decoded[data] = restore(data)
        return value

    def states_of(self, world: World) -> dict[str, Any]:
        """Fresh decoded state objects of every node, by name."""
        return {name: restore(data) for name, data in zip(self.names, world.states, strict=True)}

    def forget_before(self, time_ms: int) -> int:
        """Drop cached handler outcomes of events due before `time_ms`; return how many.

        A search calls this with the smallest t* of its frontier: every world it will
        still expand runs events at or after that time, so nothing dropped could be
        used again.
        """
        return 0 if self._memo is None else self._memo.forget_before(time_ms)

    def cache_sizes(self) -> dict[str, int]:
        """Entries in the system's caches (transition outcomes, interned states, hashes)."""
        return {"handler_runs": self.handler_runs, "cached_outcomes": len(self._memo or {}),
                "interned_states": len(self._canon),
                "state_hashes": len(self._hashes), "decoded": len(self._decoded)}
