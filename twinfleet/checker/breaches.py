"""The contract breaches a handler run shows once it has run (`checker.diagnosis`).

A misused ctx, an attribute other than `state` that changed (by identity; with
`debug_state`, by value), and a message sent whose type is not the one the receiving
handler declares, found at the send in the words the live fleet uses for it. Each is one
`Breach`: the failure kind, the node, the handler and the message `checker.runner.Runner`
reports.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, final

from twinfleet.checker.diagnosis import FIX_CONTEXT, FIX_STATE
from twinfleet.checker.topology import Topology
from twinfleet.checker.transition import changed_attributes, fingerprint
from twinfleet.checker.world import Event
from twinfleet.runtime.contract.context import Call, Publish
from twinfleet.runtime.contract.dispatch import (
    HandlerOutcome,
    declared_message_type,
    wrong_type_line,
)
from twinfleet.runtime.contract.kinds import FailureKind
from twinfleet.runtime.contract.node import Node

#: A breach: its failure kind, the node, the handler and the one-line message.
Breach = tuple[FailureKind, str, str, str]


@final
class Breaches:
    """Finds the breaches of the handler runs on a scenario's nodes (module docstring)."""

    def __init__(self, topology: Topology) -> None:
        self.topology = topology
        self.nodes: tuple[Node, ...] = topology.nodes
        self.names = tuple(node.name for node in self.nodes)
        self._declared_types: dict[tuple[int, str], type | None] = {}

    def of(self, node: Node, ev: Event, attributes: dict[str, Any] | None,
           before: dict[str, bytes] | None, outcome: HandlerOutcome) -> Breach | None:
        """The first breach of the run of `ev`'s handler on `node`, or None: `attributes`
        are the node's attributes before it (None: not compared), `before` their encodings
        (with `debug_state`)."""
        return self._breach(node, ev, attributes, before, outcome) or self._wrong_type(
            ev, outcome.effects)

    def _wrong_type(self, ev: Event, effects: Sequence[Any]
                    ) -> Breach | None:
        """A message sent whose type is not what a receiving handler declares: a breach
        found at the send, in the words the live fleet uses for it (`wrong_type_line`)."""
        topology, sender = self.topology, self.names[ev.target]
        for eff in effects:
            match eff:
                case Publish(topic=name, msg=msg):
                    receivers, call = tuple(topology.subscribers.get(name, ())), False
                case Call(service=name, request=msg):
                    server = topology.servers.get(name)
                    receivers, call = ((server,) if server else ()), True
                case _:
                    continue
            for j, method, _ in receivers:
                expected = self._declared(j, method)
                if expected is not None and type(msg) is not expected:
                    return (FailureKind.CONTRACT, sender, ev.method, wrong_type_line(
                        sender, name, msg, expected, f"{self.names[j]}.{method}", call=call))
        return None

    def _declared(self, j: int, method: str) -> type | None:
        """The message class node j's handler `method` declares (looked up once)."""
        key = (j, method)
        if key not in self._declared_types:
            self._declared_types[key] = declared_message_type(self.nodes[j], method)
        return self._declared_types[key]

    def _breach(self, node: Node, ev: Event, attributes: dict[str, Any] | None,
                before: dict[str, bytes] | None, outcome: HandlerOutcome
                ) -> Breach | None:
        """A contract breach of one handler run: a misused ctx, or attributes other than
        `state` that changed (by identity; with `debug_state`, by value)."""
        error = outcome.error
        if error is not None and error.contract:
            return (FailureKind.CONTRACT, node.name, ev.method,
                    f"{error.message}; fix: {error.fix or FIX_CONTEXT}")
        if attributes is not None:
            now = vars(node)
            stray = sorted(k for k in attributes.keys() | now.keys()
                           if k != "state" and attributes.get(k) is not now.get(k))
            if stray:
                return (FailureKind.STATE_OUTSIDE, node.name, ev.method,
                        f"it changed {', '.join('self.' + k for k in stray)}, outside "
                        f"self.state; fix: {FIX_STATE}")
        if before is not None:
            stray = changed_attributes(before, fingerprint(node))
            if stray:
                return (FailureKind.STATE_OUTSIDE, node.name, ev.method,
                        f"handler changed attribute(s) {', '.join(stray)} outside "
                        f"self.state; fix: {FIX_STATE}")
        return None
