"""The checker's optional `check:` settings: latency, deadlines, queue bounds and faults.

Every setting is off by default; with none of them a search explores exactly
what it did before. Schema (names are fully qualified topic or service names
as nodes resolve them, e.g. ``/r1/scan``, ``/poses``, ``/generate_path``)::

    check:
      latency: [min, max]              # every message takes min..max ms (one branch per value)
      latency:                         # or per topic / service, with an optional default
        default: [0, 0]
        /r1/scan: [0, 20]
      deadline_ms: 50                  # every message must be handled within 50 ms of its send
      deadline_ms: {default: 100, /r1/scan: 50}
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
- `queue_bound`: a world in which a node has more pending events (messages,
  timers, periodic timers, replies) than its bound is a *queue overflow*
  (property `queue_bound`). Mapping keys are node names; `default` applies to
  the rest; a node with no entry and no default is unbounded.
- `faults.drop`: for a topic, each delivery to each subscriber is two
  branches, delivered or lost. For a service, each request is delivered or
  lost; a lost request makes the caller's reply handler get
  ``CallError(service, "timeout")`` after the call's timeout (an event of kind
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

from twinfleet.runtime.scenario import Scenario, ScenarioError

DELIVER: Final = "deliver"
DROP: Final = "drop"
DUPLICATE: Final = "duplicate"

FAULT_KEYS: Final = frozenset({"drop", "duplicate", "crash"})
CRASH_KEYS: Final = frozenset({"nodes", "max", "durable"})
DEFAULT: Final = "default"


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
    return ScenarioError(f"{scenario.path}: check.{key}: {what}")


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _range(scenario: Scenario, key: str, raw: Any) -> tuple[int, int] | None:
    if not isinstance(raw, list | tuple) or len(raw) != 2 or not all(_is_int(v) for v in raw):
        raise _fail(scenario, key, f"expected [min, max] in ms, got {raw!r}")
    if not 0 <= raw[0] <= raw[1]:
        raise _fail(scenario, key, f"latency must be [min, max] with 0 <= min <= max, got {list(raw)}")
    return None if tuple(raw) == (0, 0) else (raw[0], raw[1])


def _names(scenario: Scenario, key: str, names: Iterable[str], known: set[str], what: str,
           *, keyed: bool = True) -> None:
    """Reject names not in `known`; `keyed`: the names are mapping keys (named in the error)."""
    for name in names:
        if name not in known:
            raise _fail(scenario, f"{key}.{name}" if keyed else key,
                        f"{name!r} is not {what}; expected one of {', '.join(sorted(known))}")


def parse_latency(scenario: Scenario, names: set[str]) -> tuple[tuple[int, int] | None,
                                                                 tuple[tuple[str, Any], ...]]:
    """`check.latency`: (global range or None, per-name overrides)."""
    raw = scenario.check.get("latency")
    if raw is None:
        return None, ()
    if not isinstance(raw, Mapping):
        return _range(scenario, "latency", raw), ()
    default = _range(scenario, "latency.default", raw[DEFAULT]) if DEFAULT in raw else None
    per = {k: v for k, v in raw.items() if k != DEFAULT}
    _names(scenario, "latency", per, names, "a topic with a subscriber or a served service")
    return default, tuple(sorted((k, _range(scenario, f"latency.{k}", v)) for k, v in per.items()))


def _ms(scenario: Scenario, key: str, raw: Any) -> int:
    if not _is_int(raw) or raw < 0:
        raise _fail(scenario, key, f"expected milliseconds >= 0, got {raw!r}")
    return raw


def parse_deadlines(scenario: Scenario, names: set[str] | None) -> tuple[int | None,
                                                                         dict[str, int]]:
    """`check.deadline_ms`: (default or None, per-name deadlines); `names` None = unchecked."""
    raw = scenario.check.get("deadline_ms")
    if raw is None:
        return None, {}
    if not isinstance(raw, Mapping):
        return _ms(scenario, "deadline_ms", raw), {}
    default = _ms(scenario, "deadline_ms.default", raw[DEFAULT]) if DEFAULT in raw else None
    per = {k: _ms(scenario, f"deadline_ms.{k}", v) for k, v in raw.items() if k != DEFAULT}
    if names is not None:
        _names(scenario, "deadline_ms", per, names,
               "a topic with a subscriber or a served service")
    return default, per


def parse_queue_bounds(scenario: Scenario) -> tuple[int | None, ...]:
    """`check.queue_bound`: per node (scenario order) its bound, or None."""
    raw = scenario.check.get("queue_bound")
    nodes = [n.name for n in scenario.nodes]
    if raw is None:
        return ()
    if not isinstance(raw, Mapping):
        bound = _bound(scenario, "queue_bound", raw)
        return tuple(bound for _ in nodes)
    default = _bound(scenario, "queue_bound.default", raw[DEFAULT]) if DEFAULT in raw else None
    per = {k: v for k, v in raw.items() if k != DEFAULT}
    _names(scenario, "queue_bound", per, set(nodes), "a node of this scenario")
    return tuple(_bound(scenario, f"queue_bound.{n}", per[n]) if n in per else default
                 for n in nodes)


def _bound(scenario: Scenario, key: str, raw: Any) -> int:
    if not _is_int(raw) or raw < 1:
        raise _fail(scenario, key, f"expected a number of pending events >= 1, got {raw!r}")
    return raw


def _list(scenario: Scenario, key: str, raw: Any) -> list[str]:
    if not isinstance(raw, list) or not all(isinstance(v, str) for v in raw):
        raise _fail(scenario, key, f"expected a list of names, got {raw!r}")
    return raw


def parse_faults(scenario: Scenario, topics: set[str], services: set[str]) -> tuple[
        frozenset[str], frozenset[str], CrashFaults | None]:
    """`check.faults`: (drop names, duplicate topics, crash settings or None)."""
    raw = scenario.check.get("faults")
    if raw is None:
        return frozenset(), frozenset(), None
    if not isinstance(raw, Mapping):
        raise _fail(scenario, "faults", f"expected a mapping with drop, duplicate, crash; got {raw!r}")
    for key in raw:
        if key not in FAULT_KEYS:
            raise _fail(scenario, f"faults.{key}",
                        f"unknown key; expected one of {', '.join(sorted(FAULT_KEYS))}")
    drop = _list(scenario, "faults.drop", raw.get("drop", []))
    _names(scenario, "faults.drop", drop, topics | services,
           "a topic with a subscriber or a served service", keyed=False)
    dup = _list(scenario, "faults.duplicate", raw.get("duplicate", []))
    _names(scenario, "faults.duplicate", dup, topics, "a topic with a subscriber "
           "(services cannot be duplicated)", keyed=False)
    crash = _crash(scenario, raw["crash"]) if "crash" in raw else None
    return frozenset(drop), frozenset(dup), crash


def _crash(scenario: Scenario, raw: Any) -> CrashFaults:
    key = "faults.crash"
    if not isinstance(raw, Mapping):
        raise _fail(scenario, key, f"expected a mapping with nodes, max, durable; got {raw!r}")
    for k in raw:
        if k not in CRASH_KEYS:
            raise _fail(scenario, f"{key}.{k}",
                        f"unknown key; expected one of {', '.join(sorted(CRASH_KEYS))}")
    index = {n.name: i for i, n in enumerate(scenario.nodes)}
    nodes = _list(scenario, f"{key}.nodes", raw.get("nodes"))
    if not nodes:
        raise _fail(scenario, f"{key}.nodes", "name at least one node that may crash")
    durable = _list(scenario, f"{key}.durable", raw.get("durable", []))
    for name in (*nodes, *durable):
        if name not in index:
            raise _fail(scenario, key, f"{name!r} is not a node of this scenario")
    most = raw.get("max", 1)
    if not _is_int(most) or most < 1:
        raise _fail(scenario, f"{key}.max", f"expected a number of crashes >= 1, got {most!r}")
    return CrashFaults(tuple(sorted({index[n] for n in nodes})), most,
                       frozenset(index[n] for n in durable))


def parse_settings(scenario: Scenario, topics: set[str], services: set[str], *,
                   latency: tuple[int, int] | None | Sequence[int] = ()) -> CheckSettings:
    """Every optional setting, validated against the scenario's topics and services.

    Args:
        scenario: the parsed scenario.
        topics: fully qualified topics that have at least one subscriber.
        services: fully qualified names of served services.
        latency: an explicit global latency overriding `check.latency` (the
            default, an empty tuple, means "take the scenario's").
    """
    default, per_topic = parse_latency(scenario, topics | services)
    if latency != ():
        default = None if latency is None or tuple(latency) == (0, 0) else (latency[0], latency[1])
    deadline_default, deadlines = parse_deadlines(scenario, topics | services)
    drop, dup, crash = parse_faults(scenario, topics, services)
    return CheckSettings(default, per_topic, deadline_default, deadlines,
                         parse_queue_bounds(scenario), drop, dup, crash)
