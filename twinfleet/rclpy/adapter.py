"""An rclpy `Node` subclass as a contract node: one adapter class per rclpy class.

`adapt(cls)` builds the class once: it constructs the rclpy node a first time with
its own name (the *probe*) to learn what its `__init__` creates, and declares to the
contract, as the native decorators do at class creation:

- each subscription as an ``@subscribe(topic, qos=...)`` handler and each service as an
  ``@service(name)`` handler, named after the rclpy callback (``on_pose``) so that traces
  and logs read as the node's code does (``sub_<i>``/``srv_<i>`` when the name is taken
  or not a plain public name);
- each client's replies as ``@handler`` s ``reply_<i>`` (its first pending call) and
  ``reply_<i>_<k>`` (further calls pending at once, `CALL_SLOTS` in all), the targets of
  `ctx.call`: the handler a reply arrives at names the call it answers, as rclpy matches
  a response to its request's sequence number, whatever order replies come back in;
- timers as ``ctx.after`` events of one ``@handler`` ``timer(index)``, scheduled by
  ``@on_start`` and by each firing, so they can be cancelled, reset and made at run
  time;
- its publishers' QoS as `publications`, its declared parameters as the `Params`
  dataclass the scenario's `params:` are checked against.

Each scenario node is then one adapter instance that builds its own rclpy node with
the scenario's name, namespace and parameters (`configure`); its `state` is the rclpy
node's state (`twinfleet.rclpy.state`).
"""

from __future__ import annotations

import dataclasses
import keyword
from collections.abc import Callable
from typing import Any, ClassVar

from twinfleet.rclpy import param_service
from twinfleet.rclpy.engine import CALL_SLOTS, Construction, Engine, building, reply_method
from twinfleet.rclpy.state import RclpyState, apply_state, capture
from twinfleet.runtime.contract.context import Context
from twinfleet.runtime.contract.node import (
    Node as ContractNode,
)
from twinfleet.runtime.contract.node import (
    NodeDefinitionError,
    handler,
    on_start,
    service,
    subscribe,
)


class RclpyAdapter(ContractNode):
    """Base of the adapter classes `adapt` makes (module docstring)."""

    rclpy_class: ClassVar[type]
    _tf_shape: ClassVar[tuple[Any, ...]]

    def configure(self) -> None:
        """Build the rclpy node with this scenario node's name, namespace and parameters."""
        overrides = {f.name: _parameter_value(getattr(self.params, f.name))
                     for f in dataclasses.fields(self.params)}
        made = Construction(self.name, self.namespace, overrides, adapter=self)
        with building(made):
            node = self.rclpy_class()
        engine: Engine = node._tf_engine
        self._tf_engine = engine
        self.namespace = engine.namespace
        if _shape(engine) != self._tf_shape:
            raise NodeDefinitionError(
                f"{self.rclpy_class.__qualname__} as {self.name}: its subscriptions, services "
                "or clients differ from those it creates with its own name and default "
                "parameters; twinfleet declares them once per class")

    def initial_state(self) -> RclpyState:
        """The rclpy node's state after its `__init__`."""
        return capture(self._tf_engine)

    @property
    def state(self) -> RclpyState:
        """The rclpy node's attributes and the engine's records, as one value."""
        return capture(self._tf_engine)

    @state.setter
    def state(self, value: RclpyState) -> None:
        apply_state(self._tf_engine, value)

    @property
    def rclpy_node(self) -> Any:
        """The rclpy node object this adapter runs."""
        return self._tf_engine.node

    def live_params(self) -> dict[str, Any]:
        """The parameters in force (those `param set` changed too), for ``param get``."""
        return {name: _parameter_value(value)
                for name, value in dict(self._tf_engine.dyn.params).items()}

    @on_start
    def start(self, ctx: Context) -> None:
        """The node starts: what its __init__ published, its timers' first firings."""
        self._tf_engine.start(ctx)

    @handler
    def timer(self, ctx: Context, index: int) -> None:
        """Timer `index` of the rclpy node fires."""
        self._tf_engine.on_timer(ctx, index)

    @service(param_service.SERVICE)
    def set_parameter(self, ctx: Context,
                          request: param_service.SetParameter) -> param_service.SetParameterResult:
        with self._tf_engine.handling(ctx):
            return param_service.set_parameter(self._tf_engine.node, request)


