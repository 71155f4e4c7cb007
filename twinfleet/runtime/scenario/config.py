"""A scenario's `check:` and `live:` settings as typed, frozen values, checked when built.

`CheckConfig` and `LiveConfig` are what `Scenario.check` and `Scenario.live`
hold. The scenario loader builds them from the YAML mappings
(`check_config`, `live_config`); Python code may build them directly, with
the same checks: every constructor normalises its values (lists become
tuples, ints become floats where seconds are meant, a bare value or a
``{default: ..., name: ...}`` mapping becomes a `PerName`) and raises
`ConfigError` naming the key (``check.latency.default``) and what was
expected. Rules that need the compiled node graph (is ``/r1/scan`` a topic
with a subscriber?) are the checker's: `checker.faults` applies them when it
builds a `System`; rules that need the node list (is ``r1`` a node?) are the
scenario's (`runtime.scenario.spec`).

The meaning of each checker setting is documented in `checker.faults`; the
live settings in `runtime.fleet.launcher` (report, summary topics, wall timeout,
horizon, time scale) and `runtime.fleet.node_main` (stop_on_error, time scale).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from enum import StrEnum, unique
from typing import Any, Final, Generic, TypeVar, final

from twinfleet.runtime.scenario.suggest import did_you_mean

T = TypeVar("T")
C = TypeVar("C")
Range = tuple[int, int]
"""A latency range in ms, ``(min, max)`` with ``0 <= min <= max``."""

SEARCHES: Final = ("bfs", "dfs", "random")
LIVE_STOPS: Final = ("timeout", "settled", "violation")  # `live.stop`: what ends a live run
DEFAULT: Final = "default"


@unique
class Fairness(StrEnum):
    """What an `eventually` property's counterexample may assume of lossy channels
    (`check.fairness`, `check --fairness`; defined in docs/finite-state.md)."""

    NONE = "none"  # every reachable cycle on which the property never holds counts
    WEAK = "weak"  # only a cycle on which every message dropped is also handled counts


class ConfigError(ValueError):
    """A setting has a bad value: `key` is its dotted name (``check.faults.crash.max``)."""

    def __init__(self, key: str, what: str) -> None:
        super().__init__(f"{key}: {what}")
        self.key, self.what = key, what


@final
@dataclass(frozen=True, slots=True)
class PerName(Generic[T]):
    """A setting given once for every name (`default`) and/or per name (`names`, sorted)."""

    default: T | None = None
    names: tuple[tuple[str, T], ...] = ()

    def get(self, name: str) -> T | None:
        """The value for `name`: its own, else the default (None: not set)."""
        return dict(self.names).get(name, self.default)

    def named(self) -> tuple[str, ...]:
        """The names that have their own value."""
        return tuple(name for name, _ in self.names)

    def __bool__(self) -> bool:
        return self.default is not None or bool(self.names)


@final
@dataclass(frozen=True, slots=True)
class CrashConfig:
    """`check.faults.crash`: which nodes may crash, how often per path, which keep their state."""

    nodes: tuple[str, ...]
    max: int = 1
    durable: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        key = "check.faults.crash"
        _set(self, "nodes", _names(f"{key}.nodes", self.nodes))
        if not self.nodes:
            raise ConfigError(f"{key}.nodes", "name at least one node that may crash")
        _set(self, "durable", _names(f"{key}.durable", self.durable))
        if not _is_int(self.max) or self.max < 1:
            raise ConfigError(f"{key}.max", f"expected a number of crashes >= 1, got {self.max!r}")


@final
@dataclass(frozen=True, slots=True)
class FaultConfig:
    """`check.faults`: names whose deliveries may be dropped or duplicated, and node crashes."""

    drop: tuple[str, ...] = ()
    duplicate: tuple[str, ...] = ()
    crash: CrashConfig | None = None

    def __post_init__(self) -> None:
        _set(self, "drop", _names("check.faults.drop", self.drop))
        _set(self, "duplicate", _names("check.faults.duplicate", self.duplicate))
        if self.crash is not None:
            _set(self, "crash", from_mapping(CrashConfig, self.crash, "check.faults.crash"))


@final
@dataclass(frozen=True, slots=True)
class CheckConfig:
    """`check:`, the checker's settings; every one optional (see `checker.faults`)."""

    search: str | None = None  # None: not said (breadth-first; relaxed across workers)
    max_states: int | None = None
    max_depth: int | None = None
    max_time_s: float | None = None
    global_priority: bool = False
    latency: PerName[Range] = PerName()
    deadline_ms: PerName[int] = PerName()
    queue_bound: PerName[int] = PerName()
    faults: FaultConfig = field(default_factory=FaultConfig)
    fairness: Fairness = Fairness.NONE
    timer_lateness: Range | None = None

    def __post_init__(self) -> None:
        if self.fairness not in tuple(Fairness):
            raise ConfigError("check.fairness", f"expected one of "
                              f"{', '.join(Fairness)}, got {self.fairness!r}")
        _set(self, "fairness", Fairness(self.fairness))
        if self.search is not None and self.search not in SEARCHES:
            raise ConfigError("check.search", f"expected one of {', '.join(SEARCHES)}, "
                              f"got {self.search!r}")
        for name in ("max_states", "max_depth"):
            _optional(self, "check", name, _count)
        _optional(self, "check", "max_time_s", _seconds)
        _optional(self, "check", "timer_lateness", _range)
        _bool("check.global_priority", self.global_priority)
        _set(self, "latency", _per_name("check.latency", self.latency, _range))
        _set(self, "deadline_ms", _per_name("check.deadline_ms", self.deadline_ms, _ms))
        _set(self, "queue_bound", _per_name("check.queue_bound", self.queue_bound, _bound))
        _set(self, "faults", from_mapping(FaultConfig, self.faults, "check.faults"))


