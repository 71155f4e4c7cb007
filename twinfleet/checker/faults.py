"""The checker's optional `check:` settings: latency, deadlines, queue bounds and faults.

Every setting is off by default; with none of them a search explores exactly
what it did before. The scenario loader parses their shapes into
`runtime.scenario.config.CheckConfig` (a bad value fails at load); this module checks
the topic and service names against the compiled node graph and turns them
into `CheckSettings` for a `System`. Schema (names are fully qualified topic or service names
as nodes resolve them, e.g. ``/r1/scan``, ``/poses``, ``/generate_path``)::

    check:
      latency: [min, max]              # every message takes min..max ms (one branch per value)
      latency:                         # or per topic / service, with an optional default
        default: [0, 0]
        /r1/scan: [0, 20]
      deadline_ms: 50                  # every message must be handled within 50 ms of its send
      deadline_ms: {default: 100, /r1/scan: 50}
      timer_lateness: [0, 50]          # an @every tick may leave its queue 0..50 ms late
      queue_bound: 8                   # at most 8 pending events at any node
      queue_bound: {default: 8, map_server: 20}
      faults:
        drop: [/r1/scan, /generate_path]   # each delivery: delivered | dropped
        duplicate: [/poses]                # each delivery: delivered | delivered twice
        crash:
          nodes: [r1, map_server]          # nodes that may crash (required, non-empty)
          max: 1                           # crash faults per path (default 1)
          durable: [map_server]            # these keep their state across a crash

What each does (the rules themselves are Rule 5 of `checker.semantics`; the
crash itself is `checker.system`'s `Crash` action):

- `latency`: a message (delivery, service request or reply) is due `min..max`
  ms after it is sent, each value a separate branch. A topic mapped to
  ``[0, 0]`` has no latency even if `default` has one. Under `ros` a message
  is never due before an earlier one of its channel (the due time is clamped).
- `deadline_ms`: a message whose handler runs later than `send time + d` is a
  *deadline miss* (property `deadline`, kind "deadline miss"), reported when
  the message is taken, as RMC does. Since time passes only when nothing is
  due, a message can be late only through latency or FIFO clamping.
  Requests and replies use their service's name.
- `timer_lateness`: how late a node may take an `@every` tick, as a node
  process under load does. A tick late by a period or more than the next one
  makes the runtime skip the missed periods (`runtime.contract.rules`), so
  where the range allows that, the next tick's due time is a branch: one
  period on, or each later tick the range reaches (Rule 7 of
  `checker.semantics`). Below twice the period nothing changes.
- `queue_bound`: a world in which a node has more pending events (messages,
  timers, periodic timers, replies) than its bound is a *queue overflow*
  (property `queue_bound`). Mapping keys are node names; `default` applies to
  the rest; a node with no entry and no default is unbounded.
- `faults.drop`: for a topic, each delivery to each subscriber is two
  branches, delivered or lost. For a service, each request is delivered or
  lost; a lost request makes the caller's reply handler get
  ``CallError(service, CallFailure.TIMEOUT)`` after the call's timeout (an event of kind
  TIMEOUT), as live mode does. Replies are never lost.
- `faults.duplicate` (topics only): each delivery is delivered once or twice
  (the copy is a separate message with its own latency branch). A topic in
  both lists has three branches: delivered, dropped, duplicated.
- `faults.crash`: in every world with something pending, and while fewer than
  `max` crashes happened on the path, each listed node may crash at the next
  event time t*: every pending event addressed to it is lost (timers,
  periodic timers and queued messages; messages it already sent stay in
  flight), its state resets to `initial_state()` unless it is `durable`, and
  it restarts at once: periodic timers re-armed from t*, `on_start` handlers
  run at t* (their `ctx.choose` branches are separate transitions). A crash is
  one transition; the crash count is part of the state. Nothing crashes in a
  world with nothing pending.

Fault branches are enumerated like `ctx.choose` options, after the handler's
own choices, in effect order (for each delivery: the fault choice, then the
latency of each copy), so they appear in a trace's `choices` and replay
re-takes them; trace steps also list them under `faults`.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Final, final

from twinfleet.runtime.scenario.config import PerName
from twinfleet.runtime.scenario.spec import Scenario, ScenarioError

DELIVER: Final = "deliver"
DROP: Final = "drop"
DUPLICATE: Final = "duplicate"


@final
@dataclass(frozen=True, slots=True)
class CrashFaults:
    """Which nodes may crash, how often per path, and which keep their state."""

    nodes: tuple[int, ...]
    max: int = 1
    durable: frozenset[int] = frozenset()


@final
@dataclass(frozen=True, slots=True)
class CheckSettings:
    """The parsed optional settings (see the module docstring)."""

    latency: tuple[int, int] | None = None
    topic_latency: tuple[tuple[str, tuple[int, int] | None], ...] = ()
    deadline_default: int | None = None
    deadlines: Mapping[str, int] = field(default_factory=dict)
    queue_bounds: tuple[int | None, ...] = ()
    drop: frozenset[str] = frozenset()
    duplicate: frozenset[str] = frozenset()
    crash: CrashFaults | None = None
    timer_lateness: tuple[int, int] | None = None

    def deadline_for(self, name: str) -> int | None:
        """The deadline (ms after sending) of messages on topic/service `name`, or None."""
        return self.deadlines.get(name, self.deadline_default)

    def delivery_options(self, topic: str) -> tuple[str, ...]:
        """The fault branches of one delivery on `topic` (just (DELIVER,) without faults)."""
        options = [DELIVER]
        if topic in self.drop:
            options.append(DROP)
        if topic in self.duplicate:
            options.append(DUPLICATE)
        return tuple(options)

    @property
    def has_deadlines(self) -> bool:
        """True when some message has a deadline."""
        return self.deadline_default is not None or bool(self.deadlines)


def _fail(scenario: Scenario, key: str, what: str) -> ScenarioError:
    return ScenarioError(f"{scenario.source}: check.{key}: {what}")


def _range(latency: tuple[int, int] | None) -> tuple[int, int] | None:
    """A latency range, None for no latency (``[0, 0]``)."""
    return None if latency is None or tuple(latency) == (0, 0) else (latency[0], latency[1])


def _names(scenario: Scenario, key: str, names: Iterable[str], known: set[str], what: str,
           *, keyed: bool = True) -> None:
    """Reject names not in `known`; `keyed`: the names are mapping keys (named in the error)."""
    for name in names:
        if name not in known:
            raise _fail(scenario, f"{key}.{name}" if keyed else key,
                        f"{name!r} is not {what}; expected one of {', '.join(sorted(known))}")


_CHANNEL = "a topic with a subscriber or a served service"


def parse_latency(scenario: Scenario, names: set[str]) -> tuple[tuple[int, int] | None,
                                                                 tuple[tuple[str, Any], ...]]:
    """`check.latency`: (global range or None, per-name overrides), names checked."""
    latency = scenario.check.latency
    _names(scenario, "latency", latency.named(), names, _CHANNEL)
    return _range(latency.default), tuple((k, _range(v)) for k, v in latency.names)


def parse_deadlines(scenario: Scenario, names: set[str] | None) -> tuple[int | None,
                                                                         dict[str, int]]:
    """`check.deadline_ms`: (default or None, per-name deadlines); `names` None = unchecked."""
    deadlines: PerName[int] = scenario.check.deadline_ms
    if names is not None:
        _names(scenario, "deadline_ms", deadlines.named(), names, _CHANNEL)
    return deadlines.default, dict(deadlines.names)


def parse_queue_bounds(scenario: Scenario) -> tuple[int | None, ...]:
    """`check.queue_bound`: per node (scenario order) its bound, or None (node names were
    checked when the scenario was loaded)."""
    bounds = scenario.check.queue_bound
    return tuple(bounds.get(n.name) for n in scenario.nodes) if bounds else ()


def parse_faults(scenario: Scenario, topics: set[str], services: set[str]) -> tuple[
        frozenset[str], frozenset[str], CrashFaults | None]:
    """`check.faults`: (drop names, duplicate topics, crash settings or None)."""
    faults = scenario.check.faults
    _names(scenario, "faults.drop", faults.drop, topics | services, _CHANNEL, keyed=False)
    _names(scenario, "faults.duplicate", faults.duplicate, topics, "a topic with a subscriber "
           "(services cannot be duplicated)", keyed=False)
    crash = None
    if faults.crash is not None:
        index = {n.name: i for i, n in enumerate(scenario.nodes)}
        crash = CrashFaults(tuple(sorted({index[n] for n in faults.crash.nodes})),
                            faults.crash.max, frozenset(index[n] for n in faults.crash.durable))
    return frozenset(faults.drop), frozenset(faults.duplicate), crash


def parse_settings(scenario: Scenario, topics: set[str], services: set[str], *,
                   latency: tuple[int, int] | None | Sequence[int] = (),
                   topic_latency: Sequence[tuple[str, tuple[int, int]]] = (),
                   timer_lateness: tuple[int, int] | None = None) -> CheckSettings:
    """Every optional setting, validated against the scenario's topics and services.

    Args:
        scenario: the parsed scenario.
        topics: fully qualified topics that have at least one subscriber.
        services: fully qualified names of served services.
        latency: an explicit global latency overriding `check.latency` (the
            default, an empty tuple, means "take the scenario's").
        topic_latency: per topic or service ranges overriding the scenario's for those
            names (a timing model's bounds, `checker.timing`).
        timer_lateness: a lateness range of `@every` ticks overriding the scenario's
            `check.timer_lateness` (a timing model's bounds).
    """
    default, per_topic = parse_latency(scenario, topics | services)
    if latency != ():
        default = None if latency is None else _range(tuple(latency))  # type: ignore[arg-type]
    if topic_latency:
        _names(scenario, "latency", (name for name, _ in topic_latency), topics | services,
               _CHANNEL)
        merged = dict(per_topic) | {name: _range(span) for name, span in topic_latency}
        per_topic = tuple(sorted(merged.items()))
    deadline_default, deadlines = parse_deadlines(scenario, topics | services)
    drop, dup, crash = parse_faults(scenario, topics, services)
    return CheckSettings(default, per_topic, deadline_default, deadlines,
                         parse_queue_bounds(scenario), drop, dup, crash,
                         timer_lateness or scenario.check.timer_lateness)
