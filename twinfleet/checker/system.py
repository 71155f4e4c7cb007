"""`System`: a scenario compiled into initial worlds, actions and one step function.

The system is a model in Stateright's sense: `initial()` gives the initial
worlds, `actions(world)` what may happen next (`RunEvent` of an enabled
event, `Crash` of a node, `Drop` of a waiting delivery; the rules are
`checker.semantics`), and
`step(world, action, chooser)` the one function from a world, an action and
the answers to its choice points to the next world (a `Transition`, which
also says what the step did). `outcomes(world, action)` takes an action with
every combination of answers (the siblings a search explores), and
`successors(world)` is every outcome of every action. Every search, trace
replay, `agreement.validate` and the live replay use these; a handler runs
in `checker.runner`.

Initial worlds: every node's `initial_state()`, the liveliness events of every
node appearing (to `/_liveliness` subscribers), the first firing of each
`@every` timer at phase + period, then every `@on_start` handler run at t=0 in
scenario order, like Rebeca constructors: they are not transitions (R10) and
their effects are the initial pending events. If start handlers call
`ctx.choose`, each combination is a separate initial world.

Speed. A handler's outcome depends only on the node's state, the event and
the time (that is the node contract, which replay relies on too), so
`outcomes` runs each (node state, event, time) once and keeps every choice
variant's outcome — new node state and new events — in a cache: the
interleavings of independent nodes repeat the same local steps many times
(C1a: 128,800 transitions, 5,595 distinct handler runs); a cache miss reuses a
kept run of the same (node state, event) at another time when the handler did not
read the clock (`Runner.run_kept`), so that run is not repeated, nor verified again
(c1a_rebeca: 2,326 handler runs where 5,513 ran). Entries are keyed by
absolute time, so the search drops those older than its frontier's earliest
t* (`forget_before`), which no world left to expand can use; and whatever
the search order it keeps at most two generations of 1,024 outcomes
(`checker.cache.GenerationCache`): a breadth-first frontier can span a wide
range of times, and outcomes not used for a generation are rarely used again.
Equal node states are interned to one bytes object, hashed once (`World.key`,
`checker.builder`).
Every handler run that is not a cache hit is verified (`checker.diagnosis`:
clocks and random sources probed, run twice and compared), so a node that
breaks the contract is found in every search at the cost of one extra run per
distinct (node state, event, time). The cache is off under `debug_state` and
`check_determinism`, which must really run (and verify) every transition;
`transition_cache=False` turns it off for comparison.

Faults, deadlines and latency follow `checker.faults` and Rule 5 of
`checker.semantics`; crash actions are listed after the event actions of a
world.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import TYPE_CHECKING, Any, final

from twinfleet.checker import start
from twinfleet.checker.builder import WorldBuilder
from twinfleet.checker.cache import GenerationCache
from twinfleet.checker.choices import ExploringChooser, PrefixChooser
from twinfleet.checker.faults import parse_settings
from twinfleet.checker.options import Semantics
from twinfleet.checker.publications import Publications
from twinfleet.checker.runner import Runner
from twinfleet.checker.semantics import Rules
from twinfleet.checker.topology import Topology
from twinfleet.checker.transition import (
    Action,
    Crash,
    Drop,
    Failure,
    RunEvent,
    Step,
    Transition,
    Variant,
)
from twinfleet.checker.world import ENVIRONMENT, Event, World
from twinfleet.runtime.contract.kinds import EventKind
from twinfleet.runtime.contract.snapshot import restore
from twinfleet.runtime.scenario.spec import Scenario, ScenarioError

if TYPE_CHECKING:
    from twinfleet.checker.properties import PropertySet

__all__ = ["Action", "Crash", "Drop", "Failure", "RunEvent", "Step", "System", "Transition"]

_MEMO_LIMIT = 1_024  # handler outcomes per cache generation (two kept; ~0.55 KB each on C1b)
_DECODED_LIMIT = 64  # decoded states kept for property expressions (~2.5 KB each on C1a)

# Actions are listed for every world a search expands: share one RunEvent per index.
_SHARED = 256
_RUN_EVENTS = tuple(RunEvent(i) for i in range(_SHARED))


def run_event(index: int) -> RunEvent:
    """`RunEvent(index)`, shared for the usual small indices (built once per step)."""
    return _RUN_EVENTS[index] if index < _SHARED else RunEvent(index)


@final
class System:
    """Initial worlds, actions and steps of a scenario under one set of message rules.

    Args:
        scenario: the parsed scenario.
        semantics: `Semantics.ROS` or `Semantics.REBECA`; default the scenario's.
        latency: (min, max) delivery delay branches; default `check.latency`.
        topic_latency: (topic or service, (min, max)) ranges overriding the scenario's
            for those names (a timing model's bounds, `checker.timing`).
        timer_lateness: (min, max) lateness of `@every` ticks (Rule 7 of
            `checker.semantics`); default `check.timer_lateness`.
        global_priority: rebeca's `@globalPriority`; default `check.global_priority`.
        debug_state: detect handlers that change node attributes other than `state`.
        properties: the properties (`checker.properties.PropertySet`) whose `within`
            obligations worlds carry.
        exact_states: key worlds by their 128-bit digest (`World.digest`).
        check_determinism: verify every transition, not only new handler runs (turns the
            transition cache off).
        transition_cache: reuse handler outcomes (see the module docstring).
        verify: verify every new handler run (`checker.diagnosis`; implied by
            `check_determinism`).
        keyed: key every world as it is built (`WorldBuilder`); simulations turn it off.
    """

    def __init__(self, scenario: Scenario, *, semantics: Semantics | str | None = None,
                 latency: tuple[int, int] | None = None,
                 topic_latency: tuple[tuple[str, tuple[int, int]], ...] = (),
                 timer_lateness: tuple[int, int] | None = None,
                 global_priority: bool | None = None,
                 debug_state: bool = False, properties: PropertySet | None = None,
                 exact_states: bool = False, check_determinism: bool = False,
                 transition_cache: bool = True, verify: bool = True, keyed: bool = True
                 ) -> None:
        self.scenario = scenario
        self.topology = Topology([cfg.instantiate() for cfg in scenario.nodes], scenario.path)
        self.nodes = self.topology.nodes
        self.names: tuple[str, ...] = tuple(cfg.name for cfg in scenario.nodes)
        self.index = {name: i for i, name in enumerate(self.names)}
        self.settings = parse_settings(scenario, set(self.topology.subscribers),
                                       set(self.topology.servers),
                                       latency=() if latency is None else latency,
                                       topic_latency=topic_latency,
                                       timer_lateness=timer_lateness)
        self.topic_latency = topic_latency
        if self.settings.crash is not None:
            self.topology.refuse_late_joiners(self.settings.crash.nodes, scenario.path)
        if global_priority is None:
            global_priority = scenario.check.global_priority
        try:
            # Rules converts a str (and rejects an unknown one with a readable error).
            self.rules = Rules(semantics or scenario.semantics,  # type: ignore[arg-type]
                               tuple(cfg.priority for cfg in scenario.nodes),
                               bool(global_priority), self.settings, self.topology.depths,
                               frozenset(self.topology.lossy))
        except ValueError as exc:
            raise ScenarioError(f"{scenario.source}: check: {exc}") from None
        self.debug_state = debug_state
        self.check_determinism = check_determinism
        self.exact_states = exact_states
        self.properties = properties
        self.runner = Runner(self.topology, self.rules, debug_state=debug_state,
                             verify=verify or check_determinism)
        self._memo: GenerationCache[list[Variant]] | None = (
            GenerationCache(_MEMO_LIMIT)
            if transition_cache and not debug_state and not check_determinism else None)
        self._worlds = WorldBuilder(self, properties, exact=exact_states, keyed=keyed,
                                    ranked=self.rules.fifo)
        self._world = self._worlds.world
        self._decoded: dict[bytes, Any] = {}
        #: zero-delay sends seen in every handler run computed (`checker.reduction`)
        classes = [type(n) for n in self.nodes]
        self.publications = Publications(len(self.nodes), [
            tuple(j for j, c in enumerate(classes) if c is k and j != i)
            for i, k in enumerate(classes)])

    @property
    def semantics(self) -> Semantics:
        """The message semantics the system runs under."""
        return self.rules.semantics

    @property
    def hashed(self) -> int:
        """Content hashes computed (node states, events): for the collision bound."""
        return self._worlds.hashed + self.runner.hashed

    # ----------------------------------------------------------------- model

    def initial(self) -> list[Transition]:
        """Every initial world (one per combination of choices made by start handlers)."""
        return start.initial_transitions(self)

    def initial_world(self, choices: tuple[int, ...] = (), *,
                      chooser: ExploringChooser | None = None) -> Transition:
        """The initial world reached with the start-handler `choices` (or `chooser`)."""
        return start.initial_world(self, self._worlds, choices, chooser=chooser)

    def actions(self, world: World) -> list[Action]:
        """What may happen next: each enabled event (`RunEvent`), then each crash fault, then
        each KEEP_LAST drop (`Drop`)."""
        acts: list[Action] = [run_event(i) for i in self.rules.enabled(world.events)]
        if self.settings.crash is not None:
            acts += [Crash(j) for j in self.rules.crashable(world)]
        acts += [Drop(i) for i in self.rules.droppable(world.events)]
        return acts

    def step(self, world: World, action: Action, chooser: ExploringChooser) -> Transition:
        """Take `action` in `world`, `chooser` answering its choice points: the next world."""
        return self._apply(world, action, self._variant(world, action, chooser))

    def draw(self, world: World, action: RunEvent, chooser: ExploringChooser) -> Transition:
        """`step` for a fresh chooser that draws its answers (a simulation): handler runs
        are kept and reused as `Runner.run_kept` says; the same transition as `step`."""
        ev = world.events[action.index]
        if ev.sk[3]:  # late: a deadline miss, nothing runs
            return self.step(world, action, chooser)
        return self._apply(world, action,
                           self.runner.run_kept(ev, world.states[ev.target], chooser))

    def apply(self, world: World, action: Action, variant: Variant) -> Transition:
        """The transition of one of `variants(world, action)`: a walk that picks one
        builds only that world."""
        return self._apply(world, action, variant)

    def outcomes(self, world: World, action: Action) -> list[Transition]:
        """`action` taken with every combination of answers to its choice points."""
        return [self._apply(world, action, v) for v in self._variants(world, action)]

    def successors(self, world: World, enabled: list[int] | None = None) -> Iterator[Transition]:
        """Every outcome of every action of `world`, in `actions` order (the same
        transitions as `outcomes` of each of `actions`); `enabled`: the world's enabled
        event indices, if the caller has them already."""
        # The search's inner loop, so `actions` and `outcomes` are spelled out here: a hit
        # of the outcome cache (the key of `_variants`) costs one lookup (C1a: 96 % hits).
        events, states = world.events, world.states
        apply, run, memo = self._apply, self._apply_run, self._memo
        for index in self.rules.enabled(events) if enabled is None else enabled:
            action = _RUN_EVENTS[index] if index < _SHARED else RunEvent(index)
            ev = events[index]
            found = None
            if memo is not None and not ev.sk[3]:
                found = memo.get((states[ev.target], ev.key, ev.due))
            for v in found if found is not None else self._variants(world, action):
                yield run(world, action, v)
        if self.settings.crash is not None:
            for j in self.rules.crashable(world):
                crash = Crash(j)
                for v in self._variants(world, crash):
                    yield apply(world, crash, v)
        if self.rules.may_drop(events):
            for index in self.rules.droppable(events):
                yield self._apply_drop(world, index)

    # ------------------------------------------------------------ variants

    def _variant(self, world: World, action: Action, chooser: ExploringChooser,
                 reuse: bool = False) -> Variant:
        """What taking `action` in `world` with `chooser` does, independent of the world;
        `reuse`: from a kept handler run if there is one (`Runner.run_kept`)."""
        if isinstance(action, Drop):  # nothing runs (`_apply_drop` does the dropping)
            return Variant((), (), world.states[world.events[action.index].target])
        if isinstance(action, Crash):
            j, now = action.node, world.events[0].due
            return self.runner.start(j, self._crash_state(world, j), now, chooser)
        ev = world.events[action.index]
        data = world.states[ev.target]
        if ev.sk[3]:  # late: a deadline miss (Rule 5)
            return self.runner.deadline_miss(ev, data)
        if reuse:
            return self.runner.run_kept(ev, data, chooser)
        return self.runner.run(ev, data, chooser)

    def variants(self, world: World, action: Action) -> list[Variant]:
        """Every choice variant of `action` in `world`: what it does, before it is applied."""
        return self._variants(world, action)

    def _variants(self, world: World, action: Action) -> list[Variant]:
        """Every choice variant of `action` in `world` (cached, see the module docstring)."""
        if type(action) is Drop:
            return [self._variant(world, action, PrefixChooser())]
        if type(action) is RunEvent:
            ev = world.events[action.index]
            if ev.sk[3]:  # late: a deadline miss, nothing runs
                return [self._variant(world, action, PrefixChooser())]
            mk: tuple[Any, ...] = (world.states[ev.target], ev.key, ev.due)  # time last
            sender = (ev.target, ev.method)
        else:
            j = action.node
            sender = (j, "")
            mk = (EventKind.CRASH, j, self._crash_state(world, j), world.events[0].due)
        memo = self._memo
        found = None if memo is None else memo.get(mk)
        if found is not None:
            return found
        variants = []
        prefix: tuple[int, ...] | None = ()
        while prefix is not None:
            chooser = PrefixChooser(prefix)
            variants.append(self._variant(world, action, chooser, memo is not None))
            prefix = chooser.next_prefix()
        self.publications.observe(sender, mk[-1], variants)
        if memo is not None:
            memo.put(mk, variants)
        return variants

    def _crash_state(self, world: World, j: int) -> bytes:
        crash = self.settings.crash
        durable = crash is not None and j in crash.durable
        return world.states[j] if durable else self.topology.initial_states[j]

    # ------------------------------------------------------------ next worlds

    def _apply(self, world: World, action: Action, v: Variant) -> Transition:
        """The transition of variant `v` of `action` in `world`."""
        if type(action) is Crash:
            return self._apply_crash(world, action.node, v)
        if type(action) is Drop:
            return self._apply_drop(world, action.index)
        return self._apply_run(world, action, v)

    def _apply_run(self, world: World, action: RunEvent, v: Variant) -> Transition:
        """The transition of variant `v` of `action`, a pending event of `world` run."""
        events = world.events
        index = action.index
        ev = events[index]
        rules = self.rules
        if rules.fifo:
            pending = rules.remove(events, index)
            for e in v.events:
                rules.add(pending, e)
        else:  # there `remove` and `add` change no event: the others, then the new ones
            pending = [*events[:index], *events[index + 1:], *v.events]
        states, changed = world.states, ()
        i = ev.target
        if v.state is not states[i]:
            states, changed = (*states[:i], v.state, *states[i + 1:]), (i,)
        new = self._world(ev.due, states, pending, world, world.crashes)
        return Transition(Step(action, v.choices, v.options), new, ev, v.failure, v.logs,
                          v.faults, v.branches, v.events, changed, v.lost)

    def _apply_drop(self, world: World, index: int) -> Transition:
        """KEEP_LAST drops pending delivery `index` (Rule 6): nothing runs, no state changes."""
        ev = world.events[index]
        pending = self.rules.remove(world.events, index)
        new = self._world(ev.due, world.states, pending, world, world.crashes)
        label = Event(ev.due, EventKind.DROP, ev.target, ev.method, ev.sender, ev.args,
                      ev.priority)
        depth = self.rules.depths[(ev.target, ev.method)]
        note = (f"{self.names[ev.target]}.{ev.method}: a waiting message dropped "
                f"(KEEP_LAST depth {depth})")
        return Transition(Step(Drop(index)), new, label, faults=(note,))

    def _apply_crash(self, world: World, j: int, v: Variant) -> Transition:
        now = world.events[0].due
        pending = [e for e in world.events if e.target != j]
        for e in (*self.topology.crashed(j, now), *v.events):
            self.rules.add(pending, e)
        states = (*world.states[:j], v.state, *world.states[j + 1:])
        new = self._world(now, states, pending, world, world.crashes + 1)
        crash = self.settings.crash
        kept = "state kept (durable)" if crash and j in crash.durable else "state reset"
        note = f"{self.names[j]} crashed and restarted: pending events lost, {kept}"
        label = Event(now, EventKind.CRASH, j, "", ENVIRONMENT, (), 0)
        changed = (j,) if v.state is not world.states[j] else ()
        return Transition(Step(Crash(j), v.choices, v.options), new, label, v.failure, v.logs,
                          (note, *v.faults), v.branches, v.events, changed, v.lost)

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

    def widen_cache(self, limit: int) -> None:
        """Keep up to `limit` handler outcomes per cache generation: a reduced search, which
        starts again from time 0 when its send relation grows, needs old ones again."""
        if self._memo is not None and self._memo.limit < limit:
            self._memo.limit = limit

    def forget_before(self, time_ms: int) -> int:
        """Drop cached handler outcomes of events due before `time_ms`; return how many
        (a search passes its frontier's smallest t*: no world left to expand uses them)."""
        return 0 if self._memo is None else self._memo.forget_before(time_ms)

    def cache_sizes(self) -> dict[str, int]:
        """Entries in the system's caches (transition outcomes, interned states, hashes)."""
        return {"handler_runs": self.runner.handler_runs,
                "cached_outcomes": len(self._memo or {}),
                "interned_states": self.runner.interned(),
                "state_hashes": len(self._worlds), "decoded": len(self._decoded)}