def _parameter_value(value: Any) -> Any:
    return list(value) if isinstance(value, tuple) else value


def _shape(engine: Engine) -> tuple[Any, ...]:
    return (tuple((s.topic, s.qos) for s in engine.subscriptions),
            tuple(s.name for s in engine.services), tuple(c.name for c in engine.clients))


_ADAPTED: dict[type, type[RclpyAdapter]] = {}


def adapt(cls: type) -> type[RclpyAdapter]:
    """The adapter class of an rclpy `Node` subclass (built once per class)."""
    made = _ADAPTED.get(cls)
    if made is not None:
        return made
    with building(Construction()):
        probe = cls()
    engine: Engine = probe._tf_engine
    namespace: dict[str, Any] = {
        "__module__": cls.__module__, "__qualname__": cls.__qualname__,
        "__doc__": cls.__doc__, "rclpy_class": cls, "_tf_shape": _shape(engine),
        "Params": _params_class(cls, engine.dyn.params),
        "publications": {p.topic: p.qos for p in engine.publishers},
    }
    for i, sub in enumerate(engine.subscriptions):
        name = _handler_name(sub.callback, f"sub_{i}", namespace)
        namespace[name] = subscribe(sub.topic, qos=sub.qos)(_on_message(i, name))
    for i, srv in enumerate(engine.services):
        name = _handler_name(srv.callback, f"srv_{i}", namespace)
        namespace[name] = service(srv.name)(_on_request(i, name))
    for i in range(len(engine.clients)):
        for k in range(CALL_SLOTS):
            name = reply_method(i, k)
            namespace[name] = handler(_on_reply(i, k, name))
    made = _ADAPTED[cls] = type(cls.__name__, (RclpyAdapter,), namespace)
    return made


def _named(fn: Callable[..., Any], name: str) -> Callable[..., Any]:
    fn.__name__ = fn.__qualname__ = name
    return fn


def _handler_name(callback: Any, fallback: str, taken: dict[str, Any]) -> str:
    """The rclpy callback's own name when it is free on the adapter, else `fallback`."""
    name = getattr(getattr(callback, "__func__", callback), "__name__", "")
    if (not name.isidentifier() or name.startswith("_") or keyword.iskeyword(name)
            or name in taken or hasattr(RclpyAdapter, name)):
        return fallback
    return name


def _on_message(i: int, name: str) -> Callable[..., Any]:
    def method(self: RclpyAdapter, ctx: Context, msg: Any) -> None:
        self._tf_engine.on_message(ctx, i, msg)
    return _named(method, name)


def _on_request(i: int, name: str) -> Callable[..., Any]:
    def method(self: RclpyAdapter, ctx: Context, request: Any) -> Any:
        return self._tf_engine.on_request(ctx, i, request)
    return _named(method, name)


def _on_reply(i: int, k: int, name: str) -> Callable[..., Any]:
    def method(self: RclpyAdapter, ctx: Context, reply: Any) -> None:
        self._tf_engine.on_reply(ctx, i, k, reply)
    return _named(method, name)


_HINTS = {bool: bool, int: int, float: float, str: str, bytes: bytes}


def _params_class(cls: type, declared: dict[str, Any]) -> type:
    """A frozen dataclass of the parameters the class declares, with their defaults: the
    scenario's `params:` are checked against it (names that are no identifier, such as
    ``a.b``, keep their defaults and cannot be set from a scenario)."""
    fields: list[tuple[str, Any, Any]] = []
    for name, value in declared.items():
        if not name.isidentifier() or keyword.iskeyword(name):
            continue
        if isinstance(value, list | tuple):
            item = _HINTS.get(type(value[0]), Any) if value else Any
            fields.append((name, tuple[item, ...],  # type: ignore[valid-type]
                           dataclasses.field(default=tuple(value))))
        else:
            fields.append((name, _HINTS.get(type(value), Any),
                           dataclasses.field(default=value)))
    return dataclasses.make_dataclass(f"{cls.__name__}Params", fields, frozen=True)
