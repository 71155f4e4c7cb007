"""What a node process and a fleet tell monitors about themselves; launch-time overrides.

Every node process serves ``twinfleet/<fleet>/@info/<node>``
(`runtime.host.keys.KeyKind.INFO`): a msgpack map built once from the scenario
entry and the node class's declared handlers (`node_description`)::

    {"name", "namespace", "class", "pid",
     "params":        {name: value},            # in force when asked (`params_in_force`)
     "subscriptions": {"/listener/chatter": qos}, "services": ["/add_two_ints"],
     "subscription_types": {"/listener/chatter": "std_msgs/String"},
     "service_types": {"/add_two_ints": ["example_interfaces/AddTwoInts_Request",
                                         "example_interfaces/AddTwoInts_Response"]},
     "timers": [{"handler", "period_ms"}],    # @every; ctx.after targets: "after": True
     "clients": ["/add_two_ints"],            # services its code calls (`lint.code_uses`)
     "publication_qos": {"/map": qos},
     "publications":  {"/chatter": "std_msgs/String"}}   # published so far

with ``qos = {"reliability", "durability", "depth"}``. `twinfleet node info`,
`topic info`, `service list -t|type` and `param list|get` read it (a
service's request and reply types, and the type a subscription admits, come
from the handler's annotations, "?" where it has none; `topic pub` and
`service call` refuse another type by them); what a node *publishes* is only
known once it publishes (its ``@pub`` liveliness token and ``publications``,
which records the envelope type of each topic's first message), and its QoS
is ``publication_qos`` or the default.

The fleet as a whole is described on ``twinfleet/<fleet>/@fleet`` (`fleet_key`)
by its launcher, and by `twinfleet play` for a recording: a msgpack map
``{"scene": "module:Name" | None, "latched": [topic, ...]}`` (`fleet_description`):
the scenario's scene (`runtime.contract.scene`) and the topics its nodes declare
transient-local. A viewer that finds the fleet only over Zenoh asks it there,
once the fleet's first sample arrives, so that it learns how to draw the fleet
and which topics to ask history of.

Overrides (``r1.speed:=0.4``) are parsed and validated by
`runtime.scenario.overrides`, shared with `check`; the launcher hands the same
``--param`` arguments to every node process (`param_arguments`), which loads
its scenario with them the same way.
"""

from __future__ import annotations

import dataclasses
import os
import typing
from collections.abc import Mapping, Sequence
from typing import Any

from twinfleet.runtime.contract.dispatch import declared_message_type
from twinfleet.runtime.contract.messages import type_name_of
from twinfleet.runtime.contract.names import resolve
from twinfleet.runtime.contract.node import Durability, HandlerSpec, NodeSpec, QoS
from twinfleet.runtime.host.keys import KeyKind, node_key, topic_in_fleet
from twinfleet.runtime.scenario.lint import code_uses
from twinfleet.runtime.scenario.overrides import (  # noqa: F401 (launch and node processes load here)
    load_with_params,
    overrides_doc,
    parse_param,
    scenario_common,
)

PARAM_FLAG = "--param"


def fleet_description(scenario: Any) -> dict[str, Any]:
    """What `fleet_key` serves for a scenario: its scene and its latched topics."""
    return {"scene": scenario.scene, "latched": latched_topics(scenario)}


def latched_topics(scenario: Any) -> list[str]:
    """The topics that the scenario's node classes publish or subscribe transient-local,
    by fully qualified name: what a late joiner gets only from history."""
    found: set[str] = set()
    for cfg in scenario.nodes:
        spec = NodeSpec.of(cfg.cls)
        declared = [*spec.publications.items(),
                    *((s.name or "", s.qos) for s in spec.of_kind("subscribe"))]
        found.update(resolve(name, cfg.namespace, cfg.name) for name, qos in declared
                     if name and qos.durability is Durability.TRANSIENT_LOCAL)
    return sorted(found)


def qos_dict(qos: QoS) -> dict[str, Any]:
    """A QoS as plain values, with rclpy's policy names."""
    return {"reliability": qos.reliability.value, "durability": qos.durability.value,
            "depth": qos.depth}


def plain_value(value: Any) -> Any:
    """A parameter value as msgpack-ready data (tuples → lists, other objects → str)."""
    if isinstance(value, bool | int | float | str | bytes) or value is None:
        return value
    if isinstance(value, list | tuple):
        return [plain_value(v) for v in value]
    if isinstance(value, Mapping):
        return {str(k): plain_value(v) for k, v in value.items()}
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: plain_value(getattr(value, f.name)) for f in dataclasses.fields(value)}
    return str(value)


