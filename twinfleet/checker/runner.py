"""Running one handler of one node on a snapshot state: its new state and new events.

`Runner.run` sets the node's `state` from the world's snapshot bytes, runs the
handler through `runtime.contract.dispatch.run_handler` with a `Context` whose chooser
is the checker's, snapshots the state again and turns the recorded effects
into pending events (`Publish` → one delivery per subscriber, `Call` → a
request to the server, or a TIMEOUT carrying a `CallError` after the call's
timeout when there is no server or the request is lost, `After` → a timer, a
service's return value → a reply, unless the handler deferred it (`Defer`): a
`Reply` effect of a later handler makes that reply event), with the latency, deadline and fault
branches of `checker.semantics` (Rule 5). Node code is never special-cased.
The result is a `checker.transition.Variant`, independent of the world, so
the system can cache it.

Every run is verified (`checker.diagnosis`): clocks and random sources are
probed, the node's other attributes compared by identity, the module and class
variables of its code watched, and the handler is run a second time from the same state with the same answers; a difference is
a contract breach. The system caches outcomes, so only new runs are verified.

`Runner.run_kept` is `run` reusing kept handler runs (a search's outcomes, with the
system's outcome cache on, and a simulation's draws): a handler that made no
`ctx.choose` is run once per (node state, event) — and per time too if it read
`ctx.now()` — and its recorded effects are kept; a later run of the same key turns
the kept effects into events again with the chooser's answers (latency and fault
branches are answered there, after the handler, and only set the due times and
copies of the messages it sent). The same answers are taken in the same order as a
real run would take them, so results do not depend on the cache, and a run is
verified once, when it is new: by the node contract its outcome is a function of
that key (c1a_rebeca: 3,193 of 5,513 runs repeated an earlier one at another time,
none of them reading the clock). `run` always runs: a trace's replay must.

Equal node states are interned to one bytes object; the node object keeps
the last state it was given, so running several events of one node in a row
restores nothing.
"""

from __future__ import annotations

import contextlib
import re
from collections.abc import Sequence
from typing import Any, final

from twinfleet.checker.breaches import Breaches
from twinfleet.checker.cache import GenerationCache
from twinfleet.checker.choices import ChoiceMismatch, ExploringChooser, PrefixChooser
from twinfleet.checker.diagnosis import (
    CONTRACT_KINDS,
    FIX_ENCODABLE,
    FIX_HIDDEN,
    FIX_STATE,
    EnvironmentProbe,
    ScopeWatch,
    describe_difference,
    environment_message,
)
from twinfleet.checker.semantics import Rules
from twinfleet.checker.topology import Topology
from twinfleet.checker.transition import (
    Failure,
    Variant,
    fingerprint,
)
from twinfleet.checker.world import ENVIRONMENT, Event, event_key
from twinfleet.runtime.contract.context import (
    After,
    Call,
    Context,
    Fail,
    Log,
    Publish,
    Reply,
    ReplyToken,
)
from twinfleet.runtime.contract.dispatch import HandlerOutcome, run_handler
from twinfleet.runtime.contract.kinds import EventKind, FailureKind
from twinfleet.runtime.contract.messages import CallError, CallFailure
from twinfleet.runtime.contract.node import Node
from twinfleet.runtime.contract.snapshot import SnapshotError, restore, snapshot

_INTERN_LIMIT = 100_000  # interned node states kept before starting afresh
# failures not to verify by a second run: breaches already, or a forced answer that the
# run does not offer (a trace that does not fit)
_UNVERIFIED = CONTRACT_KINDS | {FailureKind.CHOICE_MISMATCH}
_NO_PROBE = contextlib.nullcontext()
_ADDRESS = re.compile(r" at 0x[0-9a-f]+")  # object addresses differ between two runs
_KEPT_LIMIT = 20_000  # handler runs kept for reuse per generation (two kept)
_ANY_TIME = -1  # the time slot of a drawn-run key whose handler did not read the clock
_KEY_LIMIT = 50_000  # message event keys kept by message identity before starting afresh