@final
@dataclass(frozen=True, slots=True)
class LiveConfig:
    """`live:`, the launcher's and the node processes' settings.

    Two limits, each with one meaning: `wall_timeout_s`, wall seconds a launch runs once
    its fleet is up, and `horizon_s`, fleet seconds a run covers (a launch ends there
    too, at any time scale; the statistical checker simulates that far). `timeout_s` is
    the old key: it is taken as `wall_timeout_s` (the lint says so in one line)."""

    wall_timeout_s: float | None = None
    horizon_s: float | None = None
    timeout_s: float | None = None  # deprecated: moved into wall_timeout_s when built
    stop_on_error: bool = False
    time_scale: float = 1.0
    report: str | None = None
    summary_topics: tuple[str, ...] = ()
    max_payload_bytes: int | None = None  # per sample; default sized to the map (runtime.core.guard)
    max_nodes: int = 100  # nodes a scenario may have (checked first by runtime.scenario.spec)
    # "settled": end the run once every eventually (and within) property has held;
    # "violation": end it at the first violation the live verdict sees;
    # "timeout": run until the timeout, a shutdown request, a failure or Ctrl-C
    stop: str = "timeout"

    def __post_init__(self) -> None:
        for name in ("wall_timeout_s", "horizon_s", "timeout_s"):
            _optional(self, "live", name, _positive)
        if self.timeout_s is not None:
            if self.wall_timeout_s is not None:
                raise ConfigError("live.timeout_s", "give live.wall_timeout_s only (timeout_s "
                                                    "is its old name)")
            _set(self, "wall_timeout_s", self.timeout_s)
            _set(self, "timeout_s", None)
        if self.stop not in LIVE_STOPS:
            raise ConfigError("live.stop", f"expected one of {', '.join(LIVE_STOPS)}, "
                                           f"got {self.stop!r}")
        if self.max_payload_bytes is not None and (
                type(self.max_payload_bytes) is not int or self.max_payload_bytes < 1024):
            raise ConfigError("live.max_payload_bytes",
                              f"expected an integer >= 1024, got {self.max_payload_bytes!r}")
        _set(self, "time_scale", _positive("live.time_scale", self.time_scale))
        _bool("live.stop_on_error", self.stop_on_error)
        if self.report is not None and (not isinstance(self.report, str)
                                        or ":" not in self.report):
            raise ConfigError("live.report", f"expected 'module:factory', got {self.report!r}")
        _set(self, "summary_topics", _names("live.summary_topics", self.summary_topics))


