"""The node contract: a node is an actor with declared, synchronous handlers.

Handlers run to completion and never block, sleep, await or touch a socket,
clock or `random`; every effect goes through the `Context` they receive
(see `runtime.contract.context`). Entry points are declared on the class, so both the
live host and the checker read the node graph without running anything::

    class Counter(Node):
        Params = CounterParams          # frozen dataclass built from the scenario
        def initial_state(self) -> CounterState: ...

        @on_start
        def start(self, ctx): ...
        @subscribe("ping", priority=2)
        def on_ping(self, ctx, msg: String): ...
        @service("add")
        def add(self, ctx, req: AddRequest) -> AddReply: ...
        @every(100)
        def tick(self, ctx): ...
        @handler(priority=1)            # target of ctx.after / ctx.call replies
        def resume(self, ctx, reason: str): ...

Lower `priority` runs first among simultaneous events of one node.
Everything a handler changes lives in `self.state`; everything else on the
node is configuration built once in `__init__`/`configure`.
"""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from enum import Enum
from typing import Any, ClassVar, Final, Literal, TypeVar

from twinfleet.runtime.contract.names import normalise_namespace, resolve

H = TypeVar("H", bound=Callable[..., Any])

HandlerKind = Literal["subscribe", "service", "every", "start", "handler"]


class NodeDefinitionError(TypeError):
    """A node class declares its handlers wrongly; the message says how to fix it."""


class Reliability(Enum):
    """QoS reliability: RELIABLE blocks the publisher under congestion, BEST_EFFORT drops."""

    RELIABLE = "reliable"
    BEST_EFFORT = "best_effort"


class Durability(Enum):
    """QoS durability: TRANSIENT_LOCAL ("latched") topics replay their last samples to late joiners."""

    VOLATILE = "volatile"
    TRANSIENT_LOCAL = "transient_local"


@dataclass(frozen=True, slots=True)
class QoS:
    """Quality of service of a topic, with rclpy's names."""

    reliability: Reliability = Reliability.RELIABLE
    durability: Durability = Durability.VOLATILE
    depth: int = 10


#: The topic of liveliness events: `@subscribe(LIVELINESS_TOPIC)` gets a `NodeAlive` when a
#: node of the fleet appears or disappears (live only: the checker refuses it at load).
LIVELINESS_TOPIC: Final = "/_liveliness"

QOS_DEFAULT = QoS()
QOS_SENSOR_DATA = QoS(Reliability.BEST_EFFORT, Durability.VOLATILE, 5)
QOS_LATCHED = QoS(Reliability.RELIABLE, Durability.TRANSIENT_LOCAL, 1)


@dataclass(frozen=True, slots=True)
class HandlerSpec:
    """One declared entry point of a node class."""

    kind: HandlerKind
    method: str
    name: str | None = None  # topic or service, unresolved; for `every`, a Params field name
    period_ms: int | None = None
    phase_ms: int = 0
    priority: int = 0
    qos: QoS = QOS_DEFAULT
    commutes: bool = False  # messages at one instant may be handled in any order (checker hint)


_SPEC_ATTR = "__twinfleet_handler__"


def _declare(fn: H, spec: HandlerSpec) -> H:
    if not callable(fn):
        raise NodeDefinitionError(f"@{spec.kind} decorates a function, got {fn!r}")
    if hasattr(fn, _SPEC_ATTR):
        raise NodeDefinitionError(f"{fn.__qualname__} is declared twice (@{spec.kind})")
    setattr(fn, _SPEC_ATTR, dataclasses.replace(spec, method=fn.__name__))
    return fn


def subscribe(topic: str, *, priority: int = 0, qos: QoS = QOS_DEFAULT,
              commutes: bool = False) -> Callable[[H], H]:
    """Declare `fn(self, ctx, msg)` as the handler of messages on `topic`.

    `commutes=True` declares that messages arriving at the same instant (from different
    senders) leave the node in the same state and send the same messages whichever is
    handled first. It changes nothing live; the checker then explores one order of them
    (its partial-order reduction), checking each pair it relies on in both orders.
    """
    spec = HandlerSpec("subscribe", "", topic, priority=priority, qos=qos, commutes=commutes)
    return lambda fn: _declare(fn, spec)


def service(name: str, *, priority: int = 0, commutes: bool = False) -> Callable[[H], H]:
    """Declare `fn(self, ctx, request) -> reply` as the server of service `name`.

    `commutes=True`: requests arriving at the same instant may be served in any order
    (as for `subscribe`).
    """
    spec = HandlerSpec("service", "", name, priority=priority, commutes=commutes)
    return lambda fn: _declare(fn, spec)


def every(period_ms: int | str, *, phase_ms: int = 0, priority: int = 0) -> Callable[[H], H]:
    """Declare `fn(self, ctx)` as a periodic timer firing at phase + period, phase + 2·period, ...

    `period_ms` is a number of ms, or the name of an int field of the node's Params.
    """
    if isinstance(period_ms, str):
        spec = HandlerSpec("every", "", period_ms, None, phase_ms, priority)
        return lambda fn: _declare(fn, spec)
    if not isinstance(period_ms, int) or period_ms <= 0:
        raise NodeDefinitionError(f"@every needs an integer period_ms > 0, got {period_ms!r}")
    spec = HandlerSpec("every", "", None, period_ms, phase_ms, priority)
    return lambda fn: _declare(fn, spec)


def on_start(fn: H | None = None, *, priority: int = 0) -> Any:
    """Declare `fn(self, ctx)` to run once when the node starts (time 0)."""
    spec = HandlerSpec("start", "", priority=priority)
    if fn is None:
        return lambda f: _declare(f, spec)
    return _declare(fn, spec)