# A handler run that reached its effects: (new node state, effects, service reply).
_Handled = tuple[bytes, tuple[Any, ...], Any]


class _ClockContext(Context):
    """A `Context` that notes whether the handler read the time (`now()` or `now_ms`):
    a handler that did not gives the same outcome at any time."""

    __slots__ = ("_t", "read_clock")

    def __init__(self, node: Node, now_ms: int, chooser: Any, serving: ReplyToken | None
                 ) -> None:
        super().__init__(node, now_ms, chooser)
        self.read_clock = False
        self.serving = serving

    @property
    def now_ms(self) -> int:
        self.read_clock = True
        return self._t

    @now_ms.setter
    def now_ms(self, value: int) -> None:
        self._t = value


@final
class Runner:
    """Runs the handlers of a scenario's nodes (module docstring).

    Args:
        topology: the scenario's node graph.
        rules: the enabling rules (latency, deadlines and faults of Rule 5).
        debug_state: detect handlers that change node attributes other than `state`, by
            value (slow: every attribute is encoded before and after each handler).
        verify: probe clocks and random sources, compare attributes by identity, watch
            module and class variables, and run every handler twice and compare
            (checker.diagnosis; on by default).
    """

    def __init__(self, topology: Topology, rules: Rules, *, debug_state: bool = False,
                 verify: bool = True) -> None:
        self.topology = topology
        self.rules = rules
        self.nodes: tuple[Node, ...] = topology.nodes
        self.names = tuple(node.name for node in self.nodes)
        self._breaches = Breaches(topology)
        self.debug_state = debug_state
        self.verify = verify
        self._probe = EnvironmentProbe() if verify else None
        self._scopes = [ScopeWatch(type(node)) for node in self.nodes] if verify else None
        self._current: list[bytes | None] = [None] * len(self.nodes)
        self._canon: dict[bytes, bytes] = {}
        self.hashed = 0  # events created: content hashes for the collision bound
        self.handler_runs = 0  # handlers actually run (re-executions included)
        self.reruns = 0  # re-executions that verified a run (checker.diagnosis)
        self._handled: _Handled | None = None  # the last `_exec` that reached its effects
        self._read_clock = False  # whether that handler read the time
        self._kept: GenerationCache[_Handled] = GenerationCache(_KEPT_LIMIT)
        self._keys: dict[tuple[int, EventKind, int, str, int, str], tuple[Any, bytes]] = {}

    def interned(self) -> int:
        """How many node-state encodings are interned."""
        return len(self._canon)

    def forget_loaded(self) -> None:
        """Restore every node's state from bytes on its next run (for re-runs)."""
        self._current = [None] * len(self.nodes)

    # ---------------------------------------------------------------- runs

    def run(self, ev: Event, data: bytes, chooser: ExploringChooser) -> Variant:
        """Run `ev`'s handler on node state `data` (verified unless `verify` is off)."""
        return self._checked(ev, data, chooser)

    def run_kept(self, ev: Event, data: bytes, chooser: ExploringChooser) -> Variant:
        """`run`, unless a run of the same (node state, event) is kept — of the same time
        too if that run read the clock: then its recorded effects become events again, the
        chooser answering their latency and fault branches as a real run would (module
        docstring)."""
        kept_runs = self._kept
        kept = kept_runs.get((data, ev.key, _ANY_TIME)) or kept_runs.get((data, ev.key, ev.due))
        first = len(chooser.indices)  # a trace's replay may share its chooser
        if kept is not None:
            return _again(self, ev, data, kept, chooser, first)
        v = self._checked(ev, data, chooser)
        handled = self._handled
        # Kept only when every answer came after the handler (no ctx.choose) and the run was
        # sound: a breach or a handler exception is reported by running it again.
        if (handled is not None and len(v.choices) - first == len(v.branches)
                and (v.failure is None or v.failure.kind is FailureKind.HANDLER)):
            kept_runs.put((data, ev.key, ev.due if self._read_clock else _ANY_TIME), handled)
        return v

    def kept(self, data: bytes, key: bytes) -> _Handled | None:
        """The kept drawn run (new state, effects, reply) of the event whose untimed
        identity is `key` on node state `data`, if one is kept that did not read the clock
        (`checker.settled`)."""
        return self._kept.get((data, key, _ANY_TIME))

    def deadline_miss(self, ev: Event, data: bytes) -> Variant:
        """Taking `ev` after its deadline (Rule 5): nothing runs, the step fails."""
        names = self.names
        sender = "environment" if ev.sender == ENVIRONMENT else names[ev.sender]
        message = (f"{ev.kind} from {sender} to {names[ev.target]}.{ev.method} is handled "
                   f"at t={ev.due} ms, {ev.due - (ev.deadline or 0)} ms after its deadline "
                   f"t={ev.deadline} ms")
        failure = Failure(FailureKind.DEADLINE, names[ev.target], ev.method, message)
        return Variant((), (), data, (), failure)

    def start(self, j: int, data: bytes, now: int, chooser: ExploringChooser) -> Variant:
        """Node `j` started at `now` from state `data` (also its restart after a crash
        fault): the first firing of each periodic timer, then every `@on_start` run in
        declaration order (until one fails)."""
        topology = self.topology
        events = list(topology.periodic(j, now))
        failure: Failure | None = None
        logs: list[Log] = []
        faults: list[str] = []
        branches: list[int] = []
        lost: list[bytes] = []
        for spec in topology.starts(j):
            v = self._checked(topology.start_event(j, spec, now), data, chooser)
            data, failure = v.state, v.failure
            events += v.events
            logs += v.logs
            faults += v.faults
            branches += v.branches  # positions in the chooser, which the handlers share
            lost += v.lost
            if failure is not None:
                break
        return Variant(tuple(chooser.indices), tuple(chooser.options), data, tuple(events),
                       failure, tuple(logs), tuple(faults), tuple(branches), tuple(lost))

    def _checked(self, ev: Event, data: bytes, chooser: ExploringChooser) -> Variant:
        """`_exec`, then (with `verify`) once more from the same state with the same
        answers: a difference is a contract breach (checker.diagnosis)."""
        first = len(chooser.indices)  # start handlers share one chooser
        v = self._exec(ev, data, chooser)
        if not self.verify or (v.failure is not None and v.failure.kind in _UNVERIFIED):
            return v
        self.reruns += 1
        handled = self._handled
        self._current[ev.target] = None  # restore the node state from the bytes again
        if v.failure is None and handled is not None and \
                _same_again(self, ev, data, v, first, handled):
            return v
        self._current[ev.target] = None
        again = self._exec(ev, data, PrefixChooser(v.choices[first:]))
        a, b = _comparable(v, first), _comparable(again, 0)
        if a == b and v.logs == again.logs:
            return v
        diff = (describe_difference((v.state, v.events, a[2], a[3]),
                                    (again.state, again.events, b[2], b[3]))
                if a != b else "the ctx.log records differ")
        return _failed(chooser, data, FailureKind.NONDETERMINISM, self.names[ev.target],
                       ev.method, f"running it twice from the same state gave different "
                       f"results: {diff}; fix: {FIX_HIDDEN}")

    def _invoke(self, node: Node, ev: Event, chooser: ExploringChooser
                ) -> tuple[HandlerOutcome, _ClockContext]:
        """Run `ev`'s handler on `node` (its state loaded), under the probe if any."""
        ctx = _ClockContext(node, ev.due, chooser, _serving(self, ev))
        self._current[ev.target] = None  # the state object is about to change
        with self._probe or _NO_PROBE:
            outcome = run_handler(node, ev.method, ctx, ev.args,
                                  expects_reply=ev.kind is EventKind.REQUEST)
        return outcome, ctx

    def _load(self, i: int, data: bytes) -> Node:
        node = self.nodes[i]
        current = self._current[i]
        if current is not data and current != data:
            node.state = restore(data)
            self._current[i] = data
        return node

    def _exec(self, ev: Event, data: bytes, chooser: ExploringChooser) -> Variant:
        """Run `ev`'s handler on node state `data`: its new state, new events and failure."""
        i = ev.target
        node = self._load(i, data)
        self.handler_runs += 1
        before = fingerprint(node) if self.debug_state else None
        attributes = dict(vars(node)) if self.verify else None
        scope = None if self._scopes is None else self._scopes[i]
        held = None if scope is None else scope.take()
        self._handled = None
        outcome, ctx = self._invoke(node, ev, chooser)
        probe = self._probe
        if probe is not None and probe.calls:
            return _failed(chooser, data, FailureKind.CONTRACT, node.name, ev.method,
                           environment_message(probe.calls))
        if scope is not None and held is not None and (stray := scope.changed(held)):
            return _failed(chooser, data, FailureKind.STATE_OUTSIDE, node.name, ev.method,
                           f"it changed {', '.join(stray)}, outside self.state; fix: "
                           f"{FIX_STATE}")
        breach = self._breaches.of(node, ev, attributes, before, outcome)
        if breach is not None:
            return _failed(chooser, data, *breach)
        if chooser.mismatch is not None:  # even if the handler caught the exception
            return _failed(chooser, data, FailureKind.CHOICE_MISMATCH, node.name, ev.method,
                           str(chooser.mismatch))
        if outcome.error is not None:
            return _failed(chooser, data, FailureKind.HANDLER, node.name, ev.method,
                           outcome.error.message, outcome.error.traceback)
        try:
            new = snapshot(node.state)
        except SnapshotError as exc:
            return _failed(chooser, data, FailureKind.CONTRACT, node.name, ev.method,
                           f"its new state cannot be encoded ({exc}); fix: {FIX_ENCODABLE}")
        new = data if new == data else self._intern(new)
        self._current[i] = new
        handler_end = len(chooser.indices)
        try:
            events, failure, logs, faults, lost = self._effects(ev, outcome.effects,
                                                                outcome.reply, chooser)
        except ChoiceMismatch as exc:  # a forced latency or fault branch that does not exist
            return _failed(chooser, data, FailureKind.CHOICE_MISMATCH, node.name, ev.method,
                           str(exc))
        self._handled, self._read_clock = (new, tuple(outcome.effects), outcome.reply), \
            ctx.read_clock
        indices = tuple(chooser.indices)
        return Variant(indices, tuple(chooser.options), new, tuple(events), failure,
                       tuple(logs), tuple(faults), tuple(range(handler_end, len(indices))),
                       tuple(lost))

    def _intern(self, data: bytes) -> bytes:
        """The one bytes object kept for this node-state encoding."""
        canon = self._canon.get(data)
        if canon is None:
            if len(self._canon) >= _INTERN_LIMIT:
                self._canon.clear()
            canon = self._canon[data] = data
        return canon

    # ------------------------------------------------------------- effects

    def _effects(self, ev: Event, effects: Sequence[Any], reply: Any, chooser: ExploringChooser
                 ) -> tuple[list[Event], Failure | None, list[Log], list[str], list[bytes]]:
        """The events a handler's effects create, in order (the rules of one transition),
        and the keys (`Event.key`) of the messages a fault branch lost."""
        i, now, topology = ev.target, ev.due, self.topology
        out: list[Event] = []
        faults: list[str] = []
        logs: list[Log] = []
        lost_keys: list[bytes] = []
        if ev.kind is EventKind.PERIODIC:
            out.append(Event(self.rules.tick_after(now, topology.period(i, ev.method), chooser),
                             EventKind.PERIODIC, i, ev.method, i, (), ev.priority))
        failure = None
        for k, eff in enumerate(effects):
            match eff:
                case Publish(topic=topic, msg=msg):
                    for j, method, prio in topology.subscribers.get(topic, ()):
                        copies = self._copies(topic, j, chooser, faults)
                        if not copies:
                            lost_keys.append(event_key(EventKind.DELIVERY, j, method, i, "",
                                                       (msg,)))
                        for _ in range(copies):
                            out.append(self._message(now, topic, EventKind.DELIVERY, j, method,
                                                     i, (msg,), prio, "", chooser, k))
                case Call(service=service, request=req, reply_to=reply_to, timeout_ms=timeout):
                    server = topology.servers.get(service)
                    lost = server is not None and self._copies(service, server[0], chooser,
                                                               faults) == 0
                    if server is not None and lost:
                        lost_keys.append(event_key(EventKind.REQUEST, server[0], server[1], i,
                                                   reply_to, (req,)))
                    if server is None or lost:
                        why = CallFailure.TIMEOUT if lost else self.rules.no_server(chooser)
                        err = CallError(service, why, why.value)
                        out.append(Event(now + timeout, EventKind.TIMEOUT, i, reply_to, i,
                                         (err,), topology.priority(i, reply_to)))
                    else:
                        j, method, prio = server
                        out.append(self._message(now, service, EventKind.REQUEST, j, method, i,
                                                 (req,), prio, reply_to, chooser))
                case After(delay_ms=delay, handler=method, args=args):
                    out.append(Event(now + delay, EventKind.TIMER, i, method, i, args,
                                     topology.priority(i, method),
                                     key=self.key_of(EventKind.TIMER, i, method, i, "", args)))
                case Fail(reason=reason):
                    failure = failure or Failure(FailureKind.HANDLER, self.names[i], ev.method,
                                                 f"ctx.fail: {reason}")
                case Log():
                    logs.append(eff)
                case Reply():
                    failure = failure or _reply(self, ev, eff, out, chooser)
        if ev.kind is EventKind.REQUEST and reply is not None:  # None: deferred (`Defer`)
            _reply(self, ev, Reply(_token(self, ev), reply), out, chooser)
        self.hashed += len(out)
        return out, failure, logs, faults, lost_keys

    def _copies(self, name: str, j: int, chooser: ExploringChooser, faults: list[str]) -> int:
        """How many copies of one message on `name` to node `j` arrive (fault branches)."""
        n, fault = self.rules.copies(name, chooser, j)
        if fault:
            faults.append(f"{name} to {self.names[j]}: {fault}")
        return n

    def _message(self, now: int, name: str, kind: EventKind, target: int, method: str,
                 sender: int, args: tuple[Any, ...], priority: int, reply_to: str,
                 chooser: ExploringChooser, publish: int | None = None) -> Event:
        """A message on topic/service `name`, with its latency branch and deadline
        (`publish`: the index of the publish effect it is a copy of)."""
        due, deadline = self.rules.delivery(now, name, chooser, publish)
        return Event(due, kind, target, method, sender, args, priority, reply_to,
                     key=self.key_of(kind, target, method, sender, reply_to, args),
                     deadline=deadline)

    def key_of(self, kind: EventKind, target: int, method: str, sender: int, reply_to: str,
             args: tuple[Any, ...]) -> bytes:
        """`event_key` of an event, kept by the identity of its one argument (a message)
        or of its arguments (a timer's): a kept handler run (`run_kept`) sends the same
        objects again, and encoding them was a sixth of a simulation's time. The entry
        holds the object, so its id is not reused while the entry lives."""
        anchor = args[0] if len(args) == 1 else args
        slot = (id(anchor), kind, target, method, sender, reply_to)
        found = self._keys.get(slot)
        if found is not None:
            return found[1]
        key = event_key(kind, target, method, sender, reply_to, args)
        if len(self._keys) >= _KEY_LIMIT:
            self._keys.clear()
        self._keys[slot] = (anchor, key)
        return key


