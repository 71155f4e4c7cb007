"""`rclpy.service.Service`."""

from __future__ import annotations

from typing import Any


class Service:
    """A service server made in the node's `__init__`."""

    def __init__(self, engine: Any, index: int) -> None:
        self._engine, self._index = engine, index
        engine.handles[("service", index)] = self
        self._tf_key = f"service:{index}"  # how a state names it (twinfleet.rclpy.state)

    def _tf_ref(self) -> tuple[str, int] | None:
        return ("service", self._index)

    @property
    def srv_name(self) -> str:
        """The fully qualified service name."""
        return str(self._engine.adapter.resolve(self._engine.services[self._index].name))

    def destroy(self) -> None:
        """Accepted; services live as long as the node."""