DEFAULT_ROS2_ROUTER = "tcp/127.0.0.1:7447"  # where rmw_zenohd listens


@final
@dataclass(frozen=True, slots=True)
class Ros2Config:
    """`ros2:`, the ROS 2 bridge that `launch` runs beside the fleet (docs/ros2.md): the ROS 2
    domain, the router of the ROS 2 network, the ROS 2 topics routed into fleet topics
    (``{/goal_pose: /r1/goal}``) and the mapping (default: the one the scene names)."""

    domain: int = 0
    router: str = DEFAULT_ROS2_ROUTER
    inbound: tuple[tuple[str, str], ...] = ()
    mapping: str | None = None

    def __post_init__(self) -> None:
        if type(self.domain) is not int or not 0 <= self.domain <= 232:
            raise ConfigError("ros2.domain", f"expected a ROS domain id 0..232, got {self.domain!r}")
        if not isinstance(self.router, str) or "/" not in self.router:
            raise ConfigError("ros2.router", f"expected a Zenoh endpoint such as "
                                             f"{DEFAULT_ROS2_ROUTER}, got {self.router!r}")
        if self.mapping is not None and (not isinstance(self.mapping, str)
                                         or ":" not in self.mapping):
            raise ConfigError("ros2.mapping", f"expected 'module:Mapping', got {self.mapping!r}")
        raw: Any = self.inbound
        pairs = list(raw.items()) if isinstance(raw, Mapping) else list(raw)
        for pair in pairs:
            if (not isinstance(pair, tuple | list) or len(pair) != 2
                    or not all(isinstance(t, str) and t.startswith("/") for t in pair)):
                raise ConfigError("ros2.inbound", "expected a mapping of ROS 2 topic to fleet "
                                                  f"topic, e.g. {{/goal_pose: /r1/goal}}; got {raw!r}")
        _set(self, "inbound", tuple((str(a), str(b)) for a, b in pairs))


def ros2_config(raw: Any) -> Ros2Config:
    """`ros2:` from its YAML mapping (or a `Ros2Config`, returned as it is)."""
    return from_mapping(Ros2Config, {} if raw is None else raw, "ros2")


def check_config(raw: Any) -> CheckConfig:
    """`check:` from its YAML mapping (or a `CheckConfig`, returned as it is)."""
    return from_mapping(CheckConfig, {} if raw is None else raw, "check")


def live_config(raw: Any) -> LiveConfig:
    """`live:` from its YAML mapping (or a `LiveConfig`, returned as it is)."""
    return from_mapping(LiveConfig, {} if raw is None else raw, "live")


def from_mapping(cls: type[C], raw: Any, key: str) -> C:
    """An instance of the config dataclass `cls` from a mapping of its fields (keys checked)."""
    if isinstance(raw, cls):
        return raw
    names = [f.name for f in dataclasses.fields(cls)]  # type: ignore[arg-type]
    if not isinstance(raw, Mapping):
        raise ConfigError(key, f"expected a mapping with {', '.join(names)}; got {raw!r}")
    for k in raw:
        if k not in names:
            raise ConfigError(f"{key}.{k}", f"unknown key; expected one of "
                              f"{', '.join(sorted(names))}{did_you_mean(str(k), names)}")
    required = [f.name for f in dataclasses.fields(cls)  # type: ignore[arg-type]
                if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING]
    for name in required:
        if name not in raw:
            raise ConfigError(f"{key}.{name}", "missing")
    return cls(**raw)