def _serving(runner: Runner, ev: Event) -> ReplyToken | None:
    """The token of a request `ev`, should its handler defer the reply (else None)."""
    return _token(runner, ev) if ev.kind is EventKind.REQUEST else None


def _token(runner: Runner, ev: Event) -> ReplyToken:
    """The call a request `ev` is, as a `ReplyToken`."""
    service = runner.topology.service_of.get((ev.target, ev.method), "")
    return ReplyToken(service, runner.names[ev.sender], ev.reply_to, ev.args[0])


def _reply(runner: Runner, ev: Event, reply: Reply, out: list[Event],
           chooser: ExploringChooser) -> Failure | None:
    """The reply event of a request (its handler's return value, or a `Reply` effect of a
    later handler when it deferred); a failure when the token names no node."""
    token, names = reply.token, runner.names
    if token.caller not in names:
        return Failure(FailureKind.CONTRACT, names[ev.target], ev.method, f"ctx.reply() to a "
                       f"token of caller {token.caller!r}, which is no node of the scenario; "
                       "fix: reply with a token defer_reply() gave")
    j = names.index(token.caller)
    out.append(runner._message(ev.due, token.service, EventKind.REPLY, j, token.reply_to,
                               ev.target, (reply.msg,), runner.topology.priority(
                                   j, token.reply_to), "", chooser))
    return None