def _type_name(cls: type | None) -> str:
    return "?" if cls is None else type_name_of(cls)


def service_types(node: Any, spec: HandlerSpec) -> list[str]:
    """[request type, reply type] of a service handler, from its annotations ("?" if unknown):
    the request as `dispatch.declared_message_type` reads it for the admission check."""
    try:
        reply = typing.get_type_hints(getattr(type(node), spec.method)).get("return")
    except Exception:  # an unresolvable forward reference: say what is known, nothing
        reply = None
    if not (isinstance(reply, type) and hasattr(reply, "__message_type__")):
        reply = None
    return [_type_name(declared_message_type(node, spec.method)), _type_name(reply)]


def node_description(node: Any, class_path: str) -> dict[str, Any]:
    """What a node's ``@info`` queryable serves for a built node object (module docstring)."""
    spec = NodeSpec.of(type(node))
    params = node.params
    values = ({f.name: plain_value(getattr(params, f.name)) for f in dataclasses.fields(params)}
              if dataclasses.is_dataclass(params) else {})
    timers = []
    for s in spec.of_kind("every"):
        try:
            period = node.period_ms(s)
        except Exception:  # a bad period fails the node elsewhere; describe what is known
            period = None
        timers.append({"handler": s.method, "period_ms": period})
    clients, scheduled = code_uses(type(node))
    timers += [{"handler": method, "period_ms": None, "after": True} for method in scheduled]
    return {"name": node.name, "namespace": node.namespace or "/", "class": class_path,
            "pid": os.getpid(), "params": values,
            "subscriptions": {node.resolve(s.name or ""): qos_dict(s.qos)
                              for s in spec.of_kind("subscribe")},
            "subscription_types": {node.resolve(s.name or ""):
                                   _type_name(declared_message_type(node, s.method))
                                   for s in spec.of_kind("subscribe")},
            "services": [node.resolve(s.name or "") for s in spec.of_kind("service")],
            "service_types": {node.resolve(s.name or ""): service_types(node, s)
                              for s in spec.of_kind("service")},
            "timers": timers,
            "clients": sorted({node.resolve(_client(name, params)) for name in clients}),
            "publication_qos": {node.resolve(t): qos_dict(q)
                                for t, q in spec.publications.items()}}


def params_in_force(node: Any, at_start: dict[str, Any]) -> dict[str, Any]:
    """The node's parameters now: a node whose parameters change while it runs (an rclpy
    node takes `param set`) says so through ``live_params()``; the others keep the values
    they were launched with, `at_start`."""
    live = getattr(node, "live_params", None)
    if live is None:
        return at_start
    return {str(k): plain_value(v) for k, v in live().items()}


def _client(name: str, params: Any) -> str:
    """A service a node's code calls, a parameter's value where it names one."""
    if name.startswith("params."):
        value = getattr(params, name.removeprefix("params."), None)
        return value if isinstance(value, str) else f"<{name}>"
    return name


def serve_info(transport: Any, fleet: str, node: Any, class_path: str) -> None:
    """Serve `node_description` on the node's ``@info`` key through a `Transport`, with
    ``publications``: topic → message type of every topic the node has published on so far.

    Call it before the host first publishes: it wraps `transport.publisher` so that the
    first payload of each topic records its envelope type (one dict lookup per message).
    """
    import msgpack

    base = node_description(node, class_path)
    published: dict[str, str] = {}
    make_publisher = transport.publisher

    def publisher(key: str, qos: QoS) -> Any:
        put = make_publisher(key, qos)
        where = topic_in_fleet(fleet, key)
        topic = key if where is None else where.topic

        def put_and_note(payload: bytes) -> None:
            if topic not in published:
                published[topic] = _envelope_type(payload)
            put(payload)
        return put_and_note

    transport.publisher = publisher

    def respond_info(_request: bytes, respond: Any) -> None:
        described = {**base, "params": params_in_force(node, base["params"]),
                     "publications": dict(published)}
        respond(msgpack.packb(described, use_bin_type=True), "")

    transport.serve(node_key(fleet, KeyKind.INFO, node.name), respond_info)



def _envelope_type(payload: bytes) -> str:
    import msgpack

    try:
        kind = msgpack.unpackb(payload, raw=False).get("type")
    except Exception:  # msgpack raises several unrelated types; never break a publish
        return "?"
    return kind if isinstance(kind, str) else "?"


def param_arguments(params: Sequence[str]) -> list[str]:
    """``--param X`` for each override: what the launcher appends to a node's command line."""
    return [arg for p in params for arg in (PARAM_FLAG, p)]