def to_mapping(config: Any) -> dict[str, Any]:
    """The YAML form of a config dataclass: only the fields that differ from their default."""
    out = {}
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        default = f.default_factory() if f.default_factory is not dataclasses.MISSING else f.default
        if value != default:
            out[f.name] = _plain(value)
    return out


def _plain(value: Any) -> Any:
    if isinstance(value, PerName):
        if not value.names:
            return _plain(value.default)
        head = {} if value.default is None else {DEFAULT: _plain(value.default)}
        return {**head, **{k: _plain(v) for k, v in value.names}}
    if dataclasses.is_dataclass(value):
        return to_mapping(value)
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    return value


def _set(obj: Any, name: str, value: Any) -> None:
    object.__setattr__(obj, name, value)  # normalising a frozen dataclass in __post_init__


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _bool(key: str, value: Any) -> None:
    if not isinstance(value, bool):
        raise ConfigError(key, f"expected true or false, got {value!r}")


def _optional(obj: Any, section: str, name: str, check: Callable[[str, Any], Any]) -> None:
    value = getattr(obj, name)
    if value is not None:
        _set(obj, name, check(f"{section}.{name}", value))


def _count(key: str, value: Any) -> int:
    if not _is_int(value) or value < 0:
        raise ConfigError(key, f"expected a whole number >= 0 (0: no limit), got {value!r}")
    return value


def _seconds(key: str, value: Any) -> float:
    if not isinstance(value, int | float) or isinstance(value, bool) or value < 0:
        raise ConfigError(key, f"expected seconds >= 0 (0: no limit), got {value!r}")
    return float(value)


def _positive(key: str, value: Any) -> float:
    if not isinstance(value, int | float) or isinstance(value, bool) or value <= 0:
        raise ConfigError(key, f"expected a number > 0, got {value!r}")
    return float(value)


def _range(key: str, value: Any) -> Range:
    if not isinstance(value, list | tuple) or len(value) != 2 or not all(map(_is_int, value)):
        raise ConfigError(key, f"expected [min, max] in ms, got {value!r}")
    if not 0 <= value[0] <= value[1]:
        raise ConfigError(key, f"latency must be [min, max] with 0 <= min <= max, "
                          f"got {list(value)}")
    return (value[0], value[1])


def _ms(key: str, value: Any) -> int:
    if not _is_int(value) or value < 0:
        raise ConfigError(key, f"expected milliseconds >= 0, got {value!r}")
    return value


def _bound(key: str, value: Any) -> int:
    if not _is_int(value) or value < 1:
        raise ConfigError(key, f"expected a number of pending events >= 1, got {value!r}")
    return value


def _names(key: str, value: Any) -> tuple[str, ...]:
    if not isinstance(value, list | tuple) or not all(isinstance(v, str) for v in value):
        raise ConfigError(key, f"expected a list of names, got {value!r}")
    return tuple(value)


def _per_name(key: str, value: Any, check: Callable[[str, Any], T]) -> PerName[T]:
    """A `PerName` from a bare value, a ``{default: v, name: v}`` mapping or a `PerName`."""
    if isinstance(value, PerName):
        default, pairs = value.default, value.names
    elif isinstance(value, Mapping):
        default = value.get(DEFAULT)
        pairs = tuple((k, v) for k, v in value.items() if k != DEFAULT)
    else:
        default, pairs = value, ()
    for name, _ in pairs:
        if not isinstance(name, str):
            raise ConfigError(key, f"expected names as keys, got {name!r}")
    default_key = key if default is value else f"{key}.{DEFAULT}"
    return PerName(None if default is None else check(default_key, default),
                   tuple(sorted((name, check(f"{key}.{name}", v)) for name, v in pairs)))