def _again(runner: Runner, ev: Event, data: bytes, kept: _Handled, chooser: ExploringChooser,
           first: int) -> Variant:
    """`ev`'s handler run on `data` again from what a kept run of it did (`Runner.run_kept`):
    its effects become events with `chooser`'s answers from position `first` on."""
    new, effects, reply = kept
    try:
        events, failure, logs, faults, lost = runner._effects(ev, effects, reply, chooser)
    except ChoiceMismatch as exc:  # a forced branch that does not exist
        return _failed(chooser, data, FailureKind.CHOICE_MISMATCH, runner.names[ev.target],
                       ev.method, str(exc))
    n = len(chooser.indices)
    return Variant(tuple(chooser.indices), tuple(chooser.options), new, tuple(events), failure,
                   tuple(logs), tuple(faults), tuple(range(first, n)), tuple(lost))


def _same_again(runner: Runner, ev: Event, data: bytes, v: Variant, first: int,
                handled: _Handled) -> bool:
    """True if `ev`'s handler, run once more from `data` with the same answers, gives what
    its first run `v` gave (`handled`: its new state, effects and reply). The verification's
    usual case (`Runner._checked`), without rebuilding the events (about a quarter of
    c1a_rebeca's search was that second run); False sends `_checked` to the full second
    run, which names what differs."""
    i = ev.target
    node = runner._load(i, data)
    runner.handler_runs += 1
    end = v.branches[0] if v.branches else len(v.choices)  # the handler's own answers
    chooser = PrefixChooser(v.choices[first:end])
    outcome, _ = runner._invoke(node, ev, chooser)
    probe = runner._probe
    if outcome.error is not None or chooser.mismatch is not None or \
            (probe is not None and probe.calls) or tuple(chooser.indices) != v.choices[first:end]:
        return False
    try:
        same = snapshot(node.state) == handled[0] and \
            _equal((tuple(outcome.effects), outcome.reply), (handled[1], handled[2]))
    except SnapshotError:
        return False
    if same:
        runner._current[i] = handled[0]
    return same


def _equal(a: Any, b: Any) -> bool:
    """True if two runs' effects `a` and `b` are the same: equal values (`==`, the common
    case, fast), or else equal canonical bytes (NaN, numpy arrays, whose `==` is not a
    plain True). Equal values of different numeric types (1 and 1.0) count as the same
    here, unlike in the full comparison of `_checked`, which the bytes of two events give."""
    try:
        if a == b:
            return True
    except (TypeError, ValueError):
        pass
    return snapshot(a) == snapshot(b)


def _comparable(v: Variant, first: int) -> tuple[Any, ...]:
    """What two runs of one handler must agree on (choices from position `first`)."""
    failure = None if v.failure is None else (
        v.failure.kind, _ADDRESS.sub("", v.failure.message))
    return v.state, [(e.sk, e.deadline) for e in v.events], failure, v.choices[first:]


def _failed(chooser: ExploringChooser, data: bytes, kind: FailureKind, node: str, method: str,
            message: str, traceback: str = "") -> Variant:
    return Variant(tuple(chooser.indices), tuple(chooser.options), data, (),
                   Failure(kind, node, method, message, traceback))