def handler(fn: H | None = None, *, priority: int = 0) -> Any:
    """Declare `fn(self, ctx, *args)` as a target of `ctx.after` or of `ctx.call` replies.

    Used bare (`@handler`) or with options (`@handler(priority=1)`), as `@on_start`.
    """
    spec = HandlerSpec("handler", "", priority=priority)
    if fn is None:
        return lambda f: _declare(f, spec)
    return _declare(fn, spec)


@dataclass(frozen=True, slots=True)
class NodeSpec:
    """Every handler a node class declares, collected once per class."""

    handlers: tuple[HandlerSpec, ...]
    publications: Mapping[str, QoS]

    def by_method(self, method: str) -> HandlerSpec | None:
        """The spec of `method`, or None if the method is not declared."""
        for spec in self.handlers:
            if spec.method == method:
                return spec
        return None

    def of_kind(self, kind: HandlerKind) -> tuple[HandlerSpec, ...]:
        """The specs of one kind, in declaration order."""
        return tuple(s for s in self.handlers if s.kind == kind)

    @staticmethod
    def of(cls: type[Node]) -> NodeSpec:
        """Collect and validate the handler specs of a node class (cached)."""
        cached = cls.__dict__.get("_node_spec")
        if cached is not None:
            return cached
        specs: list[HandlerSpec] = []
        seen_names: dict[tuple[str, str], str] = {}
        for attr in _class_attributes_in_order(cls):
            fn = getattr(cls, attr)
            spec = getattr(fn, _SPEC_ATTR, None)
            if spec is None:
                continue
            _check_signature(cls, fn, spec)
            if spec.kind == "service":
                key = (spec.kind, spec.name or "")
                if key in seen_names:
                    raise NodeDefinitionError(
                        f"{cls.__name__}: service {spec.name!r} served by both "
                        f"{seen_names[key]} and {attr}"
                    )
                seen_names[key] = attr
            specs.append(spec)
        result = NodeSpec(tuple(specs), dict(getattr(cls, "publications", {})))
        cls._node_spec = result  # type: ignore[attr-defined]
        return result


def _class_attributes_in_order(cls: type) -> list[str]:
    seen: dict[str, None] = {}
    for klass in reversed(cls.__mro__):
        for attr in vars(klass):
            seen.setdefault(attr, None)
    return list(seen)


_ARITY = {"subscribe": 3, "service": 3, "every": 2, "start": 2}


def _check_signature(cls: type, fn: Callable[..., Any], spec: HandlerSpec) -> None:
    if inspect.iscoroutinefunction(fn):
        raise NodeDefinitionError(
            f"{cls.__name__}.{spec.method} is async: handlers are synchronous and run to completion"
        )
    want = _ARITY.get(spec.kind)
    if want is None:
        return
    params = [
        p for p in inspect.signature(fn).parameters.values()
        if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)
    ]
    if len(params) != want:
        shape = "(self, ctx, msg)" if want == 3 else "(self, ctx)"
        raise NodeDefinitionError(
            f"{cls.__name__}.{spec.method}: @{spec.kind} handlers take {shape}, "
            f"got {len(params)} positional parameters"
        )


class PureMemo:
    """Base class of a memo of pure functions that a node keeps outside `self.state`.

    A node may keep attributes besides `state` only when they are configuration (set
    in `configure`, never changed by a handler) or a *pure memo*: an object that
    caches answers of functions of their arguments alone (a scan of a static map, a
    plan), whose content may grow while its answers never change. Derive such a
    cache from `PureMemo` to declare it: the checker then knows it is not state
    (`--debug-state` does not report it filling up), both drivers keep it across
    handlers and it is never rolled back. A memo whose answers depend on what it
    saw before breaks the node contract, as any state outside `self.state` does.
    """

    __slots__ = ()


@dataclass(frozen=True, slots=True)
class NoParams:
    """Parameters of a node that takes none."""


class Node:
    """Base class of every node. Subclasses set `Params`, `initial_state` and handlers.

    Attributes:
        name: unique node name ("map_server", "r1").
        namespace: "/r1"; relative names resolve against it ("" is the root).
        params: frozen parameters built once from the scenario.
        state: the only value handlers change; the drivers snapshot and restore it.
    """

    Params: ClassVar[type[Any]] = NoParams
    publications: ClassVar[Mapping[str, QoS]] = {}

    def __init__(self, name: str, params: Any = None, *, namespace: str | None = None) -> None:
        self.name = name
        self.namespace = normalise_namespace(namespace)
        self.params = params if params is not None else self.Params()
        NodeSpec.of(type(self))
        self.configure()
        self.state = self.initial_state()

    def configure(self) -> None:
        """Build immutable configuration (maps, tables) from `self.params`; override if needed."""

    def initial_state(self) -> Any:
        """Return the state at time 0; pure. Override in subclasses."""
        return None

    def resolve(self, name: str) -> str:
        """The fully qualified form of a topic or service name used by this node."""
        return resolve(name, self.namespace, self.name)

    def period_ms(self, spec: HandlerSpec) -> int:
        """The period of an `@every` timer of this node, resolving a Params field name."""
        period = spec.period_ms if spec.name is None else getattr(self.params, spec.name, None)
        if not isinstance(period, int) or period <= 0:
            raise NodeDefinitionError(
                f"{type(self).__name__}.{spec.method}: @every period must be an int > 0, "
                f"got {period!r} (from {spec.name or 'the decorator'})"
            )
        return period

    @classmethod
    def spec(cls) -> NodeSpec:
        """The declared handlers of this class."""
        return NodeSpec.of(cls)
